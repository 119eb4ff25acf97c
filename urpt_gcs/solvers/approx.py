"""The paper's constant-factor approximation for the TSP with visibility neighbourhoods.

With the flight plane at ``H``, the highest terrain at ``l`` and camera half-angle ``delta``:

1. inner discs of radius ``r = (H - l) tan(delta)`` around every target;
2. a maximal set of pairwise disjoint inner discs (greedy);
3. a TSP tour over their centres (solved exactly here, so ``epsilon = 0``, unless the time
   limit or the exact solver's budget stops it first: then the best tour found, reported);
4. the tour followed, with a full turn around each chosen disc's circumference where it is
   entered, then on to the centre (the nadir of that disc's target).

Every inner disc meets the path: a disc not chosen overlaps a chosen one, and the circle
around the chosen centre passes through it. The paper takes ``d_i`` inside the visibility
region; terrain close to a target (a wall beside it) can break that, so here each target is
photographed from the first point of the path that is checked, on the DEM, to see it; a target
seen from no point of the path gets an out-and-back detour to its nadir (reported). The flown
tour visits those photo points in path order, which is never longer than the path.

Bounds reported: the paper's lower bound ``k/2 * alpha * R`` from ``k`` disjoint outer discs
of radius ``R = (H - z_min) tan(delta)`` (alpha = 0.4786, k >= 3), and the theorem's factor
``(1 + 16 h / (alpha (h - l))) + 16 pi h / (alpha (h - l))`` with ``h`` and ``l`` measured from
the lowest target. Two steps of the paper's proof do not hold for every terrain (the inner
disc can be partly hidden; a tour through every region need not touch every inner disc), so
the factor is reported, and checked against proven optima in ``urpt-gcs bench paper``, not
assumed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import DISC_PACKING_ALPHA, geometric_lower_bound, greedy_disjoint
from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.instance import Covers, Geometry, Instance
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_placed_tour
from urpt_gcs.solvers.exact import exact_work, quick_tour, search_exact

__all__ = [
    "ApproxBounds",
    "ApproxSolver",
    "paper_factor",
    "paper_path",
]

# Points per circumference at which the path is offered as a photo point.
_CIRCLE_POINTS = 72
# Shares of the time limit for the first tour over the centres, and for the whole path.
_SEED_SHARE = 0.2
_PATH_SHARE = 0.8


@dataclass(frozen=True, slots=True)
class ApproxBounds:
    """The paper's quantities for one instance."""

    inner_radius_m: float
    chosen: int  # m_d: disjoint inner discs
    path_length_m: float  # L_d: the paper's path, circles included
    factor: float  # the theorem's approximation factor
    lower_bound_m: float  # the paper's disc-packing bound
    centre_tour_proven: bool = True  # the centres' tour is the shortest (the paper's epsilon 0)

    def upper_bound_m(self, optimum_m: float) -> float:
        """The theorem's bound on the path for a given optimum."""
        return self.factor * optimum_m


def paper_factor(geometry: Geometry) -> float:
    """The theorem's constant for this flight plane and terrain."""
    z0 = float(np.min(geometry.ground_m))
    h = geometry.altitude_m - z0
    l_top = geometry.terrain_max_m - z0
    if h - l_top <= 0:
        return math.inf
    k = h / (DISC_PACKING_ALPHA * (h - l_top))
    return (1.0 + 16.0 * k) + 16.0 * math.pi * k


def _centre_tour(
    instance: Instance, centres: FloatArray, deadline: float, seed: int
) -> tuple[list[int], bool]:
    """Shortest closed tour over the chosen centres (and the depot), solved exactly where the
    DP fits its budget and the deadline; the order and whether it is proven shortest."""
    k = len(centres)
    if k == 1:
        return [0], True
    depot_distance = None
    if instance.depot_xy is not None:
        d = np.hypot(centres[:, 0] - instance.depot_xy[0], centres[:, 1] - instance.depot_xy[1])
        depot_distance = np.vstack([d, d])
    tsp = Instance(
        covers=Covers.identity(k),
        depot_distance=depot_distance,
        points_xy=centres,
        depot_xy=instance.depot_xy,
    )
    now = time.perf_counter()
    order = quick_tour(tsp, now + _SEED_SHARE * max(deadline - now, 0.0), seed)
    if not exact_work(tsp).fits_budget:
        return order, False
    found = search_exact(tsp, order, deadline)
    return list(found.order), found.proven


def paper_path(
    instance: Instance, deadline: float = math.inf, seed: int = 0
) -> tuple[FloatArray, ApproxBounds]:
    """The paper's path as a polyline (closed through the depot, if any) and its bounds.

    The tour over the chosen centres is the shortest one unless ``deadline`` (a
    ``time.perf_counter()`` value) or the exact solver's budget stops its search first; then
    it is the best found (``ApproxBounds.centre_tour_proven`` is False) and ``seed`` seeds it.
    """
    g = instance.geometry
    if g is None:
        raise SettingsError.about("{solver} approx needs a planning instance (targets on terrain)")
    r = (g.altitude_m - g.terrain_max_m) * math.tan(math.radians(g.fov_deg))
    if r <= 0.0:
        raise SettingsError.about(
            "{solver} approx needs the flight plane above all terrain of the area: raise "
            "{altitude_m} or use {clearance_m}"
        )
    chosen = greedy_disjoint(g.targets_xy, r)
    centres = g.targets_xy[chosen]
    order, proven = _centre_tour(instance, centres, deadline, seed)
    points: list[FloatArray] = []
    if instance.depot_xy is not None:
        points.append(np.asarray(instance.depot_xy, dtype=np.float64))
    previous = points[-1] if points else centres[order[-1]]
    turn = np.linspace(0.0, 2.0 * math.pi, _CIRCLE_POINTS + 1)
    for i in order:
        c = centres[i]
        away = previous - c
        norm = float(np.hypot(*away))
        start = math.atan2(away[1], away[0]) if norm > 1e-9 else 0.0
        ring = c + r * np.column_stack([np.cos(start + turn), np.sin(start + turn)])
        points.extend(ring)  # enter, go once around, back at the entry point
        points.append(c)
        previous = c
    path = np.asarray(points)
    closed = np.vstack([path, path[:1]])
    length = float(np.hypot(*np.diff(closed, axis=0).T).sum())
    bounds = ApproxBounds(
        inner_radius_m=r,
        chosen=len(chosen),
        path_length_m=length,
        factor=paper_factor(g),
        lower_bound_m=geometric_lower_bound(instance),
        centre_tour_proven=proven,
    )
    return path, bounds


class ApproxSolver:
    """The paper's approximation algorithm, every photo point checked on the terrain."""

    name = "approx"

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        started = time.perf_counter()
        # The photo points are checked on the terrain after the path is made: keep them time.
        deadline = started + _PATH_SHARE * settings.time_limit_s
        path, bounds = paper_path(instance, deadline, settings.seed)
        assert instance.oracle is not None and instance.geometry is not None
        on_path = path[1:] if instance.depot_xy is not None else path
        sees = instance.oracle(on_path)
        # Photo points keyed by their position along the path; a detour sorts right after
        # the point it leaves from.
        stops: dict[float, FloatArray] = {}
        detours: list[int] = []
        for t in range(instance.n_targets):
            hits = np.flatnonzero(sees[:, t])
            if hits.size:
                k = int(hits[0])
                stops.setdefault(float(k), on_path[k])
                continue
            nadir = instance.geometry.targets_xy[t]
            k = int(np.argmin(np.hypot(*(on_path - nadir).T)))
            stops[float(k)] = on_path[k]
            stops[k + 0.5 - 0.001 * len(detours)] = nadir
            detours.append(t)
        points = np.asarray([stops[k] for k in sorted(stops)])
        notes: tuple[str, ...] = (
            f"paper path {bounds.path_length_m:.1f} m through {bounds.chosen} disjoint inner "
            f"discs of radius {bounds.inner_radius_m:.1f} m; theorem factor {bounds.factor:.1f}",
        )
        if not bounds.centre_tour_proven:
            notes += (
                "the tour over the disc centres is the best found, not proven shortest (time "
                "limit, or too many centres for the exact solver); the theorem's factor "
                "assumes it is",
            )
        if detours:
            notes += (f"{len(detours)} target(s) unseen from the path; nadir detours added",)
        return finish_placed_tour(
            instance,
            _drop_repeats(points),
            lower_bound=bounds.lower_bound_m,
            solver=self.name,
            solve_s=time.perf_counter() - started,
            notes=notes,
        )


def _drop_repeats(points: FloatArray) -> FloatArray:
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > 1e-9
    out: FloatArray = points[keep]
    return out
