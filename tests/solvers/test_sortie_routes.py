"""The route search over sorties: every stop flown once, every sortie within the endurance as
the model times it, never worse than where it started, and on a handful of points as quick
as the best plan found by brute force (every partition of the points into sorties, every
order of each)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from support.sortie_brute import best_partition, sortie_time, subsets

from urpt_gcs.problem.flight_time import FlightModel, split_sorties
from urpt_gcs.solvers.sortie_routes import search_routes

HOME = (0.0, 0.0)
ALT_M = 30.0


def _model() -> FlightModel:
    return FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0)


def _cut(xy: np.ndarray, order: np.ndarray, model: FlightModel, endurance_s: float) -> list:
    """The order cut at its best cut points: the sorties the search starts from."""
    cut = split_sorties(xy[order], HOME, ALT_M, model, endurance_s, ["s"] * len(xy))
    return [order[s.first : s.stop] for s in cut]


def _check(xy: np.ndarray, routes: list, model: FlightModel, endurance_s: float) -> float:
    """Every stop exactly once, every sortie within the endurance timed independently; the
    total flight time."""
    flown = np.sort(np.concatenate(routes))
    assert flown.tolist() == list(range(len(xy)))
    times = [sortie_time(model, xy[r], HOME, ALT_M) for r in routes]
    assert max(times) <= endurance_s + 1e-9
    return math.fsum(times)


@pytest.mark.parametrize("seed", range(12))
def test_tiny_instances_reach_the_brute_force_optimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 7
    xy = rng.uniform(-300.0, 300.0, (n, 2))
    model = _model()
    # An endurance that needs two or three sorties: the longest single-stop sortie, and then
    # some of the time a sortie through everything would take.
    alone = max(sortie_time(model, xy[[i]], HOME, ALT_M) for i in range(n))
    endurance = alone + 0.3 * (sortie_time(model, xy, HOME, ALT_M) - alone)
    _, quick, _ = subsets(xy, model, endurance, HOME, ALT_M)
    optimum = best_partition(quick, n)
    start = _cut(xy, np.arange(n), model, endurance)
    start_s = _check(xy, start, model, endurance)
    found, report = search_routes(xy, HOME, ALT_M, model, endurance, start, 0.3, seed)
    total = _check(xy, found, model, endurance)
    assert total >= optimum - 1e-6, "quicker than the brute-force optimum: a timing is wrong"
    assert total <= start_s + 1e-9
    assert report.flight_time_s == pytest.approx(total, abs=1e-6)
    assert total == pytest.approx(optimum, rel=1e-9)


def test_a_poor_start_is_much_improved_and_sorties_are_saved() -> None:
    """Stops in a random order cut into sorties: far from what a routing search finds."""
    rng = np.random.default_rng(5)
    n = 300
    xy = rng.uniform(-1500.0, 1500.0, (n, 2))
    model = _model()
    endurance = 20 * 60.0
    start = _cut(xy, rng.permutation(n), model, endurance)
    start_s = _check(xy, start, model, endurance)
    found, report = search_routes(xy, HOME, ALT_M, model, endurance, start, 1.0, 0)
    total = _check(xy, found, model, endurance)
    assert total < 0.6 * start_s
    assert len(found) < len(start)
    assert report.start_s == pytest.approx(start_s)
    assert report.sorties == len(found) and report.rounds > 0


def test_stops_at_one_position_are_each_flown_once() -> None:
    """Repeated positions (stops of targets seen from one point) are each their own stop."""
    rng = np.random.default_rng(2)
    base = rng.uniform(-800.0, 800.0, (40, 2))
    xy = np.vstack([base, base[:15], base[:5]])
    model = _model()
    endurance = 10 * 60.0
    start = _cut(xy, np.arange(len(xy)), model, endurance)
    start_s = _check(xy, start, model, endurance)
    found, _ = search_routes(xy, HOME, ALT_M, model, endurance, start, 0.5, 1)
    assert _check(xy, found, model, endurance) <= start_s


def test_the_start_comes_back_when_nothing_is_found() -> None:
    """One stop per sortie, and no endurance to put two together: nothing can change."""
    xy = np.array([[400.0, 0.0], [-400.0, 0.0], [0.0, 400.0]])
    model = _model()
    endurance = max(sortie_time(model, xy[[i]], HOME, ALT_M) for i in range(3)) + 1.0
    start = [np.array([0]), np.array([1]), np.array([2])]
    found, report = search_routes(xy, HOME, ALT_M, model, endurance, start, 0.1, 0)
    assert [r.tolist() for r in found] == [[0], [1], [2]]
    assert report.flight_time_s == report.start_s


@pytest.mark.parametrize("seed", range(6))
def test_given_leg_times_are_what_is_searched(seed: int) -> None:
    """Legs timed by the caller (a flight that climbs over terrain, slower one way than the
    other): a detour made slow on purpose is avoided, the result is the brute-force optimum
    over those times, and a leg left untimed (inf) is never flown."""
    rng = np.random.default_rng(100 + seed)
    n = 6
    xy = rng.uniform(-300.0, 300.0, (n, 2))
    model = _model()
    pts = np.vstack([xy, [HOME]])
    gap = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    legs = np.asarray(model.leg_s(gap), dtype=np.float64)
    # The ground rises to the east: eastward legs climb and take longer than westward ones
    # (the legs are not the same both ways). A ridge between stops 0 and 1 and between 2 and
    # home: climbing over takes a minute.
    east = pts[:, 0][None, :] > pts[:, 0][:, None]
    legs = np.where(east, 1.4 * legs, legs)
    legs[0, 1] = legs[1, 0] = legs[0, 1] + 60.0
    legs[2, n] = legs[n, 2] = legs[2, n] + 60.0
    legs[3, 4] = legs[4, 3] = np.inf  # not timed

    def time_of(route: list[int]) -> float:
        visits = [n, *route, n]
        t = model.takeoff_s(ALT_M) + model.landing_s(ALT_M) + len(route) * model.stop_s
        return t + sum(float(legs[a, b]) for a, b in itertools.pairwise(visits))

    quick = np.full(1 << n, np.inf)
    quick[0] = 0.0
    alone = max(time_of([i]) for i in range(n))
    endurance = alone + 0.4 * (time_of(list(range(n))) - alone)
    for size in range(1, n + 1):
        for seq in itertools.permutations(range(n), size):
            t = time_of(list(seq))
            if t <= endurance:
                mask = sum(1 << i for i in seq)
                quick[mask] = min(quick[mask], t)
    optimum = best_partition(quick, n)
    start = [np.array([i]) for i in range(n)]
    found, report = search_routes(
        xy, HOME, ALT_M, model, endurance, start, 0.3, seed, leg_times=legs
    )
    total = math.fsum(time_of(r.tolist()) for r in found)
    assert sorted(np.concatenate(found).tolist()) == list(range(n))
    assert max(time_of(r.tolist()) for r in found) <= endurance + 1e-9
    assert report.flight_time_s == pytest.approx(total, abs=1e-6)
    assert total == pytest.approx(optimum, rel=1e-9)
    for r in found:
        pairs = set(itertools.pairwise(r.tolist()))
        assert (3, 4) not in pairs and (4, 3) not in pairs


def _best_over_positions(
    choices: list[np.ndarray], model: FlightModel, endurance_s: float
) -> float:
    """The brute-force optimum when each stop may be flown from any of its positions."""
    best = math.inf
    for pick in itertools.product(*[range(len(c)) for c in choices]):
        xy = np.array([c[i] for c, i in zip(choices, pick, strict=True)])
        _, quick, _ = subsets(xy, model, endurance_s, HOME, ALT_M)
        best = min(best, best_partition(quick, len(xy)))
    return best


@pytest.mark.parametrize("seed", range(8))
def test_alternative_positions_are_chosen_for_the_sorties(seed: int) -> None:
    """Each stop may also be flown from two other positions (a target seen from several
    viewpoints): the search's sorties are at least as quick as without them, fly every stop
    from one of its own positions, and reach the brute-force optimum over every choice of
    positions and every partition."""
    rng = np.random.default_rng(200 + seed)
    n = 5
    xy = rng.uniform(-400.0, 400.0, (n, 2))
    others = xy[:, None, :] + rng.uniform(-150.0, 150.0, (n, 2, 2))
    choices = [np.vstack([xy[i], others[i]]) for i in range(n)]
    model = _model()
    alone = max(sortie_time(model, xy[[i]], HOME, ALT_M) for i in range(n))
    endurance = alone + 0.3 * (sortie_time(model, xy, HOME, ALT_M) - alone)
    start = _cut(xy, np.arange(n), model, endurance)
    plain, _ = search_routes(xy, HOME, ALT_M, model, endurance, start, 0.2, seed)
    plain_s = _check(xy, plain, model, endurance)
    alternatives = (others.reshape(-1, 2), np.arange(0, 2 * n + 1, 2))
    found, report = search_routes(
        xy, HOME, ALT_M, model, endurance, start, 0.3, seed, alternatives=alternatives
    )
    at = report.stops_xy
    for i in range(n):
        assert np.isclose(choices[i], at[i]).all(axis=1).any(), "a position it was not given"
    total = _check(at, found, model, endurance)
    assert report.flight_time_s == pytest.approx(total, abs=1e-6)
    assert total <= plain_s + 1e-9
    optimum = _best_over_positions(choices, model, endurance)
    assert total >= optimum - 1e-6
    print(f"\nseed {seed}: {plain_s:.1f} s fixed, {total:.1f} s chosen, optimum {optimum:.1f} s")
    assert total == pytest.approx(optimum, rel=1e-9)
