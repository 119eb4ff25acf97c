"""The sortie bound: never above a feasible set of sorties, found by brute force, and not vacuous.

A plan is a set of sorties, each from home through its stops and back within the endurance,
timed here from the flight model's primitives (take-off, each leg from rest to rest, a stop
at every point, the leg home at the return speed, landing). On a handful of points every plan
is enumerated (every order of every subset is a sortie, every partition of the points a
plan); on discs, plans through sampled points of the discs bound the optimum from above.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from support.sortie_brute import best_partition, parts, sortie_time, subsets

import urpt_gcs.bound.sorties as sorties_module
from urpt_gcs.bound.sorties import SortieBound, SortieBudget, sortie_bound, star_distances
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.regions import OuterStar

ALT_M = 30.0
HOME = (0.0, 0.0)
TOL = 1e-6


def _model() -> FlightModel:
    """The ArduCopter model at a survey's usual speed and hold."""
    return FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0)


def _sortie_time(model: FlightModel, seq_xy: np.ndarray) -> float:
    return sortie_time(model, seq_xy, HOME, ALT_M)


def _subsets(
    points: np.ndarray, model: FlightModel, endurance_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return subsets(points, model, endurance_s, HOME, ALT_M)


_parts = parts
_best_partition = best_partition


def _tightest(fastest: np.ndarray, n: int, parts: int) -> float:
    """The least endurance under which the points fit ``parts`` sorties (or fewer)."""
    cur = fastest.copy()
    for _ in range(parts - 1):
        nxt = cur.copy()
        for mask in range(1, 1 << n):
            nxt[mask] = min(max(fastest[p], cur[mask ^ p]) for p in _parts(mask))
        cur = nxt
    return float(cur[-1])


def _optimum(
    points: np.ndarray, model: FlightModel, endurance_s: float
) -> tuple[float, float, float]:
    """Over every plan of sorties within the endurance through the points: the least total
    length, the least total flight time and the fewest sorties (inf when none fits)."""
    n = len(points)
    short, quick, _ = _subsets(points, model, endurance_s)
    count = np.where(np.isfinite(quick), 1.0, np.inf)
    count[0] = 0.0
    return (
        _best_partition(short, n),
        _best_partition(quick, n),
        _best_partition(count, n),
    )


def _tsp_m(points: np.ndarray) -> float:
    """The shortest closed tour from home through every point."""
    best = math.inf
    for perm in itertools.permutations(range(len(points))):
        path = [HOME, *[(float(x), float(y)) for x, y in points[list(perm)]], HOME]
        best = min(best, sum(math.dist(a, b) for a, b in itertools.pairwise(path)))
    return best


def _bound_points(points: np.ndarray, single_m: float, budget: SortieBudget) -> SortieBound:
    """The bound with every region a single point."""
    n = len(points)
    return sortie_bound(
        points, np.zeros(n), np.hypot(*(points - np.asarray(HOME)).T), single_m, budget
    )


def _endurance(fastest: np.ndarray, n: int, parts: int, slack: float) -> float:
    """An endurance under which ``parts`` sorties are the fewest: the tightest that lets
    them fit, plus ``slack`` of the way to the next looser threshold."""
    tight = _tightest(fastest, n, parts)
    looser = _tightest(fastest, n, parts - 1) if parts > 1 else 1.5 * tight
    return tight + slack * (looser - tight)


def test_sortie_time_matches_the_flight_model() -> None:
    """The tests' own sortie time is the model's ``sortie_s`` of the same legs."""
    model = _model()
    rng = np.random.default_rng(11)
    for k in range(1, 6):
        seq = rng.uniform(-300.0, 300.0, (k, 2))
        path = np.vstack([HOME, seq, HOME])
        legs = np.hypot(*np.diff(path, axis=0).T)
        assert _sortie_time(model, seq) == pytest.approx(model.sortie_s(legs, ALT_M), abs=1e-9)
        # And the subset enumeration times sorties the same way.
        _, _, fastest = _subsets(seq, model, math.inf)
        assert fastest[-1] <= _sortie_time(model, seq) + 1e-9
        for i in range(k):
            assert fastest[1 << i] == pytest.approx(_sortie_time(model, seq[i : i + 1]), abs=1e-9)


def test_a_sortie_takes_at_least_what_the_budget_counts() -> None:
    """A sortie's time is at least ends + stops * stop + per_metre * length (module's text)."""
    model = _model()
    budget = SortieBudget.of(model, ALT_M, 600.0)
    rng = np.random.default_rng(5)
    for _ in range(200):
        k = int(rng.integers(1, 6))
        seq = rng.uniform(-300.0, 300.0, (k, 2)) * rng.uniform(0.01, 1.0)
        path = np.vstack([HOME, seq, HOME])
        length = float(np.hypot(*np.diff(path, axis=0).T).sum())
        least = budget.ends_s + k * budget.stop_s + budget.per_metre_s * length
        assert _sortie_time(model, seq) >= least - 1e-9


def _points(seed: int, layout: str) -> np.ndarray:
    """4-6 points: around home, or in a cluster a few hundred metres away from it."""
    rng = np.random.default_rng(seed)
    n = 4 + seed % 3
    if layout == "around":
        return rng.uniform(-300.0, 300.0, (n, 2))
    return np.column_stack([rng.uniform(300.0, 500.0, n), rng.uniform(-100.0, 100.0, n)])


@pytest.mark.parametrize("layout", ["around", "far"])
@pytest.mark.parametrize("slack", [0.0, 0.5])
@pytest.mark.parametrize("parts", [1, 2, 3])
@pytest.mark.parametrize("seed", range(6))
def test_point_bound_never_above_the_best_plan(
    seed: int, parts: int, slack: float, layout: str
) -> None:
    """On 4-6 points, length, time and count stay under every feasible plan's."""
    model = _model()
    points = _points(seed, layout)
    n = len(points)
    _, _, fastest = _subsets(points, model, math.inf)
    endurance = _endurance(fastest, n, parts, slack)
    best_m, best_s, fewest = _optimum(points, model, endurance)
    assert fewest == parts  # the harness forces the count it means to
    single = _tsp_m(points)
    bound = _bound_points(points, single, SortieBudget.of(model, ALT_M, endurance))
    assert bound.single_m == single
    assert bound.length_m >= single - TOL
    assert bound.length_m <= best_m + TOL
    assert bound.flight_time_s <= best_s + TOL
    assert 1 <= bound.sorties <= fewest
    # With the single-tour bound as 0 the bound still holds (and is no larger).
    bare = _bound_points(points, 0.0, SortieBudget.of(model, ALT_M, endurance))
    assert bare.length_m <= bound.length_m + TOL
    assert bare.flight_time_s <= bound.flight_time_s + TOL
    assert bare.sorties <= bound.sorties


def test_point_bound_is_not_vacuous() -> None:
    """Where the endurance forces several sorties the bound sees them: two sorties where
    two are forced, and a length beyond the single tour's on far clusters cut in three."""
    model = _model()
    longer = 0
    for seed in range(6):
        for layout in ("around", "far"):
            points = _points(seed, layout)
            n = len(points)
            _, _, fastest = _subsets(points, model, math.inf)
            single = _tsp_m(points)
            two = SortieBudget.of(model, ALT_M, _endurance(fastest, n, 2, 0.0))
            assert _bound_points(points, single, two).sorties >= 2, (seed, layout)
            if layout == "far":
                three = SortieBudget.of(model, ALT_M, _endurance(fastest, n, 3, 0.0))
                bound = _bound_points(points, single, three)
                longer += bound.length_m > single + 100.0 and bound.radius_m > 0.0
    assert longer >= 3


def _tight_model() -> FlightModel:
    """PX4 (home at the cruise speed, no loiter) braking hard: a leg takes barely more than
    its length over the speed, so the bound has little room below a plan."""
    return FlightModel.px4(cruise_m_s=5.0, hold_s=3.0, accel_m_s2=50.0)


@pytest.mark.parametrize(
    ("points", "loose", "tour"),
    [
        ([(300.0, 0.0)], True, False),
        ([(300.0, 0.0)], False, False),
        ([(50.0 * k, 0.0) for k in range(1, 7)], True, False),
        ([(300.0, 0.0), (-300.0, 0.0)], False, False),
        ([(300.0, 0.0), (-150.0, 260.0), (-150.0, -260.0)], False, False),
        ([(0.0, 0.0)], True, False),  # a target at home: take off, photograph, land
        ([(0.0, 0.0), (300.0, 0.0)], True, False),
        # The home target's own sortie: only the single-tour bound shows two are needed.
        ([(0.0, 0.0), (300.0, 0.0)], False, True),
    ],
)
def test_point_bound_is_nearly_exact_where_the_plan_is_forced(
    points: list[tuple[float, float]], loose: bool, tour: bool
) -> None:
    """Out-and-back plans with little braking: the bound (from a zero single-tour bound
    unless ``tour``) finds the optimum's length and count, and its time to within the
    overheads it does not count."""
    model = _tight_model()
    pts = np.asarray(points)
    n = len(pts)
    _, _, fastest = _subsets(pts, model, math.inf)
    # Loose: everything in one sortie; else the endurance of the longest lone sortie.
    endurance = 2.0 * fastest[-1] if loose else max(fastest[1 << i] for i in range(n))
    best_m, best_s, fewest = _optimum(pts, model, endurance)
    single = _tsp_m(pts) if tour else 0.0
    bound = _bound_points(pts, single, SortieBudget.of(model, ALT_M, endurance))
    assert bound.length_m <= best_m + TOL
    assert bound.flight_time_s <= best_s + TOL
    assert bound.sorties == fewest
    assert bound.length_m >= best_m - 1e-3
    # Each sortie's first and last legs speed up and brake beyond what the bound counts.
    _, extra = model.cruise_overhead()
    assert bound.flight_time_s >= best_s - 2.0 * extra * fewest - 1e-6


def _discs(seed: int, layout: str) -> np.ndarray:
    """4-5 discs ``(x, y, r)`` of 10-50 m: around home, or a cluster away from it."""
    rng = np.random.default_rng(100 + seed)
    n = 4 + seed % 2
    if layout == "around":
        xy = rng.uniform(-300.0, 300.0, (n, 2))
    else:
        xy = np.column_stack([rng.uniform(300.0, 500.0, n), rng.uniform(-100.0, 100.0, n)])
    return np.column_stack([xy, rng.uniform(10.0, 50.0, n)])


def _nearest(discs: np.ndarray) -> np.ndarray:
    """Each disc's point nearest home."""
    c = discs[:, :2] - np.asarray(HOME)
    d = np.hypot(*c.T)
    pull = np.minimum(discs[:, 2], d) / np.where(d > 0.0, d, 1.0)
    out: np.ndarray = discs[:, :2] - c * pull[:, None]
    return out


def _in_discs(discs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random point of each disc (uniform over its area)."""
    n = len(discs)
    a = rng.uniform(0.0, 2.0 * math.pi, n)
    s = discs[:, 2] * np.sqrt(rng.uniform(0.0, 1.0, n))
    out: np.ndarray = discs[:, :2] + np.column_stack([s * np.cos(a), s * np.sin(a)])
    return out


@pytest.mark.parametrize("layout", ["around", "far"])
@pytest.mark.parametrize("parts", [1, 2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_disc_bound_never_above_sampled_plans(seed: int, parts: int, layout: str) -> None:
    """On 4-5 discs, the bound stays under the best plan through sampled points of them."""
    model = _model()
    discs = _discs(seed, layout)
    n = len(discs)
    near = _nearest(discs)
    assert np.all(np.hypot(*(near - discs[:, :2]).T) <= discs[:, 2] + 1e-9)
    _, _, fastest = _subsets(near, model, math.inf)
    endurance = _endurance(fastest, n, parts, 0.0)
    rng = np.random.default_rng(seed)
    samples = [near, discs[:, :2]]
    for _ in range(30):
        # Random points, and points a little way from the nearest toward them.
        pts = _in_discs(discs, rng)
        samples += [pts, near + rng.uniform(0.0, 0.3) * (pts - near)]
    best_m = best_s = fewest = math.inf
    for pts in samples:
        m, s, k = _optimum(pts, model, endurance)
        best_m, best_s, fewest = min(best_m, m), min(best_s, s), min(fewest, k)
    assert fewest <= parts  # the nearest points fit the count the endurance was cut for
    r = np.maximum(np.hypot(*(discs[:, :2] - np.asarray(HOME)).T) - discs[:, 2], 0.0)
    single = 2.0 * float(r.max())  # a closed flight out to the farthest disc and back
    bound = sortie_bound(
        discs[:, :2], discs[:, 2], r, single, SortieBudget.of(model, ALT_M, endurance)
    )
    assert bound.length_m >= single - TOL
    assert bound.length_m <= best_m + TOL
    assert bound.flight_time_s <= best_s + TOL
    assert 1 <= bound.sorties <= fewest


@pytest.mark.parametrize("tight", [False, True])
@pytest.mark.parametrize("n", [2, 5, 8])
def test_discs_through_one_point_need_one_stop(n: int, tight: bool) -> None:
    """Discs whose rims all pass through one point 300 m out: one stop there photographs
    them all, so the bound is at most that out-and-back sortie, stops and all."""
    model = FlightModel.arducopter(cruise_m_s=5.0, hold_s=20.0)
    p = np.array([240.0, 180.0])
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False) + 0.3
    reach = np.linspace(15.0, 60.0, n)
    centres = p + reach[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    assert np.allclose(np.hypot(*(centres - p).T), reach)
    plan_s = _sortie_time(model, p[None, :])
    endurance = plan_s if tight else 3.0 * plan_s
    r = np.maximum(np.hypot(*centres.T) - reach, 0.0)
    bound = sortie_bound(centres, reach, r, 600.0, SortieBudget.of(model, ALT_M, endurance))
    assert bound.sorties == 1
    assert bound.length_m <= 600.0 + TOL
    assert bound.flight_time_s <= plan_s + TOL
    # Not vacuous: a sortie out to 300 m takes nearly its time.
    assert bound.flight_time_s >= 0.85 * plan_s


@pytest.mark.parametrize("seed", range(4))
def test_sparse_trees_agree_with_dense(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Above DENSE_MAX_REGIONS the trees use the centres' triangulation: on points the
    bound is the dense one, on discs no larger, and either stays under the best plan."""
    model = _model()
    for layout in ("around", "far"):
        points = _points(seed, layout)
        n = len(points)
        _, _, fastest = _subsets(points, model, math.inf)
        budget = SortieBudget.of(model, ALT_M, _endurance(fastest, n, 3, 0.0))
        best_m, best_s, fewest = _optimum(points, model, budget.endurance_s)
        dense = _bound_points(points, 0.0, budget)
        discs = _discs(seed, layout)
        r = np.maximum(np.hypot(*discs[:, :2].T) - discs[:, 2], 0.0)
        dense_discs = sortie_bound(discs[:, :2], discs[:, 2], r, 0.0, budget)
        with monkeypatch.context() as mp:
            mp.setattr(sorties_module, "DENSE_MAX_REGIONS", 0)
            sparse = _bound_points(points, 0.0, budget)
            sparse_discs = sortie_bound(discs[:, :2], discs[:, 2], r, 0.0, budget)
        assert sparse.length_m == pytest.approx(dense.length_m, abs=1e-6)
        assert sparse.flight_time_s == pytest.approx(dense.flight_time_s, abs=1e-6)
        assert sparse.sorties == dense.sorties
        assert sparse.length_m <= best_m + TOL
        assert sparse.flight_time_s <= best_s + TOL
        assert sparse.sorties <= fewest
        assert sparse_discs.length_m <= dense_discs.length_m + TOL
        assert sparse_discs.flight_time_s <= dense_discs.flight_time_s + TOL
        assert sparse_discs.sorties <= dense_discs.sorties


def test_sparse_tree_with_repeated_centres(monkeypatch: pytest.MonkeyPatch) -> None:
    """Regions sharing a centre are 0 apart in the sparse trees too: one sortie through
    three points, one of them six targets, is not counted as three."""
    model = _model()
    points = np.array([[300.0, 0.0], [310.0, 0.0], [300.0, 10.0]] + [[300.0, 0.0]] * 5)
    n = len(points)
    # A plan: one sortie with a stop for every target (five of them where the first is).
    plan_s = _sortie_time(model, points[[0, 3, 4, 5, 6, 7, 1, 2]])
    budget = SortieBudget.of(model, ALT_M, plan_s)
    monkeypatch.setattr(sorties_module, "DENSE_MAX_REGIONS", 0)
    bound = sortie_bound(points, np.zeros(n), np.hypot(*points.T), 0.0, budget)
    assert bound.sorties == 1
    assert bound.flight_time_s <= plan_s + TOL


def _star_samples(star: OuterStar, k: int) -> np.ndarray:
    """A dense polar grid of every sector of the star, its edges and rim included."""
    cx, cy = star.center_xy
    m = star.reach_m.size
    out = []
    for j, reach in enumerate(star.reach_m.tolist()):
        t = np.linspace(2.0 * math.pi * j / m, 2.0 * math.pi * (j + 1) / m, k)
        s = np.linspace(0.0, reach, k)
        tt, ss = np.meshgrid(t, s)
        out.append(
            np.column_stack([cx + (ss * np.cos(tt)).ravel(), cy + (ss * np.sin(tt)).ravel()])
        )
    return np.vstack(out)


@pytest.mark.parametrize("sectors", [1, 3, 8])
@pytest.mark.parametrize("seed", range(3))
def test_star_distance_is_the_least_over_the_star(seed: int, sectors: int) -> None:
    """Each star's distance from home is at most every sampled point's, and near their least."""
    rng = np.random.default_rng(seed)
    stars = []
    for _ in range(5):
        reach = rng.uniform(5.0, 80.0, sectors)
        if sectors > 1:
            reach[rng.integers(sectors)] = 0.0  # an empty sector
        stars.append(OuterStar(tuple(rng.uniform(-150.0, 150.0, 2).tolist()), reach))
    k = 300
    homes = [(0.0, 0.0), tuple(rng.uniform(-200.0, 200.0, 2).tolist())]
    for home in homes:
        got = star_distances(tuple(stars), home)
        assert got.shape == (len(stars),)
        for star, d in zip(stars, got.tolist(), strict=True):
            pts = _star_samples(star, k)
            sampled = float(np.hypot(pts[:, 0] - home[0], pts[:, 1] - home[1]).min())
            # The grid is within half a step (angle and radius) of every point of the star.
            widest = float(star.reach_m.max())
            step = widest * (2.0 * math.pi / sectors) / (k - 1) + widest / (k - 1)
            assert d <= sampled + 1e-9
            assert d >= sampled - step - 1e-6


@pytest.mark.parametrize("sectors", [1, 4, 16])
def test_star_distance_is_zero_from_inside(sectors: int) -> None:
    """Home at a star's centre, or inside one of its sectors, is at distance 0."""
    rng = np.random.default_rng(sectors)
    reach = rng.uniform(20.0, 60.0, sectors)
    reach[0] = 70.0  # the widest, so that no other sector comes nearer past its rim
    c = (37.0, -12.0)
    star = OuterStar(c, reach)
    homes = [c]
    for j in range(sectors):
        t = 2.0 * math.pi * (j + 0.5) / sectors
        s = 0.9 * float(reach[j])
        homes.append((c[0] + s * math.cos(t), c[1] + s * math.sin(t)))
    for home in homes:
        assert star_distances((star,), home)[0] == 0.0
    # Just outside a sector's rim, along its middle, the distance is the gap.
    t = 2.0 * math.pi * 0.5 / sectors
    s = float(reach[0]) + 7.0
    out = star_distances((star,), (c[0] + s * math.cos(t), c[1] + s * math.sin(t)))[0]
    assert out == pytest.approx(7.0, abs=1e-6)


@pytest.mark.parametrize("cruise", [3.0, 5.0, 8.0, 12.0])
def test_leg_time_is_subadditive_and_cruise_overhead_exact(cruise: float) -> None:
    """A rest-to-rest leg takes no more than two legs of the same total, and from
    ``leg_from`` on exactly its length over the speed plus the overhead."""
    model = FlightModel.arducopter(cruise_m_s=cruise, hold_s=1.0)
    lengths = np.concatenate([np.linspace(0.0, 500.0, 201), [0.01, 0.1, 1.0, 3.0]])
    a, b = np.meshgrid(lengths, lengths)
    for speed in (None, model.return_m_s):
        whole = model.leg_s(a + b, speed)
        split = model.leg_s(a, speed) + model.leg_s(b, speed)
        assert np.all(split >= whole - 1e-9)
        v = cruise if speed is None else speed
        # No leg is faster than its length over its speed.
        assert np.all(model.leg_s(lengths, speed) >= lengths / v - 1e-12)
    assert float(model.leg_s(0.0)) == 0.0
    leg_from, extra = model.cruise_overhead()
    assert 0.0 < leg_from < math.inf
    assert extra > 0.0
    long = np.concatenate([[leg_from], leg_from + np.linspace(0.0, 500.0, 51)[1:]])
    assert np.allclose(model.leg_s(long), long / cruise + extra, rtol=0.0, atol=1e-9)
    # Continuous where the leg starts to cruise, and shorter legs take less.
    assert float(model.leg_s(leg_from * (1.0 - 1e-9))) == pytest.approx(
        leg_from / cruise + extra, abs=1e-6
    )
    short = np.linspace(0.0, leg_from, 50)
    assert np.all(np.diff(model.leg_s(short)) >= 0.0)
    budget = SortieBudget.of(model, ALT_M, 600.0)
    assert budget.chains[-1] == (leg_from, extra)


def test_no_regions_give_the_single_bound() -> None:
    """With no region the bound is the single-tour bound, no sortie and no time."""
    budget = SortieBudget.of(_model(), ALT_M, 600.0)
    bound = sortie_bound(np.zeros((0, 2)), np.zeros(0), np.zeros(0), 123.5, budget)
    assert bound == SortieBound(123.5, 0.0, 0, 123.5, 0.0)


@pytest.mark.parametrize("spacing", [1.5, 4.0, 8.0, 15.0])
@pytest.mark.parametrize("layout", ["line", "ring"])
def test_leg_overhead_counts_stay_under_the_best_plan_of_close_stops(
    spacing: float, layout: str
) -> None:
    """Six stops a few metres apart, 150 m out: legs shorter than the cruise length spend
    less on speeding up and braking, and the bound's counts of legs at each gap must not
    claim more than the best plan spends (every order, every split, timed by the model)."""
    model = _model()
    k = np.arange(6)
    if layout == "line":
        pts = np.column_stack([150.0 + spacing * k, np.zeros(6)])
    else:
        a = 2.0 * math.pi * k / 6
        rad = spacing / (2.0 * math.sin(math.pi / 6))
        pts = np.column_stack([150.0 + rad * np.cos(a), rad * np.sin(a)])
    for endurance in (math.inf, 1.3 * _sortie_time(model, pts[:3])):
        best_m, best_s, _ = _optimum(pts, model, endurance)
        budget = SortieBudget.of(model, ALT_M, endurance)
        bound = _bound_points(pts, _tsp_m(pts), budget)
        assert bound.length_m <= best_m + TOL
        assert bound.flight_time_s <= best_s + TOL
        # Not vacuous: within the speeding-up of one leg per stop of the best plan.
        _, extra = model.cruise_overhead()
        assert bound.flight_time_s >= best_s - 6.0 * extra
