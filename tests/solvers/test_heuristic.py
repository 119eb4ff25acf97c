"""The GLNS-class heuristic: optimal on tiny instances, deterministic, within its time limit."""

from __future__ import annotations

import itertools
import math
import time

import numpy as np
import pytest
from conftest import GTSPLIB, needs_shared

from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix
from urpt_gcs.solvers import SOLVERS, SolveSettings, solve
from urpt_gcs.solvers.clustered import cluster_instance
from urpt_gcs.solvers.heuristic import HeuristicSolver, SearchSettings, solve_clustered, warm_up

SETTINGS = SolveSettings(time_limit_s=10.0, seed=0)


def random_instance(
    seed: int,
    m: int,
    max_nodes: int,
    *,
    depot: bool = False,
    asymmetric: bool = False,
    overlap: bool = False,
) -> Instance:
    """Clustered points: each target's viewpoints scattered around it.

    ``asymmetric`` adds a climbing cost (going up costs more than going down), which keeps
    the triangle inequality; ``overlap`` lets some viewpoints also see another target.
    """
    rng = np.random.default_rng(seed)
    centres = rng.random((m, 2)) * 100.0
    sizes = rng.integers(1, max_nodes + 1, size=m)
    owner = np.repeat(np.arange(m), sizes)
    xy = centres[owner] + rng.normal(scale=8.0, size=(len(owner), 2))
    n = len(xy)
    covers = np.zeros((n, m), dtype=bool)
    covers[np.arange(n), owner] = True
    if overlap:
        extra = rng.random(n) < 0.4
        covers[np.flatnonzero(extra), rng.integers(0, m, size=int(extra.sum()))] = True
    distance = euclidean_matrix(xy)
    z = rng.random(n) * 30.0 if asymmetric else np.zeros(n)
    distance = distance + 0.5 * np.maximum(z[None, :] - z[:, None], 0.0)
    depot_distance = None
    if depot:
        to = np.hypot(*(xy - rng.random(2) * 100.0).T)
        depot_distance = np.vstack([to + 0.5 * z, to])
    return Instance(
        covers=Covers.from_dense(covers), distance=distance, depot_distance=depot_distance
    )


def brute_force_partition(instance: Instance) -> float:
    """Every order of the targets times every choice of one viewpoint each (disjoint covers)."""
    members = [instance.covers.viewpoints_of(t) for t in range(instance.n_targets)]
    dist = instance.matrix()
    best = math.inf
    first = [] if instance.has_depot else [0]
    rest = range(len(first), instance.n_targets)
    for perm in itertools.permutations(rest):
        order = [*first, *perm]
        seq = np.array(list(itertools.product(*(members[t] for t in order))))
        inner = dist[seq[:, :-1], seq[:, 1:]].sum(axis=1)
        if instance.depot_distance is not None:
            ends = instance.depot_distance[0, seq[:, 0]] + instance.depot_distance[1, seq[:, -1]]
        else:
            ends = dist[seq[:, -1], seq[:, 0]]
        best = min(best, float((inner + ends).min()))
    return best


def brute_force_covers(instance: Instance) -> float:
    """Every sequence of distinct viewpoints, of at most one per target, that sees all."""
    best = math.inf
    for length in range(1, instance.n_targets + 1):
        for seq in itertools.permutations(range(instance.n_viewpoints), length):
            if not instance.uncovered(seq):
                best = min(best, instance.tour_length(seq))
    return best


def check_tour(instance: Instance, length: float, expected: float) -> None:
    assert length == pytest.approx(expected, rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(
    ("depot", "asymmetric"), [(False, False), (True, False), (False, True), (True, True)]
)
def test_equals_brute_force_on_disjoint_clusters(seed: int, depot: bool, asymmetric: bool) -> None:
    instance = random_instance(seed, 6 if not depot else 5, 3, depot=depot, asymmetric=asymmetric)
    tour = HeuristicSolver().solve(instance, SETTINGS)
    assert tour.sees.any(axis=0).all()
    assert len(set(tour.order)) == len(tour.order)
    check_tour(instance, tour.length, brute_force_partition(instance))
    assert tour.length == pytest.approx(instance.tour_length(tour.order))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("depot", [False, True])
def test_equals_brute_force_with_overlapping_covers(seed: int, depot: bool) -> None:
    instance = random_instance(seed, 4, 2, depot=depot, asymmetric=seed % 2 == 1, overlap=True)
    assert instance.n_viewpoints <= 8
    tour = HeuristicSolver().solve(instance, SETTINGS)
    assert tour.sees.any(axis=0).all()
    check_tour(instance, tour.length, brute_force_covers(instance))


@pytest.mark.parametrize(
    "search",
    [
        SearchSettings(or_opt=True),
        SearchSettings(two_opt=False, children=0, final_restarts=0),
        SearchSettings(trials=1, restarts=2, neighbours=2),
    ],
    ids=["or-opt", "moves-only", "one-trial"],
)
@pytest.mark.parametrize("asymmetric", [False, True])
def test_other_search_settings_stay_exact(search: SearchSettings, asymmetric: bool) -> None:
    for seed in range(3):
        instance = random_instance(20 + seed, 6, 3, asymmetric=asymmetric)
        clustered = cluster_instance(instance)
        cycle = solve_clustered(clustered, SETTINGS, search)
        assert sorted(clustered.cluster[cycle].tolist()) == list(range(clustered.n_clusters))
        check_tour(instance, clustered.cycle_length(cycle), brute_force_partition(instance))


@pytest.mark.parametrize("depot", [False, True])
@pytest.mark.parametrize("m", [0, 1, 2, 3])
def test_tiny_instances(m: int, depot: bool) -> None:
    if m == 0:
        instance = Instance(
            covers=Covers.from_dense(np.zeros((2, 0), dtype=bool)),
            distance=np.zeros((2, 2)),
            depot_distance=np.ones((2, 2)) if depot else None,
        )
        assert HeuristicSolver().solve(instance, SETTINGS).order == ()
        return
    instance = random_instance(m, m, 3, depot=depot, asymmetric=True)
    tour = HeuristicSolver().solve(instance, SETTINGS)
    check_tour(instance, tour.length, brute_force_partition(instance))


def test_same_seed_same_tour() -> None:
    instance = random_instance(7, 40, 4, asymmetric=True)
    first = HeuristicSolver().solve(instance, SolveSettings(time_limit_s=30.0, seed=3))
    again = HeuristicSolver().solve(instance, SolveSettings(time_limit_s=30.0, seed=3))
    assert first.order == again.order
    assert first.length == again.length


def test_time_limit_is_honoured() -> None:
    warm_up()
    instance = random_instance(11, 200, 5)
    limit = 0.5
    started = time.perf_counter()
    tour = HeuristicSolver().solve(instance, SolveSettings(time_limit_s=limit, seed=0))
    wall = time.perf_counter() - started
    assert tour.sees.any(axis=0).all()
    assert tour.solve_s <= limit + 1.0
    assert wall <= limit + 1.0


def test_registered_and_reachable_through_solve() -> None:
    assert SOLVERS["heuristic"] is HeuristicSolver
    instance = random_instance(1, 5, 3, depot=True)
    tour = solve(instance, "heuristic", SETTINGS)
    assert tour.solver == "heuristic"
    check_tour(instance, tour.length, brute_force_partition(instance))


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("trials", 0),
        ("children", -1),
        ("stall_per_cluster", 0.0),
        ("temp_end", 2.0),
        ("removal_fraction", 0.0),
        ("removal_weights", (0.0, 0.0, 0.0, 0.0)),
        ("insertion_weights", (1.0, -1.0, 1.0)),
        ("neighbours", 0),
    ],
)
def test_search_settings_are_validated(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        SearchSettings(**{field: value})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("name", "best_known"), [("11eil51", 174), ("31pr152", 51576), ("35ftv170", 1205)]
)
@needs_shared(GTSPLIB)
def test_reaches_best_known_on_gtsplib(name: str, best_known: int) -> None:
    gtsplib = pytest.importorskip("urpt_gcs.files.formats.gtsplib")
    instance = gtsplib.read_gtsplib(GTSPLIB / f"{name}.gtsp")
    tour = HeuristicSolver().solve(instance, SETTINGS)
    assert tour.length == best_known


def plane_instance(m: int, per_target: int, seed: int = 0) -> Instance:
    """``m`` targets on the plane, each seen by ``per_target`` viewpoints around it, some of
    which also see a neighbouring target; a depot in a corner."""
    rng = np.random.default_rng(seed)
    centres = rng.random((m, 2)) * 100.0 * math.sqrt(m)
    owner = np.repeat(np.arange(m), per_target)
    xy = centres[owner] + rng.normal(scale=15.0, size=(len(owner), 2))
    extra = rng.random(len(owner)) < 0.2
    vp = np.r_[np.arange(len(owner)), np.flatnonzero(extra)]
    tg = np.r_[owner, (owner[extra] + 1) % m]
    return Instance.from_cover_pairs(vp, tg, xy, m, depot_xy=(0.0, 0.0))


def test_2000_clusters_on_the_plane_within_the_time_limit_and_linear_memory() -> None:
    from urpt_gcs.solvers.clustered import partition_nodes
    from urpt_gcs.solvers.heuristic import _BYTES_PER_NODE, _prepare

    instance = plane_instance(2000, 6)
    warm_up()
    limit = 3.0
    started = time.perf_counter()
    tour = HeuristicSolver().solve(instance, SolveSettings(time_limit_s=limit, seed=0))
    assert time.perf_counter() - started <= 1.1 * limit
    assert not instance.uncovered(tour.order)
    # Nothing node-by-node: every array of the instance and of the search is linear.
    n = partition_nodes(instance)
    p = _prepare(cluster_instance(instance), SearchSettings().neighbours)
    assert p.d.size == p.dt.size == p.setd.size == 0
    assert p.nbr.shape == (2001, 16)
    assert p.nbytes <= 64 * n and instance.nbytes() <= 128 * instance.n_viewpoints
    # The budget check counts bytes per node: well under 1 % of one dense node matrix.
    assert _BYTES_PER_NODE * n < 0.01 * 8.0 * n * n
    # Far shorter than visiting the targets in file order (random places).
    assert tour.length < 0.2 * instance.tour_length(np.arange(0, 6 * 2000, 6))


def test_node_reselection_beyond_the_work_cap_descends_and_stays_a_tour() -> None:
    """Past the exact programme's work cap, nodes are re-chosen one cluster at a time: each
    ends up the cheapest of its cluster between its neighbours' nodes (checked here by
    trying them all), the order is kept and the tour never gets longer."""
    from urpt_gcs.solvers import _ls_kernels as ls
    from urpt_gcs.solvers.heuristic import _prepare

    instance = plane_instance(300, 12)
    p = _prepare(cluster_instance(instance), SearchSettings().neighbours)
    m = p.m
    rng = np.random.default_rng(4)
    order = rng.permutation(m)
    t = np.array([rng.integers(p.start[c], p.start[c + 1]) for c in order], dtype=np.int32)
    before = t.copy()
    q = (np.zeros(m, np.int32), np.zeros(m, np.bool_), np.zeros(1, np.int64))
    pos = np.full(m, -1, dtype=np.int32)

    def length(tour: np.ndarray) -> float:
        xy = p.xy[tour]
        return float(np.hypot(*(xy - np.roll(xy, -1, axis=0)).T).sum())

    cost = ls.reopt_nodes(p.kernel_args, t, m, pos, length(t), q)
    exact = t.copy()
    assert cost <= length(before) + 1e-9
    t = before.copy()
    cost = ls.descend_nodes(p.kernel_args, t, m, q)
    assert cost == pytest.approx(length(t)) and cost <= length(before) + 1e-9
    assert np.array_equal(p.cl[t], p.cl[before])
    assert length(exact) <= cost + 1e-6  # the exact choice is never worse
    stable = 0
    for i in range(m):
        a, b = p.xy[t[i - 1]], p.xy[t[(i + 1) % m]]
        c = p.cl[t[i]]
        nodes = np.arange(p.start[c], p.start[c + 1])
        costs = np.hypot(*(p.xy[nodes] - a).T) + np.hypot(*(p.xy[nodes] - b).T)
        here = np.hypot(*(p.xy[t[i]] - a)) + np.hypot(*(p.xy[t[i]] - b))
        stable += here <= costs.min() + 1e-9
    assert stable >= 0.95 * m  # a sweep's last changes may leave a few to the next sweep


def test_large_instances_rank_neighbours_by_centroid_and_still_solve(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With node-level neighbour ranking capped off, each cluster's neighbours are the
    clusters of the nearest centroids, and the search still returns a tour that sees every
    target, no worse than twice the uncapped one."""
    import urpt_gcs.solvers.heuristic as heuristic
    from urpt_gcs.solvers.heuristic import _nearest_clusters

    instance = plane_instance(400, 6)
    settings = SolveSettings(time_limit_s=1.0, seed=0)
    full = HeuristicSolver().solve(instance, settings)
    monkeypatch.setattr(heuristic, "_NODE_RANKED_NODES", 0)
    clustered = cluster_instance(instance)
    xy = np.asarray(clustered.xy)
    cl = clustered.cluster.astype(np.int32)
    nbr = _nearest_clusters(xy, cl, clustered.n_clusters, 5)
    centre = np.array([xy[cl == c].mean(axis=0) for c in range(clustered.n_clusters)])
    for c in (0, 17, 250):
        gap = np.hypot(*(centre - centre[c]).T)
        gap[c] = np.inf
        assert set(nbr[c].tolist()) == set(np.argsort(gap)[:5].tolist())
    capped = HeuristicSolver().solve(instance, settings)
    assert not instance.uncovered(capped.order)
    assert capped.length <= 2.0 * full.length


def test_node_reselection_past_the_cap_is_the_descent() -> None:
    """400 clusters of 100 nodes: the exact programme would take 4e8 evaluations, over the
    cap, so re-selection is the one-at-a-time descent (the same tour as calling it)."""
    from urpt_gcs.solvers import _ls_kernels as ls

    m, size = 400, 100
    assert size * m * size * size > ls.DP_WORK_CAP
    rng = np.random.default_rng(9)
    cl = np.repeat(np.arange(m, dtype=np.int32), size)
    xy = rng.random((m, 2))[cl] * 1000.0 + rng.normal(scale=20.0, size=(m * size, 2))
    start = np.arange(0, m * size + 1, size, dtype=np.int32)
    empty = np.zeros((0, 0))
    nbr = np.zeros((m, 1), dtype=np.int32)
    P = (empty, empty, np.ascontiguousarray(xy), start, cl, nbr, empty, 1)
    t = (start[:-1] + rng.integers(0, size, m)).astype(np.int32)
    other = t.copy()

    def q() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (np.zeros(m, np.int32), np.zeros(m, np.bool_), np.zeros(1, np.int64))

    pos = np.full(m, -1, dtype=np.int32)
    cost = ls.reopt_nodes(P, t, m, pos, ls.cycle_cost(P, t, m), q())
    assert cost == ls.descend_nodes(P, other, m, q())
    assert np.array_equal(t, other)


@pytest.mark.parametrize("budget", [1, 7, 500])
def test_local_search_in_slices_reaches_the_same_tour(budget: int) -> None:
    """Stopped every few clusters and resumed, the local search ends where it does in one go:
    the clock can be read between slices without changing the answer."""
    from urpt_gcs.solvers import _lns_kernels as lns
    from urpt_gcs.solvers import _ls_kernels as ls
    from urpt_gcs.solvers.heuristic import _prepare

    p = _prepare(cluster_instance(plane_instance(150, 5)), SearchSettings().neighbours)
    m = p.m
    order = np.random.default_rng(2).permutation(m)
    first = p.start[:-1][order].astype(np.int32)

    def scratch() -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        w = (
            np.full(m, -1, np.int32),
            np.zeros(m, np.int32),
            np.zeros(m + 1),
            np.zeros(m + 1),
            np.zeros(m, np.int32),
        )
        return w, (np.zeros(m, np.int32), np.zeros(m, np.bool_), np.zeros(1, np.int64))

    whole = first.copy()
    w, q = scratch()
    moves = ls.SYMMETRIC | ls.TWO_OPT | ls.OR_OPT
    lns.queue_all(p.kernel_args, whole, m, w, q)
    want = ls.local_search(p.kernel_args, whole, m, moves, w, q)
    sliced = first.copy()
    w, q = scratch()
    lns.queue_all(p.kernel_args, sliced, m, w, q)
    calls = 0
    while True:
        calls += 1
        cost, done = ls.local_search_for(p.kernel_args, sliced, m, moves, w, q, budget)
        if done:
            break
    assert cost == pytest.approx(want) and np.array_equal(sliced, whole)
    assert cost < 0.5 * ls.cycle_cost(p.kernel_args, first, m)
    assert calls > 1


def _overlapping_plane(seed: int) -> Instance:
    """Five targets; each seen from two viewpoints near it, and three wide viewpoints each
    seeing three targets, off the short way round."""
    rng = np.random.default_rng(seed)
    centres = rng.random((5, 2)) * 100.0
    near = np.repeat(centres, 2, axis=0) + rng.normal(scale=5.0, size=(10, 2))
    wide = rng.random((3, 2)) * 100.0
    vp = [*range(10), 10, 10, 10, 11, 11, 11, 12, 12, 12]
    tg = [*np.repeat(np.arange(5), 2), *rng.permutation(5)[:3], *rng.permutation(5)[:3]]
    tg += list(rng.permutation(5)[:3])
    return Instance.from_cover_pairs(
        np.asarray(vp), np.asarray(tg), np.vstack([near, wide]), 5, depot_xy=(50.0, 50.0)
    )


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("stop_cost", [0.0, 40.0, 400.0])
def test_a_stop_cost_on_the_plane_is_weighed_against_the_length(
    seed: int, stop_cost: float
) -> None:
    """The search minimises length plus the cost of each stop (brute force over every
    sequence of distinct viewpoints that sees all); the tour's length stays its length."""
    instance = _overlapping_plane(seed)
    assert instance.distance is None
    best = math.inf
    for size in range(1, 6):
        for seq in itertools.permutations(range(instance.n_viewpoints), size):
            if not instance.uncovered(seq):
                best = min(best, instance.tour_length(seq) + stop_cost * size)
    tour = HeuristicSolver().solve(
        instance, SolveSettings(time_limit_s=2.0, seed=seed, stop_cost=stop_cost)
    )
    assert not instance.uncovered(tour.order)
    pts = np.vstack([[50.0, 50.0], instance.points_xy[np.asarray(tour.order)], [50.0, 50.0]])
    length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    assert tour.length == pytest.approx(length, rel=1e-9)
    assert length + stop_cost * len(tour.order) == pytest.approx(best, rel=1e-9)


def test_a_stop_cost_must_be_a_finite_non_negative_number() -> None:
    from urpt_gcs.errors import SettingsError

    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(SettingsError, match="stop_cost"):
            SolveSettings(stop_cost=bad)
