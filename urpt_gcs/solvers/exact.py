"""Exact solver: dynamic programming over covered-target subsets (Held–Karp with cover masks).

State ``(mask, v)``: the cheapest path that starts at the depot (or at a fixed start
viewpoint), ends at viewpoint ``v`` and has seen exactly the targets in ``mask``. A path only
moves to a viewpoint that sees something new: with distances that obey the triangle
inequality, a viewpoint adding nothing can be skipped at no cost, and in the partition form
of GTSPLIB no cluster may be visited twice anyway. Masks are processed in increasing order,
which is a topological order because every move adds a target.

Without a depot, the tour must pass through some viewpoint of the target with the fewest
viewpoints; the DP runs once from each of them. States whose cost plus a lower bound on the
rest of the tour cannot beat the best tour known are skipped.

Time: a quick tour comes first (greedy, then a short run of the heuristic's search), so there
is always an answer and its length prunes the DP from the start. The compiled DP runs a slice
of masks at a time, sized to a few hundredths of a second, and the clock is read between
slices; stopped early, it keeps the best tour so far and a lower bound from the states not
yet expanded (every shorter tour passes through one of them), and the tour is not proven.
Work is counted in units (one per state looked at, one per move tried), so a work limit stops
it at the same place on any machine.

Work is about ``starts * n * sum_v 2^(m - |cover(v)|)`` state expansions and memory
``2^m * n * 16`` bytes; :func:`exact_work` estimates both so ``--solver auto`` can decide.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import SettingsError
from urpt_gcs.memory import require_memory
from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour
from urpt_gcs.solvers.clustered import cluster_instance, partition_nodes, viewpoint_order
from urpt_gcs.solvers.heuristic import SearchSettings, solve_clustered

__all__ = [
    "F64",
    "I32",
    "I64",
    "MAX_TARGETS",
    "MEMORY_BUDGET_BYTES",
    "WORK_BUDGET",
    "ExactResult",
    "ExactSolver",
    "ExactWork",
    "exact_work",
    "greedy_order",
    "quick_tour",
    "search_exact",
    "solve_exact",
    "warm_up",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]

# What `auto` lets the exact solver spend: state expansions and bytes of DP tables.
WORK_BUDGET = 3.0e9
MEMORY_BUDGET_BYTES = 1.5e9
MAX_TARGETS = 20
# Seconds of compiled work between two looks at the clock.
_SLICE_S = 0.02
# Rows of the DP table reset per numpy call, so the progress display is never held up long.
_RESET_ROWS = 4096
# The partition form's matrix the seeding search may build; past it the greedy tour seeds.
_SEED_MATRIX_BYTES = 64e6
# Share of the time limit the seeding search may take.
_SEED_SHARE = 0.2
# How much longer than on an empty table reading the filled one back into a bound may take.
_BOUND_MARGIN = 1.5


@dataclass(frozen=True, slots=True)
class ExactWork:
    """Estimated cost of solving an instance exactly."""

    expansions: float
    memory_bytes: float
    starts: int

    @property
    def fits_budget(self) -> bool:
        return self.expansions <= WORK_BUDGET and self.memory_bytes <= MEMORY_BUDGET_BYTES


@dataclass(frozen=True, slots=True)
class ExactResult:
    """What the dynamic programme established, to the end or until it was stopped.

    ``lower_bound`` holds for every tour over the instance's viewpoints; ``proven`` says the
    programme ran to the end, so that ``order`` is optimal over them. ``work`` counts the units
    spent (see the module docstring).
    """

    order: tuple[int, ...]
    length: float
    lower_bound: float
    proven: bool
    work: int


def _masks(instance: Instance) -> I64:
    weights = np.left_shift(np.int64(1), np.arange(instance.n_targets, dtype=np.int64))
    masks: I64 = (instance.covers.dense().astype(np.int64) * weights).sum(axis=1)
    return masks


def _starts(instance: Instance) -> I64:
    """Viewpoints the DP starts from: none (depot) or those of the rarest target."""
    if instance.has_depot:
        return np.zeros(0, dtype=np.int64)
    rarest = int(np.argmin(instance.covers.per_target()))
    return instance.covers.viewpoints_of(rarest)


def exact_work(instance: Instance) -> ExactWork:
    """Estimate the work and memory :class:`ExactSolver` needs for ``instance``."""
    m, n = instance.n_targets, instance.n_viewpoints
    if m > MAX_TARGETS:
        return ExactWork(math.inf, math.inf, 0)
    sizes = instance.covers.per_viewpoint()
    per_start = float(n) * float(np.sum(np.exp2(m - sizes)))
    starts = max(len(_starts(instance)), 1)
    return ExactWork(per_start * starts, float(2**m) * n * 16.0, starts)


@numba.njit(cache=True, nogil=True)
def _held_karp_start(
    cover: I64,
    first: F64,
    upper: float,
    cost: F64,
    parent_mask: I32,
    parent_v: I32,
) -> None:
    """Seed the DP with the first moves; ``first[v]`` is inf where ``v`` may not come first."""
    for v in range(cover.shape[0]):
        if first[v] < upper:
            cost[cover[v], v] = first[v]
            parent_mask[cover[v], v] = -1
            parent_v[cover[v], v] = -1


@numba.njit(cache=True, nogil=True)
def _held_karp_masks(
    cover: I64,
    dist: F64,
    last: F64,
    finish_bound: F64,
    full: int,
    lo: int,
    budget: int,
    best: F64,
    best_v: I64,
    cost: F64,
    parent_mask: I32,
    parent_v: I32,
) -> tuple[int, int]:
    """Expand the states of masks ``lo, lo + 1, ...`` until ``budget`` work units are spent
    (the mask under way is finished) or every mask is done; return the next mask and the units.

    ``best[0]`` and ``best_v[0]`` carry the best tour's cost and last viewpoint from one call
    to the next; ``last[v]`` is the cost of closing the tour from ``v`` and
    ``finish_bound[v, t]`` a lower bound on the rest of the tour from ``v`` while target ``t``
    is unseen.
    """
    n = cover.shape[0]
    m = finish_bound.shape[1]
    units = 0
    mask = lo
    while mask <= full and units < budget:
        row = cost[mask]
        units += n
        for v in range(n):
            here = row[v]
            if here >= best[0]:
                continue
            if mask == full:
                total = here + last[v]
                if total < best[0]:
                    best[0] = total
                    best_v[0] = v
                continue
            # Prune: some unseen target still has to be reached and the tour closed.
            need = 0.0
            for t in range(m):
                if not (mask >> t) & 1 and finish_bound[v, t] > need:
                    need = finish_bound[v, t]
            if here + need >= best[0]:
                continue
            units += n
            dv = dist[v]
            for w in range(n):
                cw = cover[w]
                if cw & ~mask == 0:
                    continue
                new = mask | cw
                c = here + dv[w]
                if c < cost[new, w]:
                    cost[new, w] = c
                    parent_mask[new, w] = mask
                    parent_v[new, w] = v
        mask += 1
    return mask, units


@numba.njit(cache=True, nogil=True)
def _frontier_bound(
    cost: F64, last: F64, finish_bound: F64, full: int, lo: int, best: float
) -> float:
    """A lower bound on every tour of this start, the DP expanded up to mask ``lo``.

    A tour shorter than ``best`` passes through a first state whose mask is ``lo`` or more;
    its predecessor was expanded, so that state's cost is at most the tour's cost so far, and
    the rest of the tour costs at least the finish bound.
    """
    n = cost.shape[1]
    m = finish_bound.shape[1]
    out = best
    for mask in range(lo, full + 1):
        row = cost[mask]
        for v in range(n):
            here = row[v]
            if here >= out:
                continue
            if mask == full:
                need = last[v]
            else:
                need = 0.0
                for t in range(m):
                    if not (mask >> t) & 1 and finish_bound[v, t] > need:
                        need = finish_bound[v, t]
            if here + need < out:
                out = here + need
    return out


@numba.njit(cache=True, nogil=True)
def _relax_through(out: F64, k_lo: int, k_hi: int) -> None:
    """Floyd–Warshall steps ``k_lo`` to ``k_hi - 1`` on ``out``, in place."""
    n = out.shape[0]
    for k in range(k_lo, k_hi):
        for i in range(n):
            dik = out[i, k]
            for j in range(n):
                c = dik + out[k, j]
                if c < out[i, j]:
                    out[i, j] = c


class _Budget:
    """The deadline and work limit of one search, and slices sized to the clock."""

    def __init__(self, deadline: float, work_limit: int | None) -> None:
        self.deadline = deadline
        self.work_left = math.inf if work_limit is None else float(work_limit)
        self.work = 0
        self.units = 1 << 16

    def spent(self) -> bool:
        return self.work_left <= 0.0 or time.perf_counter() >= self.deadline

    def slice_units(self) -> int:
        return int(min(self.units, self.work_left))

    def record(self, units: int, seconds: float) -> None:
        self.work += units
        self.work_left -= units
        # Slices of about _SLICE_S: grow at most fourfold at a time, never below one mask.
        rate = units / max(seconds, 1e-6)
        self.units = max(1, min(4 * self.units, int(rate * _SLICE_S)))


def _walk_back(parent_mask: I32, parent_v: I32, full: int, v: int) -> list[int]:
    order = []
    mask = full
    while v >= 0:
        order.append(v)
        mask, v = int(parent_mask[mask, v]), int(parent_v[mask, v])
    return order[::-1]


def _shortest_paths(dist: F64, budget: _Budget) -> F64 | None:
    """All-pairs shortest paths (Floyd–Warshall; equals ``dist`` for metric distances), or
    None if the deadline strikes first."""
    out: F64 = np.array(dist, dtype=np.float64, order="C")
    n = out.shape[0]
    k = 0
    step = max(1, (1 << 22) // max(n * n, 1))
    while k < n:
        if time.perf_counter() >= budget.deadline:
            return None
        tick = time.perf_counter()
        _relax_through(out, k, min(k + step, n))
        k += step
        spent = max(time.perf_counter() - tick, 1e-6)
        step = max(1, min(4 * step, int(step * _SLICE_S / spent)))
    return out


def _finish_bounds(instance: Instance, paths: F64, close: F64) -> F64:
    """``b[v, t] = min over w seeing t of path(v, w) + close(w)``: a lower bound on the rest of
    the tour from ``v`` while ``t`` is unseen, with ``paths`` shortest-path distances and
    ``close`` the shortest cost of ending the tour from each viewpoint."""
    n, m = instance.n_viewpoints, instance.n_targets
    covers = instance.covers.dense()
    out = np.empty((n, m), dtype=np.float64)
    via = paths + close[None, :]
    for t in range(m):
        out[:, t] = via[:, covers[:, t]].min(axis=1)
    return out


def greedy_order(instance: Instance) -> list[int]:
    """A tour that sees every target, built in a blink: repeatedly insert, at its cheapest
    place, the viewpoint that sees the most unseen targets per metre added.

    Parameters
    ----------
    instance
        The GTSP with cover sets, with or without a depot.

    Returns
    -------
    list of int
        Viewpoints in flight order (after the depot, if there is one).
    """
    covers = instance.covers.dense()
    unseen = np.ones(instance.n_targets, dtype=bool)
    order: list[int] = []
    dist = instance.matrix()
    while unseen.any():
        gain = covers[:, unseen].sum(axis=1).astype(np.float64)
        if not order:
            if instance.depot_distance is not None:
                added = instance.depot_distance[0] + instance.depot_distance[1]
            else:
                added = np.zeros(instance.n_viewpoints)
        else:
            idx = np.asarray(order, dtype=np.int64)
            if instance.depot_distance is not None:
                # Legs depot -> order[0], ..., order[-1] -> depot, as (from, to) columns.
                into = np.column_stack([instance.depot_distance[0][:, None], dist[idx].T])
                out_of = np.column_stack([dist[:, idx], instance.depot_distance[1][:, None]])
                legs = np.concatenate(
                    [
                        [instance.depot_distance[0, idx[0]]],
                        dist[idx[:-1], idx[1:]],
                        [instance.depot_distance[1, idx[-1]]],
                    ]
                )
            else:
                into = dist[idx].T
                out_of = dist[:, np.roll(idx, -1)]
                legs = dist[idx, np.roll(idx, -1)]
            # Inserting v between stops a and b adds d(a, v) + d(v, b) - d(a, b).
            detour = into + out_of - legs[None, :]
            place = np.argmin(detour, axis=1)
            added = detour[np.arange(len(detour)), place]
        score = np.where(gain > 0, gain / (np.maximum(added, 0.0) + 1e-9), -np.inf)
        v = int(np.argmax(score))
        if order:
            order.insert(int(place[v]) + (0 if instance.depot_distance is not None else 1), v)
        else:
            order.append(v)
        unseen &= ~covers[v]
    return order


def quick_tour(instance: Instance, deadline: float, seed: int = 0) -> list[int]:
    """A good tour soon: the greedy one, improved by a short large-neighbourhood search
    where the instance's partition form is small.

    Parameters
    ----------
    instance
        The GTSP with cover sets, with or without a depot.
    deadline
        ``time.perf_counter()`` value by which the search answers (it always answers).
    seed
        Seed of the search.

    Returns
    -------
    list of int
        Viewpoints in flight order (after the depot, if there is one).
    """
    greedy = greedy_order(instance)
    nodes = partition_nodes(instance)
    if nodes * nodes * 8.0 > _SEED_MATRIX_BYTES:
        return greedy
    clustered = cluster_instance(instance)
    search = SearchSettings(trials=2, final_restarts=1)
    # The deadline, not the settings' time limit, bounds the search.
    cycle = solve_clustered(clustered, SolveSettings(seed=seed), search, deadline)
    found = viewpoint_order(clustered, cycle)
    return min((found, greedy), key=instance.tour_length)


def search_exact(
    instance: Instance,
    seed_order: list[int] | None = None,
    deadline: float = math.inf,
    work_limit: int | None = None,
) -> ExactResult:
    """The shortest tour over the instance's viewpoints, or the best one found in time.

    Parameters
    ----------
    instance
        The GTSP with cover sets, at most :data:`MAX_TARGETS` targets.
    seed_order
        A tour that sees every target, to start from; a greedy one when None.
    deadline
        ``time.perf_counter()`` value at which to stop and answer.
    work_limit
        Work units the DP may spend (see the module docstring); unlimited when None.

    Returns
    -------
    ExactResult
        The best tour found, a lower bound on every tour over the viewpoints, and whether the
        DP ran to the end (then the tour is optimal over them).

    Raises
    ------
    SettingsError
        With more than :data:`MAX_TARGETS` targets.
    """
    m, n = instance.n_targets, instance.n_viewpoints
    if m > MAX_TARGETS:
        raise SettingsError.about(
            "the exact solver handles at most {most} targets, not {m}: use {solver} heuristic",
            most=MAX_TARGETS,
            m=m,
        )
    order = greedy_order(instance) if seed_order is None else list(seed_order)
    length = instance.tour_length(order)
    budget = _Budget(deadline, work_limit)
    if m == 0:
        return ExactResult(tuple(order), length, length, True, 0)

    def stopped(bound: float) -> ExactResult:
        return ExactResult(tuple(order), length, min(bound, length), False, budget.work)

    # Bounds must hold even where distances break the triangle inequality (GTSPLIB rounding),
    # so they are built on shortest paths.
    matrix = instance.matrix()
    paths = _shortest_paths(matrix, budget)
    if paths is None:
        return stopped(0.0)
    cover = _masks(instance)
    full = (1 << m) - 1
    dist = np.array(matrix, dtype=np.float64, order="C")  # a copy: never mutate
    np.fill_diagonal(dist, np.inf)
    cost = np.empty((full + 1, n), dtype=np.float64)
    parent_mask = np.empty((full + 1, n), dtype=np.int32)
    parent_v = np.empty((full + 1, n), dtype=np.int32)
    # Tours of the seed's length need not be found again.
    best = np.array([length * (1.0 + 1e-12)])
    best_v = np.full(1, -1, dtype=np.int64)
    starts: list[tuple[F64, F64, F64]] = []
    if instance.depot_distance is not None:
        to_depot = instance.depot_distance[1]
        close = np.minimum(to_depot, (paths + to_depot[None, :]).min(axis=1))
        starts.append((instance.depot_distance[0].copy(), to_depot.copy(), close))
    else:
        for s in _starts(instance).tolist():
            first = np.full(n, np.inf)
            first[s] = 0.0
            starts.append((first, matrix[:, s].copy(), paths[:, s].copy()))
    for k, (first, last, close) in enumerate(starts):
        for row in range(0, full + 1, _RESET_ROWS):
            if time.perf_counter() >= deadline:
                return stopped(min(float(best[0]), _unstarted_bound(instance, paths, starts[k:])))
            cost[row : row + _RESET_ROWS] = np.inf
        bounds = _finish_bounds(instance, paths, close)
        if k == 0:
            budget.deadline = deadline - _bound_reserve(cost, last, bounds)
        _held_karp_start(cover, first, best[0], cost, parent_mask, parent_v)
        best_v[0] = -1
        mask = 1
        while mask <= full and not budget.spent():
            tick = time.perf_counter()
            mask, units = _held_karp_masks(
                cover,
                dist,
                last,
                bounds,
                full,
                mask,
                budget.slice_units(),
                best,
                best_v,
                cost,
                parent_mask,
                parent_v,
            )
            budget.record(units, time.perf_counter() - tick)
        if best_v[0] >= 0:
            order = _walk_back(parent_mask, parent_v, full, int(best_v[0]))
            length = instance.tour_length(order)
        if mask <= full:
            bound = _frontier_bound(cost, last, bounds, full, mask, float(best[0]))
            return stopped(min(bound, _unstarted_bound(instance, paths, starts[k + 1 :])))
    return ExactResult(tuple(order), length, length, True, budget.work)


def _bound_reserve(cost: F64, last: F64, bounds: F64) -> float:
    """Seconds to keep in hand for reading the whole table back into a bound, timed on its
    last rows (still unset) with room for the states the DP will have filled by then."""
    rows = min(_RESET_ROWS, cost.shape[0])
    full = cost.shape[0] - 1
    tick = time.perf_counter()
    _frontier_bound(cost, last, bounds, full, full + 1 - rows, math.inf)
    return float(_BOUND_MARGIN * (time.perf_counter() - tick) * cost.shape[0] / rows)


def _unstarted_bound(instance: Instance, paths: F64, starts: list[tuple[F64, F64, F64]]) -> float:
    """A lower bound on tours from starts the DP has not begun: every target the first
    viewpoint does not see must still be reached and the tour closed (inf without starts)."""
    out = math.inf
    for first, _last, close in starts:
        reachable = np.isfinite(first)
        # From the depot the first move is itself a leg; from a start viewpoint it is free.
        via = (first[reachable, None] + paths[reachable] + close[None, :]).min(axis=0)
        need = np.where(instance.covers.dense(), via[:, None], np.inf).min(axis=0)
        out = min(out, float(need.max()) if need.size else 0.0)
    return out


def solve_exact(
    instance: Instance, upper_bound: float = math.inf
) -> tuple[list[int], float] | None:
    """The optimal viewpoint order and its length, or None if none is shorter than
    ``upper_bound``."""
    found = search_exact(instance)
    if found.length >= upper_bound * (1.0 + 1e-12):
        return None
    return list(found.order), found.length


def warm_up() -> None:
    """Compile the DP kernels, or load them from numba's cache, on a tiny instance."""
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tiny = Instance(covers=Covers.identity(3), distance=euclidean_matrix(points))
    seed = quick_tour(tiny, time.perf_counter() + 60.0)
    search_exact(tiny, seed)
    # A stop at once, so the bound's kernel is compiled too.
    search_exact(tiny, seed, work_limit=1)


class ExactSolver:
    """Proven optimum over the instance's viewpoints by dynamic programming, or within the
    time limit the best tour found and a lower bound (not proven).

    ``work_limit`` caps the DP's work units (see the module docstring), so that where it stops
    does not depend on the machine.
    """

    name = "exact"

    def __init__(self, work_limit: int | None = None) -> None:
        self.work_limit = work_limit

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        """Solve ``instance`` within ``settings.time_limit_s``.

        Parameters
        ----------
        instance
            The GTSP with cover sets, at most :data:`MAX_TARGETS` targets.
        settings
            The time limit, and the seed of the search that finds the first tour.

        Returns
        -------
        Tour
            Proven optimal over the viewpoints when the DP finished; else the best tour found,
            with a note giving the DP's bound over the viewpoints.
        """
        started = time.perf_counter()
        m, n = instance.n_targets, instance.n_viewpoints
        if m > MAX_TARGETS:
            raise SettingsError.about(
                "the exact solver handles at most {most} targets, not {m}: use {solver} heuristic",
                most=MAX_TARGETS,
                m=m,
            )
        work = exact_work(instance)
        what = f"the exact solver's tables for {m} targets and {n} viewpoints"
        fix = "use --solver heuristic or fewer --samples"
        if work.memory_bytes > MEMORY_BUDGET_BYTES * 4:
            raise SettingsError.about(
                "{what} would need {need:.1f} GiB, over the exact solver's {most:.1f} GiB: "
                "use {solver} heuristic or fewer {samples}",
                what=what,
                need=work.memory_bytes / 2**30,
                most=MEMORY_BUDGET_BYTES * 4 / 2**30,
            )
        # Beside the DP tables: the distance copy, shortest paths and the bound tables.
        require_memory(work.memory_bytes + 4.0 * 8.0 * float(n) * float(n), what, fix)
        deadline = started + settings.time_limit_s
        seed = quick_tour(instance, started + _SEED_SHARE * settings.time_limit_s, settings.seed)
        found = search_exact(instance, seed, deadline, self.work_limit)
        notes: tuple[str, ...] = ()
        # Over the candidates only: a planning instance's bound must hold anywhere on the plane.
        bound = geometric_lower_bound(instance)
        if instance.geometry is None:
            bound = max(bound, found.lower_bound)
        if not found.proven:
            notes = (
                f"exact solver stopped at the time limit: best tour found kept; no tour over "
                f"the candidate viewpoints is shorter than {found.lower_bound:.1f}",
            )
        return finish_tour(
            instance,
            list(found.order),
            lower_bound=bound,
            solver=self.name,
            solve_s=time.perf_counter() - started,
            proven=found.proven,
            notes=notes,
        )
