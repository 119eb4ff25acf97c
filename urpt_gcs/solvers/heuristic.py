"""A GTSP large-neighbourhood search of the GLNS class (Smith & Imeson 2017, from the ideas).

It works on the partition form (:mod:`urpt_gcs.solvers.clustered`): a tour is a cyclic
sequence of clusters with one chosen node each. Each iteration removes some clusters (at
random, those whose removal saves most, a group of related ones, or a segment), puts them
back by cheapest insertion choosing both the place and the node (in random, cheapest-first or
costliest-first order, with noise), improves the result by local search around the change
(moving one cluster with its node re-chosen and 2-opt towards the nearest clusters, reversed
parts costed in reverse for asymmetric distances; Or-opt optionally), then makes the node
choice exact for the cluster order by a dynamic programme around the cycle, and keeps the
result by a simulated-annealing rule.

Stopping rule, scaled to the number of clusters ``m`` (see :class:`SearchSettings`): several
cold trials from random tours, each annealed over ``O(m)`` iterations and stopped once its
best has not improved for ``O(m)`` more; then the best trial tour is crossed with the others
(a segment of one, the rest in the order of the best, then local search) and annealed again
with warm restarts. The time limit is an upper bound that cuts this short, not a target.

Timing: the kernels are compiled by numba and cached on disk. :func:`warm_up` compiles them
(some 20 s in a fresh environment) or loads them from the cache (well under a second) once
per process, before the clock starts: ``SolveSettings.time_limit_s`` bounds the solve, the
partition form and its neighbour lists included, and ``Tour.solve_s`` excludes the one-off
compilation. A run is a pure function of ``SolveSettings.seed`` unless the time limit cuts it
short.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers import _lns_kernels as lns
from urpt_gcs.solvers import _ls_kernels as ls
from urpt_gcs.solvers._ls_kernels import EPS, OR_OPT, SYMMETRIC, TWO_OPT
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour
from urpt_gcs.solvers.clustered import (
    Clustered,
    cluster_instance,
    require_partition_memory,
    viewpoint_order,
)

__all__ = [
    "F64",
    "I32",
    "HeuristicSolver",
    "SearchSettings",
    "solve_clustered",
    "warm_up",
]

I32 = npt.NDArray[np.int32]
F64 = npt.NDArray[np.float64]

# Chunks of iterations between two looks at the clock, in seconds.
_CHUNK_S = 0.02
# Crossings per compiled call, between two looks at the clock.
_CHILDREN_PER_CALL = 25
# Peak memory per pair of partition-form nodes of an explicit instance: the partition form's
# matrix, its renumbered copy and transpose, and the temporaries that rank the clusters (33
# measured).
_BYTES_PER_NODE_PAIR = 36.0
# Peak memory per node on the plane: the partition form (position, cluster, viewpoint), its
# renumbered copy, the k-d tree, the cycle programme's labels, and per cluster its neighbour
# list and scratch space, counted per node (a cluster has at least one).
_BYTES_PER_NODE = 320.0
# Nearest clusters kept per cluster on the plane; moves look at the first `neighbours`.
_PLANE_NEIGHBOURS = 16
# Nodes per k-d tree query, which bounds its temporaries.
_QUERY_NODES = 1 << 16
# Above this many nodes, clusters are ranked as neighbours by their centroids alone.
_NODE_RANKED_NODES = 1_000_000
# From this many clusters on, a fresh tour follows a Hilbert curve over the cluster centres
# (then the cycle programme picks the nodes) instead of random cheapest insertion, whose
# cost grows with the square of the clusters and which the clock cannot interrupt.
_CURVE_CLUSTERS = 1000
# Queued clusters the local search on a curve tour takes between two reads of the clock.
_IMPROVE_SLICE = 2000


@dataclass(frozen=True, slots=True)
class SearchSettings:
    """How the search spends its effort; the defaults are tuned on GTSPLIB.

    Stopping rule: ``trials`` cold trials from random tours, then the best is crossed
    ``min(children, children_per_cluster * m)`` times with the other trial bests and annealed
    again. An annealing run cools from ``temp_start`` (``temp_warm`` for the final one) to
    ``temp_end`` times the mean edge of its first tour over ``anneal_per_cluster * m``
    iterations, then stops once its best has not improved for ``stall_per_cluster * m``
    iterations (both at least ``min_stall``); it then restarts warm from its best
    ``restarts`` times (``final_restarts - 1`` for the final run, which is skipped at 0).

    Neighbourhoods: one iteration removes 1 to ``removal_fraction * m`` clusters (at most
    ``max_removals``), drawing the removal heuristic (random, worst, related, segment) and
    the insertion order (random, cheapest first, costliest first) with probabilities
    proportional to ``removal_weights`` and ``insertion_weights``; ``noise`` perturbs the
    insertion order and ``power`` biases worst and related removal towards their first
    choices. Local search looks at the ``neighbours`` nearest clusters and uses 2-opt and
    Or-opt besides single-cluster moves when ``two_opt`` and ``or_opt`` say so.
    """

    trials: int = 12
    restarts: int = 0
    final_restarts: int = 6
    children: int = 300
    children_per_cluster: float = 3.0
    anneal_per_cluster: float = 10.0
    stall_per_cluster: float = 5.0
    min_stall: int = 50
    temp_start: float = 1.0
    temp_warm: float = 1.0
    temp_end: float = 0.02
    removal_fraction: float = 0.4
    max_removals: int = 100
    removal_weights: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    insertion_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    noise: float = 0.2
    power: float = 4.0
    neighbours: int = 10
    two_opt: bool = True
    or_opt: bool = False

    def __post_init__(self) -> None:
        if self.trials < 1 or self.restarts < 0 or self.final_restarts < 0:
            raise SettingsError(
                "SearchSettings: trials must be >= 1, restarts and final_restarts >= 0"
            )
        if self.children < 0 or self.children_per_cluster < 0.0:
            raise SettingsError("SearchSettings: children and children_per_cluster must be >= 0")
        if min(self.anneal_per_cluster, self.stall_per_cluster) <= 0.0 or self.min_stall < 1:
            raise SettingsError(
                "SearchSettings: anneal_per_cluster, stall_per_cluster and min_stall must be > 0"
            )
        if not 0.0 < self.temp_end <= min(self.temp_start, self.temp_warm):
            raise SettingsError("SearchSettings: need 0 < temp_end <= temp_start, temp_warm")
        if not (0.0 < self.removal_fraction <= 1.0 and self.max_removals >= 1):
            raise SettingsError(
                "SearchSettings: removal_fraction must be in (0, 1] and max_removals >= 1"
            )
        for name, weights in (
            ("removal_weights", self.removal_weights),
            ("insertion_weights", self.insertion_weights),
        ):
            if min(weights) < 0.0 or sum(weights) <= 0.0:
                raise SettingsError(f"SearchSettings: {name} must be >= 0 with a positive sum")
        if self.noise < 0.0 or self.power < 1.0 or self.neighbours < 1:
            raise SettingsError("SearchSettings: need noise >= 0, power >= 1, neighbours >= 1")


@dataclass(frozen=True, slots=True)
class _Problem:
    """The partition form renumbered so that each cluster's nodes are contiguous.

    Explicit: ``d``, ``dt`` node matrices, ``setd`` the cluster matrix, ``nbr`` every other
    cluster ranked; ``xy`` empty. On the plane: ``xy`` node positions, ``nbr`` the nearest
    few clusters, ``d``, ``dt``, ``setd`` empty, so that every array is linear in the nodes.
    """

    d: F64
    dt: F64
    xy: F64
    start: I32
    cl: I32
    nbr: I32
    setd: F64
    neighbours: int
    sym: bool
    node_of: npt.NDArray[np.int64]  # internal node -> node of the partition form
    # What a stop costs on top of its legs (on the plane only; see _ls_kernels).
    stop_cost: float = 0.0

    @property
    def m(self) -> int:
        return int(self.start.shape[0] - 1)

    @property
    def on_plane(self) -> bool:
        return int(self.xy.shape[0]) > 0

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays the search keeps."""
        arrays = (self.d, self.dt, self.xy, self.start, self.cl, self.nbr, self.setd)
        return sum(int(a.nbytes) for a in arrays) + int(self.node_of.nbytes)

    @property
    def kernel_args(self) -> tuple[F64, F64, F64, I32, I32, I32, F64, int]:
        xy = self.xy
        if xy.shape[0] > 0:
            # Each node's half of a stop's cost beside its position (see _ls_kernels).
            xy = np.column_stack([xy, np.full(xy.shape[0], 0.5 * self.stop_cost)])
        return (
            self.d,
            self.dt,
            xy,
            self.start,
            self.cl,
            self.nbr,
            self.setd,
            self.neighbours,
        )


def _nearest_clusters(xy: F64, cl: I32, m: int, k: int) -> I32:
    """The ``k`` clusters nearest to each cluster, nearest first, by a k-d tree over the nodes.

    Clusters are ranked by the closest pair of their nodes among each node's nearest nodes;
    each cluster's nearest centroids come after those, so that a cluster crowded by its own
    nodes still gets ``k`` neighbours. Beyond ``_NODE_RANKED_NODES`` nodes only the centroids
    rank (sorting every node's neighbours would take longer than the search).
    """
    n = len(xy)
    per_node = min(n, k + 4)
    keys: list[npt.NDArray[np.int64]] = []
    gaps: list[F64] = []
    tree = cKDTree(xy) if n <= _NODE_RANKED_NODES else None
    for lo in range(0, n if tree is not None else 0, _QUERY_NODES):
        assert tree is not None
        gap, idx = tree.query(xy[lo : lo + _QUERY_NODES], k=per_node)
        a = np.repeat(cl[lo : lo + _QUERY_NODES].astype(np.int64), per_node)
        key = a * m + cl[idx.ravel()]
        # Keep one (cluster, cluster) pair per block, its closest: blocks are whole clusters.
        order = np.lexsort((gap.ravel(), key))
        first = np.ones(order.size, dtype=bool)
        first[1:] = key[order][1:] != key[order][:-1]
        keys.append(key[order][first])
        gaps.append(gap.ravel()[order][first])
    counts = np.bincount(cl, minlength=m).astype(np.float64)
    centre = np.column_stack(
        [np.bincount(cl, weights=xy[:, i], minlength=m) / counts for i in range(2)]
    )
    gap, idx = cKDTree(centre).query(centre, k=min(m, k + 1))
    keys.append(np.repeat(np.arange(m, dtype=np.int64), idx.shape[1]) * m + idx.ravel())
    gaps.append(gap.ravel())
    key = np.concatenate(keys)
    # Pairs found among the nodes first, by their gap; then the centroid pairs.
    tier = np.zeros(key.size, dtype=np.int8)
    tier[key.size - keys[-1].size :] = 1
    order = np.lexsort((np.concatenate(gaps), tier, key // m))
    key = key[order]
    a, b = key // m, key % m
    keep = a != b
    a, b = a[keep], b[keep]
    # First occurrence of each pair, then the first k per cluster.
    pair = a * m + b
    _, first = np.unique(pair, return_index=True)
    first.sort()
    a, b = a[first], b[first]
    rank = np.arange(a.size) - np.searchsorted(a, a)
    nbr = np.empty((m, k), dtype=np.int32)
    nbr[a[rank < k], rank[rank < k]] = b[rank < k]
    return nbr


def _prepare(clustered: Clustered, neighbours: int) -> _Problem:
    perm = np.argsort(clustered.cluster, kind="stable")
    cl = clustered.cluster[perm].astype(np.int32)
    m = clustered.n_clusters
    start = np.concatenate([[0], np.cumsum(np.bincount(cl, minlength=m))]).astype(np.int32)
    empty = np.zeros((0, 0), dtype=np.float64)
    if clustered.xy is not None:
        xy = np.ascontiguousarray(clustered.xy[perm], dtype=np.float64)
        k = max(1, min(max(neighbours, _PLANE_NEIGHBOURS), m - 1))
        nbr = _nearest_clusters(xy, cl, m, k) if m > 1 else np.zeros((m, 1), np.int32)
        return _Problem(
            d=empty,
            dt=empty,
            xy=xy,
            start=start,
            cl=cl,
            nbr=nbr,
            setd=empty,
            neighbours=max(1, min(neighbours, k)),
            sym=True,
            node_of=perm,
        )
    assert clustered.distance is not None
    d = np.ascontiguousarray(clustered.distance[np.ix_(perm, perm)], dtype=np.float64)
    # Clusters are ranked by their closest pair of nodes, either way round.
    both = np.minimum(d, d.T)
    setd = np.minimum.reduceat(np.minimum.reduceat(both, start[:-1], axis=0), start[:-1], axis=1)
    ranked = np.argsort(setd + np.diag(np.full(m, np.inf)), axis=1, kind="stable")
    return _Problem(
        d=d,
        dt=np.ascontiguousarray(d.T),
        xy=np.zeros((0, 2), dtype=np.float64),
        start=start,
        cl=cl,
        nbr=np.ascontiguousarray(ranked[:, : m - 1], dtype=np.int32),
        setd=np.ascontiguousarray(setd),
        neighbours=max(1, min(neighbours, m - 1)),
        sym=bool(np.array_equal(d, d.T)),
        node_of=perm,
    )


def _hilbert_order(xy: F64, bits: int = 16) -> npt.NDArray[np.int64]:
    """Indices of ``xy`` along a Hilbert curve over their bounding square."""
    lo = xy.min(axis=0)
    span = max(float(np.ptp(xy, axis=0).max()), 1e-12)
    side = 1 << bits
    q = np.minimum(((xy - lo) / span * side).astype(np.int64), side - 1)
    x, y = q[:, 0].copy(), q[:, 1].copy()
    key = np.zeros(len(xy), dtype=np.int64)
    s = side >> 1
    while s > 0:
        rx = (x & s) > 0
        ry = (y & s) > 0
        key += s * s * ((3 * rx.astype(np.int64)) ^ ry.astype(np.int64))
        flip = ~ry & rx
        x = np.where(flip, side - 1 - x, x)
        y = np.where(flip, side - 1 - y, y)
        x, y = np.where(~ry, y, x), np.where(~ry, x, y)
        s >>= 1
    return np.argsort(key, kind="stable")


@functools.cache
def warm_up() -> None:
    """Compile the kernels, or load them from numba's cache, by solving a tiny instance."""
    xy = np.random.default_rng(0).random((12, 2))
    d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    clustered = Clustered(d, np.arange(12) % 6, 6, np.arange(12), None)
    # Two trials, so that the crossing is compiled too; the kernels' argument types are the
    # same on the plane, so one compilation serves both forms.
    search = SearchSettings(trials=2, neighbours=2)
    deadline = time.perf_counter() + 60.0
    _search(_prepare(clustered, search.neighbours), SolveSettings(), search, deadline)
    plane = Clustered(None, np.arange(12) % 6, 6, np.arange(12), None, xy=xy)
    p = _prepare(plane, search.neighbours)
    _search(p, SolveSettings(), search, deadline)
    run = _Run(p, SolveSettings(), search, deadline)
    run.curve_tour()


class _Run:
    """One search: the instance's kernel arguments, scratch space, generator and deadline."""

    def __init__(
        self, p: _Problem, settings: SolveSettings, search: SearchSettings, deadline: float
    ) -> None:
        m = p.m
        self.p, self.search, self.m = p, search, m
        self.deadline = deadline
        self.rng = np.random.default_rng(settings.seed)
        self.P = p.kernel_args
        self.W = (
            np.full(m, -1, dtype=np.int32),  # pos
            np.zeros(m, dtype=np.int32),  # rem
            np.zeros(m + 1),  # fw
            np.zeros(m + 1),  # bw
            np.zeros(m, dtype=np.int32),  # buf
        )
        self.Q = (np.zeros(m, np.int32), np.zeros(m, np.bool_), np.zeros(1, np.int64))
        kmax = max(1, min(m - 1, search.max_removals, math.ceil(search.removal_fraction * m)))
        self.stall = max(search.min_stall, math.ceil(search.stall_per_cluster * m))
        self.horizon = max(search.min_stall, math.ceil(search.anneal_per_cluster * m))
        self.moves = (
            (SYMMETRIC if p.sym else 0)
            | (TWO_OPT if search.two_opt else 0)
            | (OR_OPT if search.or_opt else 0)
        )
        self.pi = np.array([kmax, self.stall, 0, self.moves, self.horizon], dtype=np.int64)
        self.weights = np.array([*search.removal_weights, *search.insertion_weights])
        self.chunk = 8

    def out_of_time(self) -> bool:
        return time.perf_counter() >= self.deadline

    def fresh_tour(self) -> tuple[I32, float]:
        if self.p.on_plane and self.m >= _CURVE_CLUSTERS:
            return self.curve_tour()
        tour = np.zeros(self.m, dtype=np.int32)
        cost = lns.rebuild(self.P, tour, self.m, self.moves, self.W, self.Q, self.rng)
        return tour, float(cost)

    def curve_tour(self) -> tuple[I32, float]:
        """Clusters in Hilbert order of their centres, improved by local search (whose
        closing cycle programme makes the node choice exact for the order)."""
        p = self.p
        counts = np.diff(p.start).astype(np.float64)
        centre = np.column_stack(
            [np.add.reduceat(p.xy[:, i], p.start[:-1]) / counts for i in range(2)]
        )
        tour = p.start[:-1][_hilbert_order(centre)].astype(np.int32)
        lns.queue_all(self.P, tour, self.m, self.W, self.Q)
        # A slice of the queue at a time, so that the clock is read between slices.
        while True:
            cost, done = ls.local_search_for(
                self.P, tour, self.m, self.moves, self.W, self.Q, _IMPROVE_SLICE
            )
            if done or self.out_of_time():
                break
        # What is still queued is not this tour's business any more.
        self.Q[1][:] = False
        self.Q[2][0] = 0
        return tour, float(cost)

    def anneal(self, tour: I32, cost: float, temp: float, restarts: int) -> tuple[I32, float]:
        """Large-neighbourhood search from ``tour``; the best tour it finds and its cost."""
        edge = max(cost / self.m, EPS)
        t0, t1 = temp * edge, self.search.temp_end * edge
        cool = (t1 / t0) ** (1.0 / self.horizon)
        pf = np.array([t0, cool, t1, self.search.noise, self.search.power])
        sf = np.array([cost, cost, t0])
        si = np.zeros(4, dtype=np.int64)
        self.pi[lns.Q_RESTARTS] = restarts
        tours = (tour.copy(), tour.copy(), tour.copy())
        while self.m > 2 and not self.out_of_time():
            tick = time.perf_counter()
            args = (self.P, tours, sf, si, pf, self.pi, self.weights, self.W, self.Q, self.rng)
            if lns.lns_chunk(*args, self.chunk):
                break
            # Size chunks so that the clock is read about every _CHUNK_S seconds.
            spent = max(time.perf_counter() - tick, 1e-6)
            self.chunk = max(1, min(4 * self.chunk, int(self.chunk * _CHUNK_S / spent)))
        return tours[1], float(sf[lns.F_BEST])

    def recombine(self, best: I32, others: list[I32], n_children: int) -> float:
        """Cross ``best`` with ``others`` (in place, keeping improvements); its cost after."""
        elite = np.array(others, dtype=np.int32)
        child = np.zeros(self.m, dtype=np.int32)
        cost = math.inf
        for done in range(0, n_children, _CHILDREN_PER_CALL):
            n = min(_CHILDREN_PER_CALL, n_children - done)
            args = (self.P, best, elite, n, self.moves, self.W, self.Q, self.rng, child)
            cost = float(lns.recombine(*args))
            if self.out_of_time():
                break
        return cost


def _search(p: _Problem, settings: SolveSettings, search: SearchSettings, deadline: float) -> I32:
    """The best node cycle (internal numbering) found before the stopping rule or deadline.

    Cold trials from random tours, each annealed with ``search.restarts`` warm restarts;
    then the best of them is crossed with the others and annealed again with
    ``search.final_restarts`` warm restarts.
    """
    run = _Run(p, settings, search, deadline)
    best, best_cost = run.fresh_tour()
    elite: list[I32] = []
    for trial in range(search.trials):
        tour, cost = (best, best_cost) if trial == 0 else run.fresh_tour()
        tour, cost = run.anneal(tour, cost, search.temp_start, search.restarts)
        elite.append(tour)
        if cost < best_cost - EPS:
            best, best_cost = tour, cost
        if run.out_of_time():
            return best
    others = [t for t in elite if t is not best]
    n_children = min(search.children, math.ceil(search.children_per_cluster * p.m))
    if others and n_children > 0 and p.m > 2:
        best = best.copy()
        best_cost = run.recombine(best, others, n_children)
    if search.final_restarts > 0:
        tour, cost = run.anneal(best, best_cost, search.temp_warm, search.final_restarts - 1)
        if cost < best_cost - EPS:
            best = tour
    return best


def solve_clustered(
    clustered: Clustered,
    settings: SolveSettings,
    search: SearchSettings | None = None,
    deadline: float | None = None,
) -> list[int]:
    """The best node cycle the search finds on the partition form.

    Parameters
    ----------
    clustered
        The instance in partition form (one node per cluster to visit).
    settings
        Time limit (an upper bound on the search; compilation excluded) and seed.
    search
        Effort and heuristic parameters; the defaults when None.
    deadline
        ``time.perf_counter()`` value by which to answer, when the caller's clock started
        before this call; else the time limit counts from here (after compilation).

    Returns
    -------
    list of int
        Nodes of ``clustered``, one per cluster, in cycle order.
    """
    if clustered.n_clusters == 0:
        return []
    warm_up()
    if deadline is None:
        deadline = time.perf_counter() + settings.time_limit_s
    search = search or SearchSettings()
    p = _prepare(clustered, search.neighbours)
    if settings.stop_cost > 0.0:
        p = dataclasses.replace(p, stop_cost=settings.stop_cost)
    tour = _search(p, settings, search, deadline)
    return [int(v) for v in p.node_of[tour]]


class HeuristicSolver:
    """Large-neighbourhood search with exact node re-selection (GLNS class); see the module."""

    name = "heuristic"

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        """Solve ``instance`` within ``settings`` (see the module docstring for timing).

        Parameters
        ----------
        instance
            The GTSP with cover sets, with or without a depot.
        settings
            Time limit and seed.

        Returns
        -------
        Tour
            A tour that sees every target, with the instance's geometric lower bound.
        """
        if instance.explicit:
            require_partition_memory(instance, self.name, _BYTES_PER_NODE_PAIR)
        else:
            require_partition_memory(instance, self.name, 0.0, _BYTES_PER_NODE)
        warm_up()
        started = time.perf_counter()
        clustered = cluster_instance(instance)
        cycle = solve_clustered(clustered, settings, deadline=started + settings.time_limit_s)
        return finish_tour(
            instance,
            viewpoint_order(clustered, cycle),
            lower_bound=geometric_lower_bound(instance),
            solver=self.name,
            solve_s=time.perf_counter() - started,
        )
