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

Work is about ``starts * n * sum_v 2^(m - |cover(v)|)`` state expansions and memory
``2^m * n * 20`` bytes; :func:`exact_work` estimates both so ``--solver auto`` can decide.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from urpt_gcs.errors import SettingsError
from urpt_gcs.gtsp import Instance, euclidean_matrix
from urpt_gcs.inputs import require_memory
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour, geometric_lower_bound

# What `auto` lets the exact solver spend: state expansions and bytes of DP tables.
WORK_BUDGET = 3.0e9
MEMORY_BUDGET_BYTES = 1.5e9
MAX_TARGETS = 20


@dataclass(frozen=True, slots=True)
class ExactWork:
    """Estimated cost of solving an instance exactly."""

    expansions: float
    memory_bytes: float
    starts: int

    @property
    def fits_budget(self) -> bool:
        return self.expansions <= WORK_BUDGET and self.memory_bytes <= MEMORY_BUDGET_BYTES


def _masks(instance: Instance) -> npt.NDArray[np.int64]:
    weights = np.left_shift(np.int64(1), np.arange(instance.n_targets, dtype=np.int64))
    masks: npt.NDArray[np.int64] = (instance.covers.astype(np.int64) * weights).sum(axis=1)
    return masks


def _starts(instance: Instance) -> npt.NDArray[np.int64]:
    """Viewpoints the DP starts from: none (depot) or those of the rarest target."""
    if instance.has_depot:
        return np.zeros(0, dtype=np.int64)
    counts = instance.covers.sum(axis=0)
    rarest = int(np.argmin(counts))
    return np.flatnonzero(instance.covers[:, rarest]).astype(np.int64)


def exact_work(instance: Instance) -> ExactWork:
    """Estimate the work and memory :class:`ExactSolver` needs for ``instance``."""
    m, n = instance.n_targets, instance.n_viewpoints
    if m > MAX_TARGETS:
        return ExactWork(math.inf, math.inf, 0)
    sizes = instance.covers.sum(axis=1)
    per_start = float(n) * float(np.sum(np.exp2(m - sizes)))
    starts = max(len(_starts(instance)), 1)
    return ExactWork(per_start * starts, float(2**m) * n * 20.0, starts)


@numba.njit(cache=True)
def _held_karp(
    cover: npt.NDArray[np.int64],
    dist: npt.NDArray[np.float64],
    first: npt.NDArray[np.float64],
    last: npt.NDArray[np.float64],
    finish_bound: npt.NDArray[np.float64],
    full: int,
    upper: float,
    cost: npt.NDArray[np.float64],
    parent_mask: npt.NDArray[np.int64],
    parent_v: npt.NDArray[np.int32],
) -> tuple[float, int]:
    """Fill the DP tables; return the best tour cost below ``upper`` and its last viewpoint.

    ``first[v]`` is the cost of the first move to ``v`` (inf where ``v`` may not come first),
    ``last[v]`` the cost of closing the tour from ``v``; ``finish_bound[v, t]`` a lower bound
    on the rest of the tour from ``v`` when target ``t`` is still unseen.
    """
    n = cover.shape[0]
    m = finish_bound.shape[1]
    cost[:, :] = np.inf
    for v in range(n):
        if first[v] < upper:
            cost[cover[v], v] = first[v]
            parent_mask[cover[v], v] = -1
            parent_v[cover[v], v] = -1
    best = upper
    best_v = -1
    for mask in range(1, full + 1):
        row = cost[mask]
        for v in range(n):
            here = row[v]
            if here >= best:
                continue
            if mask == full:
                total = here + last[v]
                if total < best:
                    best = total
                    best_v = v
                continue
            # Prune: some unseen target still has to be reached and the tour closed.
            need = 0.0
            for t in range(m):
                if not (mask >> t) & 1 and finish_bound[v, t] > need:
                    need = finish_bound[v, t]
            if here + need >= best:
                continue
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
    return best, best_v


def _walk_back(
    parent_mask: npt.NDArray[np.int64], parent_v: npt.NDArray[np.int32], full: int, v: int
) -> list[int]:
    order = []
    mask = full
    while v >= 0:
        order.append(v)
        mask, v = int(parent_mask[mask, v]), int(parent_v[mask, v])
    return order[::-1]


@numba.njit(cache=True)
def _shortest_paths(dist: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """All-pairs shortest paths (Floyd–Warshall); equals ``dist`` for metric distances."""
    out: npt.NDArray[np.float64] = dist.copy()
    n = out.shape[0]
    for k in range(n):
        for i in range(n):
            dik = out[i, k]
            for j in range(n):
                c = dik + out[k, j]
                if c < out[i, j]:
                    out[i, j] = c
    return out


def _finish_bounds(
    instance: Instance, paths: npt.NDArray[np.float64], close: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """``b[v, t] = min over w seeing t of path(v, w) + close(w)``: a lower bound on the rest of
    the tour from ``v`` while ``t`` is unseen, with ``paths`` shortest-path distances and
    ``close`` the shortest cost of ending the tour from each viewpoint."""
    n, m = instance.covers.shape
    out = np.empty((n, m), dtype=np.float64)
    via = paths + close[None, :]
    for t in range(m):
        out[:, t] = via[:, instance.covers[:, t]].min(axis=1)
    return out


def solve_exact(
    instance: Instance, upper_bound: float = math.inf
) -> tuple[list[int], float] | None:
    """The optimal viewpoint order and its length, or None if none is shorter than
    ``upper_bound``."""
    m, n = instance.n_targets, instance.n_viewpoints
    if m > MAX_TARGETS:
        raise SettingsError(
            f"the exact solver handles at most {MAX_TARGETS} targets, not {m}: "
            "use --solver heuristic"
        )
    cover = _masks(instance)
    full = (1 << m) - 1
    dist = np.array(instance.distance, dtype=np.float64, order="C")  # a copy: never mutate
    np.fill_diagonal(dist, np.inf)
    cost = np.empty((full + 1, n), dtype=np.float64)
    parent_mask = np.empty((full + 1, n), dtype=np.int64)
    parent_v = np.empty((full + 1, n), dtype=np.int32)
    best: tuple[list[int], float] | None = None
    upper = upper_bound * (1.0 + 1e-12)
    # Bounds must hold even where distances break the triangle inequality (GTSPLIB rounding),
    # so they are built on shortest paths.
    paths = _shortest_paths(np.ascontiguousarray(instance.distance, dtype=np.float64))
    starts: list[
        tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]
    ] = []
    if instance.depot_distance is not None:
        to_depot = instance.depot_distance[1]
        close = np.minimum(to_depot, (paths + to_depot[None, :]).min(axis=1))
        starts.append((instance.depot_distance[0].copy(), to_depot.copy(), close))
    else:
        for s in _starts(instance).tolist():
            first = np.full(n, np.inf)
            first[s] = 0.0
            starts.append((first, instance.distance[:, s].copy(), paths[:, s].copy()))
    for first, last, close in starts:
        bounds = _finish_bounds(instance, paths, close)
        length, v = _held_karp(
            cover, dist, first, last, bounds, full, upper, cost, parent_mask, parent_v
        )
        if v >= 0 and length < upper:
            upper = length
            best = (_walk_back(parent_mask, parent_v, full, v), length)
    return best


def warm_up() -> None:
    """Compile the DP kernels, or load them from numba's cache, on a tiny instance."""
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tiny = Instance(covers=np.eye(3, dtype=bool), distance=euclidean_matrix(points))
    solve_exact(tiny)


class ExactSolver:
    """Proven optimum over the instance's viewpoints by dynamic programming."""

    name = "exact"

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        started = time.perf_counter()
        m, n = instance.n_targets, instance.n_viewpoints
        work = exact_work(instance)
        what = f"the exact solver's tables for {m} targets and {n} viewpoints"
        fix = "use --solver heuristic or fewer --samples"
        if m <= MAX_TARGETS and work.memory_bytes > MEMORY_BUDGET_BYTES * 4:
            raise SettingsError(
                f"{what} would need {work.memory_bytes / 2**30:.1f} GiB, over the exact "
                f"solver's {MEMORY_BUDGET_BYTES * 4 / 2**30:.1f} GiB: {fix}"
            )
        if m <= MAX_TARGETS:
            # Beside the DP tables: the distance copy, shortest paths and the bound tables.
            require_memory(work.memory_bytes + 4.0 * 8.0 * float(n) * float(n), what, fix)
        found = solve_exact(instance)
        if found is None:
            raise SettingsError("internal check failed: the exact solver found no tour")
        order, _ = found
        return finish_tour(
            instance,
            order,
            lower_bound=geometric_lower_bound(instance),
            solver=self.name,
            solve_s=time.perf_counter() - started,
            proven=True,
        )
