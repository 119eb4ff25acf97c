"""The continuous problem from regions alone: refinement, the solve path and ``bench cetsp``."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import CETSP, needs_shared
from scipy.optimize import minimize
from shapely.geometry import LineString, Point

from urpt_gcs.bench.cetsp import COLUMNS, read_instance, read_published
from urpt_gcs.cli import main
from urpt_gcs.problem.regions import RegionSet
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.continuous import _from_relaxed, solve_regions
from urpt_gcs.solvers.disc_tour import exact_positions, improve
from urpt_gcs.solvers.refine import best_on_disc, closed_length, refine_touches


def test_best_point_on_a_disc_matches_a_dense_search() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, b = rng.uniform(-10, 10, 2), rng.uniform(-10, 10, 2)
        c, r = rng.uniform(-10, 10, 2), rng.uniform(0.5, 4.0)
        p = np.asarray(best_on_disc(*a, *b, *c, r))
        rr = np.sqrt(rng.uniform(0, 1, 200_000)) * r
        t = rng.uniform(0, 2 * np.pi, 200_000)
        q = c + np.column_stack([rr * np.cos(t), rr * np.sin(t)])
        dense = np.min(np.hypot(*(q - a).T) + np.hypot(*(q - b).T))
        got = np.hypot(*(p - a)) + np.hypot(*(p - b))
        assert np.hypot(*(p - c)) <= r * (1 + 1e-9)
        assert got <= dense + 1e-6


def test_refinement_never_lengthens_and_stays_inside() -> None:
    rng = np.random.default_rng(1)
    n = 12
    discs = np.column_stack([rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(2, 9, n)])
    regions = RegionSet(discs=discs, depot_xy=(50.0, 50.0))
    seq = np.arange(n)
    start = discs[:, :2].copy()  # the centres: a tour through the discs, far from the best
    refined = refine_touches(regions, seq, start)
    assert regions.contains(refined, seq).all()
    before, after = closed_length(start, regions.depot_xy), closed_length(refined, regions.depot_xy)
    # Each disc lets its leg pair shorten by up to twice its radius: a real gain, bounded.
    assert before - 2 * discs[:, 2].sum() - 1e-9 <= after < before


def _drifts_passed(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The drift of every call of the order search from here on."""
    from urpt_gcs.solvers import disc_tour

    drifts: list[float] = []
    real = disc_tour.improve

    def spy(*args):  # type: ignore[no-untyped-def]
        drifts.append(args[6])  # (seq, pts, discs, start, seconds, seed, drift)
        return real(*args)

    monkeypatch.setattr(disc_tour, "improve", spy)
    return drifts


def test_solve_regions_enters_every_disc_and_brackets_the_optimum(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Discs on a circle of radius 20 around the depot: the tour is about the circle through
    # their inner rims, 2 pi (20 - r), give or take the chords.
    k, r = 10, 2.0
    a = 2 * np.pi * np.arange(k) / k
    discs = np.column_stack([20 * np.cos(a), 20 * np.sin(a), np.full(k, r)])
    regions = RegionSet(discs=discs, depot_xy=(18.0, 0.0))
    drifts = _drifts_passed(monkeypatch)
    tour = solve_regions(regions, SolveSettings(time_limit_s=2.0))
    assert drifts and set(drifts) == {0.0}  # few discs: the strict rule
    seen = regions.contains(tour.touch_xy, tour.touch_region)
    assert seen.all() and sorted(tour.touch_region.tolist()) == list(range(k))
    polygon = k * 2 * (20 - r) * np.sin(np.pi / k)  # the inscribed polygon through inner rims
    assert tour.length <= polygon * 1.001
    assert tour.length <= tour.discrete_length + 1e-9
    assert 0.0 < tour.lower_bound <= tour.length


def test_a_polyline_through_every_disc_becomes_a_tour_no_longer() -> None:
    # A square from the depot; discs at its corners, on its sides (crossed, not visited)
    # and one the square misses.
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    discs = np.array(
        [[10.5, 0.0, 1.0], [5.0, 10.8, 1.0], [-0.5, 4.0, 0.6], [9.0, 9.0, 2.0], [3.0, -0.999, 1.0]]
    )
    regions = RegionSet(discs=discs, depot_xy=(0.0, 0.0))
    got = _from_relaxed(regions, np.roll(square, 2, axis=0))
    assert got is not None
    seq, pts = got
    assert sorted(seq.tolist()) == list(range(len(discs)))
    assert np.all(np.hypot(*(pts - discs[seq, :2]).T) <= discs[seq, 2])
    # From the depot round the square: the bottom side's discs first, the left side's last.
    assert seq[0] == 4 and seq[-1] == 2
    assert closed_length(pts, regions.depot_xy) <= 40.0 + 1e-9
    missed = RegionSet(discs=np.vstack([discs, [[5.0, 5.0, 1.0]]]), depot_xy=(0.0, 0.0))
    assert _from_relaxed(missed, square) is None
    # A polyline that does not pass through the depot is no tour from it.
    assert _from_relaxed(regions, square + 0.5) is None


def test_bench_cetsp_writes_the_columns(tmp_path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "instances").mkdir()
    (tmp_path / "instances" / "square.txt").write_text(
        "# square source=here depot=0,0\n10 0 1\n10 10 1\n0 10 1\n"
    )
    (tmp_path / "best_known.csv").write_text(
        "name,n_discs,depot,best_known_length,best_known_source,proven_optimal,lower_bound,notes\n"
        "square,3,yes,34.0,here,no,,\n"
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["bench", "cetsp", str(tmp_path), "--time-limit", "1", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS
    length, bound = float(rows[0]["length"]), float(rows[0]["lower_bound"])
    # Brute force: one rim point per disc (the best touch is on the rim), every order.
    t = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    rims = [
        np.column_stack([x + np.cos(t), y + np.sin(t)]) for x, y in ((10, 0), (10, 10), (0, 10))
    ]
    brute = np.inf
    for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2)):
        p, q, w = (rims[i] for i in order)
        pq = np.hypot(p[:, None, 0] - q[None, :, 0], p[:, None, 1] - q[None, :, 1])
        qw = np.hypot(q[:, None, 0] - w[None, :, 0], q[:, None, 1] - w[None, :, 1])
        total = np.hypot(*p.T)[:, None, None] + pq[:, :, None] + qw[None] + np.hypot(*w.T)
        brute = min(brute, float(total.min()))
    assert bound <= length <= brute + 1e-9
    assert length >= brute - 0.01  # the grid is fine: 4 degrees of rim
    assert float(rows[0]["best_known"]) == 34.0


def test_bench_cetsp_runs_only_the_sizes_asked_for(tmp_path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "instances").mkdir()
    for name, k in (("three", 3), ("four", 4), ("six", 6)):
        rows = "".join(f"{10 * np.cos(a):.4f} {10 * np.sin(a):.4f} 1\n" for a in range(k))
        (tmp_path / "instances" / f"{name}.txt").write_text(f"# {name} depot=0,0\n{rows}")
    out = tmp_path / "out"
    args = ["bench", "cetsp", str(tmp_path), "--time-limit", "0.5", "--out", str(out)]
    result = CliRunner().invoke(main, [*args, "--min-discs", "4", "--max-discs", "5"])
    assert result.exit_code == 0, result.output
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["instance"], r["n_discs"]) for r in rows] == [("four", "4")]

    # A range no instance falls in: one line naming the options and the sizes there are,
    # and no results written.
    empty = tmp_path / "empty"
    result = CliRunner().invoke(
        main, ["bench", "cetsp", str(tmp_path), "--min-discs", "7", "--out", str(empty)]
    )
    assert result.exit_code == 1
    assert "--min-discs/--max-discs" in result.output and "3 to 6" in result.output
    assert "Traceback" not in result.output and not empty.exists()


def test_bench_cetsp_refuses_a_folder_without_instances(tmp_path) -> None:  # type: ignore[no-untyped-def]
    result = CliRunner().invoke(main, ["bench", "cetsp", str(tmp_path)])
    assert result.exit_code == 1
    assert "instances/" in result.output and "Traceback" not in result.output


def _polyline_distance(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Each centre's distance to the closed polyline through ``points`` (shapely, not ours)."""
    ring = LineString(np.vstack([points, points[:1]]))
    return np.asarray([ring.distance(Point(*c)) for c in centres])


def _fixed_order_optimum(seq: np.ndarray, discs: np.ndarray, depot: np.ndarray) -> float:
    """The fixed-order problem solved by scipy's SLSQP from the centres, as a check."""
    c, r = discs[seq, :2], discs[seq, 2]

    def legs(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.diff(np.vstack([depot, z.reshape(-1, 2), depot]), axis=0)
        return d, np.sqrt((d**2).sum(axis=1) + 1e-18)

    def length(z: np.ndarray) -> float:
        return float(legs(z)[1].sum())

    def grad(z: np.ndarray) -> np.ndarray:
        d, s = legs(z)
        u = d / s[:, None]
        return (u[:-1] - u[1:]).ravel()

    def inside(z: np.ndarray) -> np.ndarray:
        return r**2 - ((z.reshape(-1, 2) - c) ** 2).sum(axis=1)

    def inside_jac(z: np.ndarray) -> np.ndarray:
        e = z.reshape(-1, 2) - c
        jac = np.zeros((len(c), 2 * len(c)))
        jac[np.arange(len(c)), 2 * np.arange(len(c))] = -2 * e[:, 0]
        jac[np.arange(len(c)), 2 * np.arange(len(c)) + 1] = -2 * e[:, 1]
        return jac

    cons = {"type": "ineq", "fun": inside, "jac": inside_jac}
    res = minimize(
        length,
        c.ravel(),
        jac=grad,
        method="SLSQP",
        constraints=[cons],
        tol=1e-12,
        options={"maxiter": 200},
    )
    assert (inside(res.x) >= -1e-9).all()
    return float(res.fun)


def test_exact_positions_match_an_independent_convex_solve() -> None:
    # A chain of overlapping discs: the best tour enters lenses where consecutive stops
    # coincide, where moving one stop at a time stalls.
    rng = np.random.default_rng(3)
    for trial in range(3):
        n = 8
        centres = np.cumsum(rng.uniform(-3, 3, (n, 2)), axis=0) + 10.0
        discs = np.column_stack([centres, rng.uniform(1.5, 3.5, n)])
        if trial == 2:
            discs[3, 2] = 0.0  # a point to pass through
        seq = rng.permutation(n) if trial % 2 else np.arange(n)
        depot = np.asarray([0.0, 0.0])
        got = exact_positions(seq, discs[seq, :2].copy(), discs, depot)
        assert (np.hypot(*(got - discs[seq, :2]).T) <= discs[seq, 2]).all()
        length = closed_length(got, (0.0, 0.0))
        swept = refine_touches(RegionSet(discs=discs, depot_xy=(0.0, 0.0)), seq, discs[seq, :2])
        reference = _fixed_order_optimum(seq, discs, depot)
        assert length <= reference + 1e-6 * reference
        assert length <= closed_length(swept, (0.0, 0.0)) + 1e-9


def test_order_search_touches_every_disc_and_never_lengthens() -> None:
    rng = np.random.default_rng(5)
    n = 60
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(1, 8, n)])
    depot = np.asarray([50.0, 50.0])
    seq = rng.permutation(n)  # a poor start: a random order through the centres
    start = discs[seq, :2].copy()
    got_seq, got = improve(seq, start, discs, depot, time_limit_s=1.0)
    assert sorted(got_seq.tolist()) == list(range(n))
    tour = np.vstack([depot, got])
    # Every disc is touched by the closed tour: by its own stop or by a leg crossing it.
    assert (_polyline_distance(tour, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9) + 1e-9).all()
    length = float(np.hypot(*np.diff(np.vstack([tour, tour[:1]]), axis=0).T).sum())
    assert length < closed_length(start, tuple(depot)) * 0.5  # random orders are long


def test_kicks_on_the_stops_alone_keep_to_them_and_never_lengthen() -> None:
    # The kick loop also runs on a tour of some of the discs (the others taken out, their
    # position -1): it must neither put one of those in nor lose one of its own.
    from urpt_gcs.solvers._disc_kicks import _kicks
    from urpt_gcs.solvers.disc_tour import RUIN_NEIGHBOURS, _among, path_length

    rng = np.random.default_rng(14)
    n = 300
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(1, 6, n)])
    ends = np.ascontiguousarray(np.array([[50.0, 50.0], [50.0, 50.0]]))
    kept = np.sort(rng.choice(n, 120, replace=False))
    seq = rng.permutation(kept)
    pts = discs[seq, :2].copy()
    pos = np.full(n, -1, dtype=np.int64)
    pos[seq] = np.arange(seq.size)
    start = path_length(pts, ends)
    cur_seq, cur_pts = seq.copy(), pts.copy()
    best_seq, best_pts = seq.copy(), pts.copy()
    near, wide = _among(discs, seq), _among(discs, seq, RUIN_NEIGHBOURS)
    tours = (cur_seq, cur_pts, best_seq, best_pts)
    got = _kicks(seq, pts, pos, discs, ends, near, wide, *tours, 3000, rng)
    assert sorted(best_seq.tolist()) == kept.tolist()
    assert (pos[np.setdiff1d(np.arange(n), kept)] == -1).all()
    assert (pos[cur_seq] == np.arange(seq.size)).all()
    assert (seq == cur_seq).all() and (pts == cur_pts).all()
    assert path_length(cur_pts, ends) <= got * (1.0 + 1e-9)
    inside = np.hypot(*(best_pts - discs[best_seq, :2]).T) <= discs[best_seq, 2]
    assert inside.all()
    assert got == pytest.approx(path_length(best_pts, ends), rel=1e-12)
    assert got < 0.5 * start  # a random order through the centres is long


def test_a_drifting_search_keeps_tours_within_its_drift_and_returns_the_shortest() -> None:
    # With a drift the kept tour may be longer than the shortest met, by that factor at
    # most; the shortest is the one returned, and it still touches every disc.
    from urpt_gcs.solvers._disc_kicks import _kicks
    from urpt_gcs.solvers.disc_tour import RUIN_NEIGHBOURS, neighbours, path_length

    rng = np.random.default_rng(21)
    n = 250
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(1, 6, n)])
    depot = np.asarray([50.0, 50.0])
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    seq = rng.permutation(n)
    pts = discs[seq, :2].copy()
    pos = np.empty(n, dtype=np.int64)
    pos[seq] = np.arange(n)
    start = path_length(pts, ends)
    cur_seq, cur_pts = seq.copy(), pts.copy()
    best_seq, best_pts = seq.copy(), pts.copy()
    drift = 0.01
    tours = (cur_seq, cur_pts, best_seq, best_pts)
    near, wide = neighbours(discs), neighbours(discs, RUIN_NEIGHBOURS)
    got = _kicks(seq, pts, pos, discs, ends, near, wide, *tours, 3000, rng, drift)
    assert got == pytest.approx(path_length(best_pts, ends), rel=1e-12)
    kept = path_length(cur_pts, ends)
    assert got < kept <= got * (1.0 + drift) * (1.0 + 1e-12)  # it wandered, within the drift
    assert sorted(best_seq.tolist()) == list(range(n))
    assert (np.hypot(*(best_pts - discs[best_seq, :2]).T) <= discs[best_seq, 2]).all()
    assert got < 0.5 * start
    # Through improve(): never longer than the start, every disc touched.
    got_seq, got_pts = improve(seq, pts, discs, depot, time_limit_s=1.0, seed=3, drift=0.005)
    assert sorted(got_seq.tolist()) == list(range(n))
    tour = np.vstack([depot, got_pts])
    assert (_polyline_distance(tour, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9) + 1e-9).all()
    assert closed_length(got_pts, tuple(depot)) <= closed_length(pts, tuple(depot))


@needs_shared("bench/cetsp")
@pytest.mark.parametrize("name", ["concentricCircles1", "rotatingDiamonds1", "bubbles1"])
def test_proven_optima_are_matched(name: str) -> None:
    published = read_published(CETSP)[name]
    assert published.proven_optimal and published.best_known is not None
    regions = read_instance(CETSP / "instances" / f"{name}.txt")
    tour = solve_regions(regions, SolveSettings(time_limit_s=3.0))
    assert regions.depot_xy is not None and regions.discs is not None
    ring = np.vstack([regions.depot_xy, tour.points_xy])
    gaps = _polyline_distance(ring, regions.discs[:, :2]) - regions.discs[:, 2]
    assert gaps.max() <= 1e-7
    length = float(np.hypot(*np.diff(np.vstack([ring, ring[:1]]), axis=0).T).sum())
    assert abs(length - tour.length) <= 1e-9 * length
    # Within 0.01 % of the proven optimum; below it only by the file's rounding.
    assert published.best_known * (1 - 1e-5) <= length <= published.best_known * 1.0001
    assert tour.lower_bound <= published.best_known * (1 + 1e-4)
    assert length <= tour.discrete_length + 1e-9


def test_a_disc_tour_without_depot_touches_every_disc() -> None:
    rng = np.random.default_rng(8)
    n = 30
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(2, 6, n)])
    regions = RegionSet(discs=discs)
    tour = solve_regions(regions, SolveSettings(time_limit_s=2.0))
    ring = np.asarray(tour.points_xy)
    assert (_polyline_distance(ring, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9)).all()
    length = float(np.hypot(*np.diff(np.vstack([ring, ring[:1]]), axis=0).T).sum())
    assert abs(length - tour.length) <= 1e-9 * length
    assert length <= tour.discrete_length + 1e-9


@pytest.mark.parametrize(
    ("many", "depot"), [(True, (50.0, 50.0)), (True, None), (False, (50.0, 50.0))]
)
def test_discs_are_searched_from_many_starts_and_every_disc_is_entered(
    monkeypatch: pytest.MonkeyPatch, many: bool, depot: tuple[float, float] | None
) -> None:
    """The order search runs from the discrete tour, from other starts (above 200 discs
    random insertion tours, up to 200 discrete solves with fresh seeds) and from the
    shortest tour ruined (an area, or around a depot on few discs the depot moved): every
    start holds every disc once with its point inside, the starts differ, the ruins ran, and
    the tour kept enters every disc (by shapely's distance), is as long as its legs and no
    longer than the shortest tour any of the searches returned."""
    from urpt_gcs.solvers import continuous, disc_tour
    from urpt_gcs.solvers.continuous import _DRIFT, _DRIFT_ABOVE, nested_discs

    rng = np.random.default_rng(11)
    n_all = _DRIFT_ABOVE + 40 if many else 60
    all_discs = np.column_stack([rng.uniform(0, 100, (n_all, 2)), rng.uniform(0.5, 4.0, n_all)])
    regions = RegionSet(discs=all_discs, depot_xy=depot)
    # The searches see the discs that hold no other (a disc holding one is entered with it).
    discs = all_discs[nested_discs(all_discs) < 0]
    n = len(discs)
    assert n < n_all
    calls: list[tuple[np.ndarray, np.ndarray, float, np.ndarray]] = []
    ruined: list[tuple[int, ...]] = []
    real, real_ruin = disc_tour.improve, disc_tour.region_ruin

    def spy(*args):  # type: ignore[no-untyped-def]
        seq, pts, _, anchor, _, _, drift = args
        out = real(*args)
        ring = np.vstack([anchor, out[1]])
        calls.append((np.asarray(seq), np.asarray(pts), drift, ring))
        return out

    def spy_ruin(*args):  # type: ignore[no-untyped-def]
        out = real_ruin(*args)
        ruined.append(tuple(out[0].tolist()))
        return out

    real_moved, real_solve = disc_tour.depot_moved, continuous.solve
    moved: list[tuple[int, ...]] = []

    def spy_moved(*args):  # type: ignore[no-untyped-def]
        out = real_moved(*args)
        ruined.append(tuple(out[0].tolist()))
        moved.append(ruined[-1])
        return out

    seeds: list[int] = []

    def spy_solve(instance, name, settings):  # type: ignore[no-untyped-def]
        seeds.append(settings.seed)
        return real_solve(instance, name, settings)

    monkeypatch.setattr(disc_tour, "improve", spy)
    monkeypatch.setattr(disc_tour, "region_ruin", spy_ruin)
    monkeypatch.setattr(disc_tour, "depot_moved", spy_moved)
    monkeypatch.setattr(continuous, "solve", spy_solve)
    tour = solve_regions(regions, SolveSettings(time_limit_s=6.0))
    # Without a depot each search holds one stop fixed in its place: two calls a search.
    per_search = 1 if depot is not None else 2
    firsts = calls[::per_search]
    assert len(firsts) >= 3  # the discrete start, other starts, ruins
    assert {c[2] for c in calls} == {_DRIFT if many else 0.0}  # many: record-to-record
    for seq, pts, _, _ in firsts:
        # Without a depot the fixed stop's disc is not among those searched.
        assert len(seq) == len(set(seq.tolist())) == (n if depot is not None else n - 1)
        off = np.hypot(*(pts - discs[seq, :2]).T) - discs[seq, 2]
        assert (off <= 1e-9).all()
    # The ruins come last, each searched from what the ruin returned.
    assert len(ruined) >= 1
    restarts, ruin_starts = firsts[: -len(ruined)], firsts[-len(ruined) :]
    assert [tuple(s.tolist()) for s, *_ in ruin_starts] == ruined
    assert len({tuple(s.tolist()) for s, *_ in restarts}) == len(restarts) >= 2  # none alike
    # Up to 200 discs every restart after the first is a discrete solve of its own seed.
    assert len(seeds) == (1 if many else len(restarts)) == len(set(seeds))
    assert (len(moved) > 0) == (not many and depot is not None)
    assert sorted(tour.touch_region.tolist()) == list(range(n_all))
    ring = np.asarray(tour.points_xy if depot is None else np.vstack([depot, tour.points_xy]))
    assert (_polyline_distance(ring, all_discs[:, :2]) <= all_discs[:, 2] * (1 + 1e-9)).all()
    legs = np.vstack([ring, ring[:1]])
    assert tour.length == pytest.approx(float(np.hypot(*np.diff(legs, axis=0).T).sum()), rel=1e-9)
    returned = [float(np.hypot(*np.diff(np.vstack([r, r[:1]]), axis=0).T).sum()) for *_, r in calls]
    assert tour.lower_bound <= tour.length <= min(returned) * (1 + 1e-9)


def test_searches_side_by_side_run_on_two_threads_and_keep_the_shortest(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With two threads the order search runs in two threads at once (their searches
    overlap in time), and the tour kept enters every disc (by shapely's distance) and is no
    longer than the shortest tour any of the searches returned."""
    import threading
    import time

    from urpt_gcs.solvers import disc_tour

    rng = np.random.default_rng(12)
    n = 80
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(0.5, 4.0, n)])
    depot = np.array([50.0, 50.0])
    regions = RegionSet(discs=discs, depot_xy=(50.0, 50.0))
    spans: list[tuple[int, float, float, float]] = []
    real = disc_tour.improve

    def spy(*args):  # type: ignore[no-untyped-def]
        began = time.perf_counter()
        out = real(*args)
        length = closed_length(out[1], depot)
        spans.append((threading.get_ident(), began, time.perf_counter(), length))
        return out

    monkeypatch.setattr(disc_tour, "improve", spy)
    tour = solve_regions(regions, SolveSettings(time_limit_s=4.0, threads=2))
    assert len({ident for ident, *_ in spans}) == 2
    # Some search of one thread ran while one of the other did.
    overlap = any(a[0] != b[0] and a[1] < b[2] and b[1] < a[2] for a in spans for b in spans)
    assert overlap
    assert sorted(tour.touch_region.tolist()) == list(range(n))
    ring = np.vstack([depot, tour.points_xy])
    assert (_polyline_distance(ring, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9)).all()
    assert tour.length <= min(length for *_, length in spans) * (1 + 1e-9)


def test_a_failing_search_thread_ends_the_others_after_their_current_search(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """When the search in one thread fails, the error reaches the caller and the other
    thread starts no new search: of 30 s of searching, each search about 3 s, the other
    thread finishes the one it is in (lane 0 first, so this is not the order the caller
    waits in) and stops."""
    import threading

    from urpt_gcs.solvers import continuous

    rng = np.random.default_rng(13)
    n = 60
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(0.5, 4.0, n)])
    regions = RegionSet(discs=discs, depot_xy=(50.0, 50.0))
    start = continuous._insertion_start(regions, np.random.default_rng(0))
    real = continuous._search_discs
    calls: list[str] = []
    failed = threading.Event()

    def spy(regions, seq, pts, seconds, seed):  # type: ignore[no-untyped-def]
        name = threading.current_thread().name
        calls.append(name)
        if len(set(calls)) == 2 and name == calls[-1] and name != calls[0]:
            failed.set()
            raise RuntimeError("search failed")
        return real(regions, seq, pts, seconds, seed)

    monkeypatch.setattr(continuous, "_search_discs", spy)
    with pytest.raises(RuntimeError, match="search failed"):
        continuous._search_starts(regions, *start, 30.0, 0, threads=2)
    assert failed.is_set()
    first = calls[0]
    # The first thread: the search it was in when the other failed, and at most one more
    # (it may have begun one just before).
    assert calls.count(first) <= 2


def test_threads_below_one_are_refused(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from urpt_gcs.errors import SettingsError

    with pytest.raises(SettingsError, match="threads 0"):
        SolveSettings(threads=0)
    result = CliRunner().invoke(main, ["bench", "cetsp", str(tmp_path), "--threads", "0"])
    assert result.exit_code == 2 and "--threads" in result.output
    assert "Traceback" not in result.output


def test_a_region_ruin_puts_back_the_discs_of_one_area() -> None:
    """The discs taken out are the nearest to one disc's centre, the others keep their order
    and points, and every disc is back once with its point inside."""
    from urpt_gcs.solvers.disc_tour import region_ruin

    rng = np.random.default_rng(8)
    discs = np.column_stack([rng.uniform(0, 100, (90, 2)), rng.uniform(0.5, 6.0, 90)])
    seq = rng.permutation(np.arange(5, 90))  # some discs not in the tour
    pts = discs[seq, :2] + 0.3 * discs[seq, 2:] * rng.uniform(-1, 1, (seq.size, 2))
    depot = np.array([50.0, 50.0])
    changed = 0
    for trial in range(20):
        new_seq, new_pts = region_ruin(seq, pts, discs, depot, 0.2, np.random.default_rng(trial))
        assert sorted(new_seq.tolist()) == sorted(seq.tolist())
        assert (np.hypot(*(new_pts - discs[new_seq, :2]).T) <= discs[new_seq, 2]).all()
        # Those whose points moved are the ones taken out: 20 % of the tour, all nearer some
        # disc's centre than every disc left in place.
        where = {d: i for i, d in enumerate(seq.tolist())}
        moved = [
            d
            for d, p in zip(new_seq.tolist(), new_pts, strict=True)
            if not np.array_equal(p, pts[where[d]])
        ]
        kept = [d for d in new_seq.tolist() if d not in set(moved)]
        assert kept == [d for d in seq.tolist() if d not in set(moved)]  # order kept
        assert len(moved) <= int(0.2 * seq.size)
        reach = [np.hypot(*(discs[moved, :2] - discs[c, :2]).T).max() for c in seq.tolist()]
        near_enough = [
            c
            for c, r in zip(seq.tolist(), reach, strict=True)
            if (np.hypot(*(discs[kept, :2] - discs[c, :2]).T) >= r).all()
        ]
        assert near_enough, "no centre has the moved discs as its nearest"
        changed += new_seq.tolist() != seq.tolist()
    assert changed >= 10


def test_a_depot_move_joins_the_depot_to_a_far_leg_of_the_same_cycle() -> None:
    """Around a ring of discs the tour's cycle stays the same (a rotation of the order), the
    depot joins it at least 10 stops from where it did, the stops stay inside their discs
    and only those next to the old and the new joins move; the length is the ring's plus
    the new join's two legs, by an independent sum."""
    from urpt_gcs.solvers.disc_tour import depot_moved

    n = 48
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    rng = np.random.default_rng(3)
    radius = 40.0 + rng.uniform(-3.0, 3.0, n)
    discs = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(n, 2.0)])
    depot = np.array([0.0, 0.0])
    seq = np.arange(n)
    pts = discs[:, :2] * (1.0 - 1.0 / radius)[:, None]  # 1 m inward of each centre
    rotations = set()
    for trial in range(10):
        new_seq, new_pts = depot_moved(seq, pts, discs, depot, np.random.default_rng(trial))
        k = int(new_seq[0])
        assert new_seq.tolist() == np.roll(seq, -k).tolist()
        assert 10 <= k <= n - 10
        rotations.add(k)
        off = np.hypot(*(new_pts - discs[new_seq, :2]).T) - discs[new_seq, 2]
        assert (off <= 0.0).all()
        # Moved: up to three stops either side of the new join, two either side of the old.
        moved = set(np.flatnonzero(np.any(new_pts != pts[new_seq], axis=1)).tolist())
        old_join = n - k
        assert moved <= {0, 1, 2, n - 3, n - 2, n - 1, *range(old_join - 2, old_join + 2)}
        ring = np.vstack([new_pts, new_pts[:1]])
        legs = np.hypot(*np.diff(ring, axis=0).T)
        tour = np.vstack([depot, new_pts, depot])
        length = float(np.hypot(*np.diff(tour, axis=0).T).sum())
        joins = np.hypot(*(new_pts[[0, -1]] - depot).T).sum()
        assert length == pytest.approx(legs.sum() - legs[-1] + joins, rel=1e-12)
    assert len(rotations) >= 2  # the leg is drawn among the cheapest


def test_insertion_tours_hold_every_disc_inside_and_differ() -> None:
    from urpt_gcs.solvers.disc_tour import insertion_tour

    rng = np.random.default_rng(5)
    discs = np.column_stack([rng.uniform(0, 100, (80, 2)), rng.uniform(0.5, 9.0, 80)])
    which = np.arange(3, 80)  # some discs left out
    depot = np.array([50.0, 50.0])
    tours = [insertion_tour(discs, which, depot, np.random.default_rng(s)) for s in range(4)]
    for seq, pts in tours:
        assert sorted(seq.tolist()) == which.tolist()
        assert (np.hypot(*(pts - discs[seq, :2]).T) <= discs[seq, 2]).all()
    assert len({tuple(seq.tolist()) for seq, _ in tours}) == 4


def test_cheapest_insertion_matches_a_scan_of_every_leg() -> None:
    # The insertion skips legs by a lower bound of their cost and takes the first leg that
    # crosses the disc: its cost must still be the least over every leg, found by brute force.
    from urpt_gcs.solvers._disc_kicks import _insert_cheapest

    rng = np.random.default_rng(11)
    for trial in range(80):
        m = int(rng.integers(1, 30))
        pts = rng.uniform(0, 100, (m + 1, 2))
        ends = np.ascontiguousarray(np.vstack([[50.0, 50.0], [50.0, 50.0]]))
        discs = np.column_stack([rng.uniform(0, 100, (1, 2)), rng.uniform(0.5, 15, 1)])
        seq = np.zeros(m + 1, dtype=np.int64)
        ring = np.vstack([ends[0], pts[:m], ends[1]])
        costs = []
        for j in range(m + 1):  # every leg, each place on it sampled densely
            a, b = ring[j], ring[j + 1]
            th = np.linspace(0, 2 * np.pi, 2001)
            rr = discs[0, 2] * np.sqrt(np.linspace(0, 1, 60))[:, None]
            p = discs[0, :2] + np.stack([rr * np.cos(th), rr * np.sin(th)], axis=-1).reshape(-1, 2)
            c = np.hypot(*(p - a).T) + np.hypot(*(p - b).T) - np.hypot(*(b - a))
            costs.append(max(float(c.min()), 0.0))
        at = _insert_cheapest(seq, pts, discs, ends, m, 0)
        tour = np.vstack([ends[0], pts[: m + 1], ends[1]])
        added = float(np.hypot(*np.diff(tour, axis=0).T).sum()) - float(
            np.hypot(*np.diff(ring, axis=0).T).sum()
        )
        assert np.hypot(*(pts[at] - discs[0, :2])) <= discs[0, 2], trial
        # Dense sampling finds each leg's cost to within a hair above it.
        assert added <= min(costs) + 1e-9 * 100, (trial, added, min(costs))
        assert added >= min(costs) - 1e-3, (trial, added, min(costs))


def test_best_point_on_a_disc_from_ends_beside_its_rim() -> None:
    # Stops of overlapping discs sit on or a hair outside a neighbour's rim: the best point
    # must still be the least over the whole circle (dense), and inside the disc.
    rng = np.random.default_rng(12)
    th = np.linspace(-np.pi, np.pi, 200_001)
    for trial in range(60):
        c, r = rng.uniform(-5, 5, 2), rng.uniform(0.1, 3.0)
        ends = []
        for _ in range(2):
            phi = rng.uniform(-np.pi, np.pi)
            out = r * (1.0 + 10.0 ** rng.uniform(-15, 0))
            ends.append(c + out * np.array([np.cos(phi), np.sin(phi)]))
        a, b = ends
        p = np.asarray(best_on_disc(*a, *b, *c, r))
        ring = c + r * np.column_stack([np.cos(th), np.sin(th)])
        dense = np.min(np.hypot(*(ring - a).T) + np.hypot(*(ring - b).T))
        got = np.hypot(*(p - a)) + np.hypot(*(p - b))
        assert np.hypot(*(p - c)) <= r * (1 + 1e-12), trial
        assert got <= dense + 1e-9 * r, (trial, got, dense)


def test_the_insertion_floor_never_exceeds_the_insertion_cost() -> None:
    # Moves are skipped on this floor: above the real cost it would skip improving moves.
    from urpt_gcs.solvers._disc_moves import _insert_cost, _insert_floor

    rng = np.random.default_rng(13)
    for trial in range(400):
        m = int(rng.integers(1, 8))
        pts = rng.uniform(0, 100, (m, 2))
        ends = np.ascontiguousarray(rng.uniform(0, 100, (2, 2)))
        discs = np.column_stack([rng.uniform(0, 100, (1, 2)), rng.uniform(0.0, 30, 1)])
        for j in range(-1, m):
            cost = _insert_cost(pts, ends, discs, 0, j)[0]
            assert _insert_floor(pts, ends, discs, 0, j) <= cost + 1e-9, (trial, j)


def test_moving_the_depot_puts_it_on_one_of_the_cheapest_far_legs() -> None:
    # The closed tour is the same cycle of stops, the depot now on a leg at least ``away``
    # stops from its old one, and that leg is among the cheapest such (checked against
    # every rotation's length, computed here).
    from urpt_gcs.solvers._disc_kicks import _DEPOT_CHOICES, _move_depot
    from urpt_gcs.solvers.disc_tour import path_length

    rng = np.random.default_rng(8)
    n, away = 40, 6
    depot = np.array([50.0, 50.0])
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    angle = np.sort(rng.uniform(0, 2 * np.pi, n))
    ring = np.column_stack([50 + 30 * np.cos(angle), 50 + 30 * np.sin(angle)])
    seq0 = np.arange(n, dtype=np.int64)
    lengths = {
        k: path_length(np.ascontiguousarray(np.roll(ring, -k, axis=0)), ends)
        for k in range(away, n - away + 1)
    }
    cheapest = sorted(lengths, key=lengths.__getitem__)[:_DEPOT_CHOICES]
    seen = set()
    for _ in range(40):
        seq, pts = seq0.copy(), ring.copy()
        pos = np.arange(n, dtype=np.int64)
        at = _move_depot(seq, pts, pos, ends, rng, away)
        k = int(seq[0])
        assert at == n - k and seq[at] == 0  # the old first stop
        assert (seq == np.roll(seq0, -k)).all() and (pts == np.roll(ring, -k, axis=0)).all()
        assert (pos[seq] == np.arange(n)).all()
        assert k in cheapest
        assert path_length(pts, ends) == pytest.approx(lengths[k], rel=1e-12)
        seen.add(k)
    assert len(seen) > 1  # chosen at random among them
    # Too few stops for a leg that far: nothing moves.
    seq, pts, pos = seq0[:11].copy(), ring[:11].copy(), np.arange(11, dtype=np.int64)
    assert _move_depot(seq, pts, pos, ends, rng, away) == -1
    assert (seq == seq0[:11]).all() and (pts == ring[:11]).all()


def test_an_escape_keeps_every_disc_and_never_lengthens_the_shortest_tour() -> None:
    from urpt_gcs.solvers.disc_tour import RUIN_NEIGHBOURS, _escape, neighbours, path_length

    rng = np.random.default_rng(31)
    n = 120
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(1, 6, n)])
    depot = np.asarray([50.0, 50.0])
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    seq = rng.permutation(n)
    pts = discs[seq, :2].copy()
    seq, pts = improve(seq, pts, discs, depot, time_limit_s=0.5, seed=2)
    pos = np.empty(n, dtype=np.int64)
    pos[seq] = np.arange(n)
    tours = (seq.copy(), pts.copy(), seq.copy(), pts.copy())
    before = path_length(pts, ends)
    near, wide = neighbours(discs), neighbours(discs, RUIN_NEIGHBOURS)
    for _ in range(3):
        got = _escape(seq, pts, pos, discs, ends, near, wide, tours, 50, rng)
        cur_seq, cur_pts, best_seq, best_pts = tours
        assert got == pytest.approx(path_length(best_pts, ends), rel=1e-12)
        assert got <= before * (1 + 1e-12)
        assert (seq == cur_seq).all() and (pts == cur_pts).all()
        assert (pos[seq] == np.arange(n)).all()
        assert sorted(best_seq.tolist()) == list(range(n))
        assert (np.hypot(*(best_pts - discs[best_seq, :2]).T) <= discs[best_seq, 2]).all()
        before = got


@pytest.mark.parametrize(("n", "escapes"), [(40, True), (260, False)])
def test_a_stalled_search_escapes_only_on_few_discs(
    monkeypatch: pytest.MonkeyPatch, n: int, escapes: bool
) -> None:
    from urpt_gcs.solvers import disc_tour

    calls: list[int] = []
    real = disc_tour._escape

    def spy(seq, *args):  # type: ignore[no-untyped-def]
        calls.append(seq.size)
        return real(seq, *args)

    monkeypatch.setattr(disc_tour, "_escape", spy)
    monkeypatch.setattr(disc_tour, "_STALL_S", 0.1)
    monkeypatch.setattr(disc_tour, "_ESCAPE_S", 0.05)
    rng = np.random.default_rng(4)
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(1, 6, n)])
    depot = np.asarray([50.0, 50.0])
    seq = rng.permutation(n)
    got_seq, got = disc_tour.improve(seq, discs[seq, :2].copy(), discs, depot, 1.5, seed=1)
    assert bool(calls) == escapes
    assert sorted(got_seq.tolist()) == list(range(n))
    tour = np.vstack([depot, got])
    assert (_polyline_distance(tour, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9) + 1e-9).all()


def test_discs_far_smaller_than_their_coordinates_are_entered() -> None:
    """Radii of a micrometre at coordinates of a kilometre: the searches keep a hair inside
    relative to the radius, below the coordinates' rounding; every touch point must still
    lie in its disc (the code before stopped on its own check, 'left a region')."""
    rng = np.random.default_rng(0)
    n = 40
    for radius in (1e-6, 1e-4):
        discs = np.column_stack([rng.uniform(0, 2000, (n, 2)), np.full(n, radius)])
        regions = RegionSet(discs=discs, depot_xy=(1000.0, 1000.0))
        tour = solve_regions(regions, SolveSettings(time_limit_s=1.0))
        at = discs[tour.touch_region]
        assert sorted(tour.touch_region.tolist()) == list(range(n))
        assert np.all(np.hypot(*(tour.touch_xy - at[:, :2]).T) <= at[:, 2])
        assert 0.0 < tour.lower_bound <= tour.length


def test_crowded_discs_are_bounded_by_the_tube_when_it_is_larger() -> None:
    """Three hundred discs crowding a square: the order search over them all is weak, the
    tube bound counts every disc at once; the tour reports the larger, below its length."""
    rng = np.random.default_rng(4)
    n = 300
    discs = np.column_stack([rng.uniform(0, 1000, (n, 2)), np.full(n, 20.0)])
    regions = RegionSet(discs=discs, depot_xy=(500.0, 500.0))
    tour = solve_regions(regions, SolveSettings(time_limit_s=2.0))
    assert tour.bound is not None
    assert tour.bound.method == f"tube over all {n}"
    assert 0.0 < tour.lower_bound <= tour.length


def test_the_time_a_bound_leaves_goes_on_ruining_the_shortest_tour(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A bound that stops at once (as the order search does where it can rise no further)
    leaves its time to the search: areas of the shortest tour are ruined after it, the solve
    takes about its whole time, and the tour kept enters every disc (shapely) and is no
    longer than the one the bound was given."""
    import time

    from urpt_gcs.solvers import continuous, disc_tour

    rng = np.random.default_rng(5)
    n = 80
    discs = np.column_stack([rng.uniform(0, 200, (n, 2)), rng.uniform(1.0, 6.0, n)])
    regions = RegionSet(discs=discs, depot_xy=(100.0, 100.0))
    real_bound, real_ruin = continuous.lower_bound, disc_tour.region_ruin
    given: list[tuple[float, float]] = []
    ruins: list[float] = []

    def quick_bound(regions, upper, time_limit_s, gap_target, method):  # type: ignore[no-untyped-def]
        found = real_bound(regions, upper, min(time_limit_s, 0.2), gap_target, method=method)
        given.append((upper, time.perf_counter()))
        return found

    def spy_ruin(*args):  # type: ignore[no-untyped-def]
        ruins.append(time.perf_counter())
        return real_ruin(*args)

    monkeypatch.setattr(continuous, "lower_bound", quick_bound)
    monkeypatch.setattr(disc_tour, "region_ruin", spy_ruin)
    limit = 8.0
    tour = solve_regions(regions, SolveSettings(time_limit_s=limit))
    assert len(given) == 1
    upper, bounded_at = given[0]
    assert tour.lower_bound < upper  # the bound stopped short of the tour
    assert sum(t > bounded_at for t in ruins) >= 2
    assert tour.solve_s >= 0.85 * limit
    assert tour.length <= upper * (1 + 1e-12)
    ring = np.vstack([(100.0, 100.0), tour.points_xy])
    assert (_polyline_distance(ring, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9)).all()


def test_nested_discs_name_a_disc_wholly_inside_that_holds_none() -> None:
    """Checked with shapely's geometry: every disc named holds no other and lies wholly
    inside the disc that names it; every disc that names none holds no other; equal discs
    name none."""
    from shapely.geometry import Point

    from urpt_gcs.solvers.continuous import nested_discs

    rng = np.random.default_rng(9)
    n = 120
    discs = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(0.5, 20.0, n)])
    discs = np.vstack([discs, discs[:3]])  # equal discs
    inside = nested_discs(discs)
    shapes = [Point(x, y).buffer(r, 256) for x, y, r in discs]

    def holds(i: int, j: int) -> bool:  # exact, apart from the polygons
        d = float(np.hypot(*(discs[i, :2] - discs[j, :2])))
        return i != j and d + discs[j, 2] < discs[i, 2] - 1e-9

    assert (inside >= 0).sum() > 10
    for i in range(len(discs)):
        if inside[i] < 0:
            assert not any(holds(i, j) for j in range(len(discs)))
        else:
            j = int(inside[i])
            assert inside[j] == -1
            assert shapes[i].buffer(1e-6).contains(shapes[j])
            assert holds(i, j)


def test_a_tour_of_discs_holding_others_enters_them_all_and_is_bounded() -> None:
    """Large discs around small ones: the tour is searched over the discs that hold none,
    enters every disc (shapely), lists each once, and its bound is below it."""
    rng = np.random.default_rng(2)
    small = np.column_stack([rng.uniform(0, 300, (40, 2)), rng.uniform(1.0, 4.0, 40)])
    around = small[:25].copy()
    around[:, :2] += rng.uniform(-3.0, 3.0, (25, 2))
    around[:, 2] += rng.uniform(8.0, 30.0, 25)
    discs = np.vstack([small, around])
    regions = RegionSet(discs=discs, depot_xy=(150.0, 150.0))
    tour = solve_regions(regions, SolveSettings(time_limit_s=3.0))
    assert sorted(tour.touch_region.tolist()) == list(range(len(discs)))
    off = np.hypot(*(tour.touch_xy - discs[tour.touch_region, :2]).T)
    assert (off <= discs[tour.touch_region, 2]).all()
    ring = np.vstack([(150.0, 150.0), tour.points_xy])
    assert (_polyline_distance(ring, discs[:, :2]) <= discs[:, 2] * (1 + 1e-9)).all()
    legs = np.vstack([ring, ring[:1]])
    assert tour.length == pytest.approx(float(np.hypot(*np.diff(legs, axis=0).T).sum()), rel=1e-9)
    assert 0.0 < tour.lower_bound <= tour.length
