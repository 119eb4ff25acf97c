"""A lower bound on the makespan of any fleet plan: the farthest target's out-and-back, the
work shared among the vehicles, the pigeonhole over targets far apart, and the sorties'
bound shared among the vehicles.

Nothing here sees a raster: only the vehicles' instances, their geometry and flight models.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import minimum_spanning_tree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import greedy_disjoint
from urpt_gcs.bound.sorties import CHAIN_GAPS, SortieBound, SortieBudget, least_extra_s
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.solvers.fleet import Vehicle

__all__ = [
    "TREE_BOUND_MAX_TARGETS",
    "MakespanBound",
    "fleet_budget",
    "makespan_bound",
    "tree_bound_m",
]


@dataclass(frozen=True, slots=True)
class MakespanBound:
    """A lower bound on the makespan of any fleet plan, and its parts."""

    reach_s: float
    share_s: float
    pigeonhole_s: float = 0.0
    sorties_s: float = 0.0

    @property
    def bound_s(self) -> float:
        return max(self.reach_s, self.share_s, self.pigeonhole_s, self.sorties_s)


# Above this many targets the spanning-tree bound (a dense matrix) is left out.
TREE_BOUND_MAX_TARGETS = 2000


def tree_bound_m(
    targets_xy: FloatArray, radius_m: FloatArray, home_xy: tuple[float, float]
) -> float:
    """A lower bound on the total length of closed tours from ``home_xy`` that between them
    pass within ``radius_m[t]`` of every target ``t``.

    Let ``p_t`` be where target ``t`` is seen. The tours, all through home, form a connected
    graph through home and every ``p_t``, so their total length is at least the minimum
    spanning tree of those points; and ``|p_i - p_j| >= |c_i - c_j| - r_i - r_j``, so that tree
    weighs at least the minimum spanning tree of the centres under those shortened (never
    negative) distances. None beyond :data:`TREE_BOUND_MAX_TARGETS` targets.
    """
    m = len(targets_xy)
    if m == 0 or m > TREE_BOUND_MAX_TARGETS:
        return 0.0
    xy = np.vstack([np.asarray(home_xy, dtype=np.float64)[None, :], targets_xy])
    r = np.concatenate([[0.0], np.asarray(radius_m, dtype=np.float64)])
    d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    w = np.maximum(d - r[:, None] - r[None, :], 0.0)
    # The sparse routine reads a zero as no edge: a hair above it keeps every edge.
    w = np.where(w > 0.0, w, 1e-12)
    np.fill_diagonal(w, 0.0)
    return max(float(minimum_spanning_tree(w).sum()) - 1e-9 * m, 0.0)


def fleet_budget(vehicles: Sequence[Vehicle]) -> SortieBudget:
    """What one sortie of any of the vehicles may spend at the most: the longest endurance,
    and the least take-off and landing, stop, time per metre and, at every gap of any
    vehicle's, leg overhead. Every vehicle's sorties are within it, so a bound of sorties
    within it holds for all of theirs together."""
    if not vehicles:
        raise ValueError("fleet_budget needs at least one vehicle")
    budgets = [
        SortieBudget.of(
            v.model, v.altitude_rel_m, math.inf if v.endurance_s is None else v.endurance_s
        )
        for v in vehicles
    ]
    gaps = sorted({g * v.model.cruise_overhead()[0] for v in vehicles for g in CHAIN_GAPS})
    return SortieBudget(
        endurance_s=max(b.endurance_s for b in budgets),
        ends_s=min(b.ends_s for b in budgets),
        stop_s=min(b.stop_s for b in budgets),
        per_metre_s=min(b.per_metre_s for b in budgets),
        cruise_per_metre_s=min(b.cruise_per_metre_s for b in budgets),
        return_per_metre_s=min(b.return_per_metre_s for b in budgets),
        chains=tuple(
            (g, min(least_extra_s(v.model, g) for v in vehicles)) for g in gaps if math.isfinite(g)
        ),
    )


def makespan_bound(
    vehicles: Sequence[Vehicle],
    single_bound_m: float | None,
    sorties: SortieBound | None = None,
) -> MakespanBound:
    """A lower bound on the makespan of any plan in which the vehicles between them see
    every target.

    ``reach_s``: some vehicle sees each target ``t``, from a point of its layer's region of
    ``t``, which lies within the cone radius of ``t`` (the instance geometry's
    ``cone_radius_m``, the widest the camera reaches). So that vehicle flies a sortie out to a
    point at least ``d_k(t) = max(|home_k - t| - r_k(t), 0)`` from its home, stops there and
    comes back: by :meth:`Vehicle.out_and_back_s`. A rest-to-rest leg's least time grows
    with its length and is subadditive (two legs flown one after the other, stopping between,
    are one way of flying their sum from rest to rest), so a chain of legs of total length at
    least ``d`` takes at least one leg of length ``d``; the profile with the faster of the two
    speeds is never slower than the other. The makespan is at least
    ``max_t min_k out_and_back_k(d_k(t))``.

    ``share_s``: the total length ``L`` of all the vehicles' flights, with ``J`` the sum of
    the homes' distances from the first vehicle's home ``h_1``, is at least
    ``single_bound_m - 2 J`` (the flights joined at their homes, each home joined to ``h_1``
    by a return trip, make one closed tour from ``h_1`` that sees every target:
    ``single_bound_m`` bounds any such tour, from any layer flown, which is the caller's to
    ensure) and at least :func:`tree_bound_m` from ``h_1`` less ``J`` (every home joined to
    ``h_1`` once), at the widest cone over the layers. A sortie's way home is no longer
    than its way out to its last stop, so at most half of a sortie is flown at the return
    speed and the rest at the cruise speed, each leg no faster than its length over its
    speed. No point sees two targets whose cones of the widest radius are disjoint, so there
    are at least as many stops as a greedy set of such targets holds, each costing its hold.
    Those legs and stops, ``W`` seconds in all, are shared by at most K vehicles: one of them
    flies at least ``W / K``, with a take-off and landing for each sortie, and with an
    endurance ``E`` a sortie holds at most ``E - ends`` of it, so that vehicle's flight is at
    least ``max(ends + W / K, W / K * E / (E - ends))`` (the least of these over the vehicles'
    models).

    ``pigeonhole_s``: see :func:`_pigeonhole_s`.

    ``sorties_s``: ``sorties`` (when given) bounds every set of sorties from the vehicles'
    one home within :func:`fleet_budget` whose stops photograph every target, from any layer
    flown (the caller's to ensure). The vehicles' sorties are such a set; if ``K'`` of the
    vehicles fly, there are at least ``K'`` sorties, and one of those vehicles flies at least
    ``1 / K'`` of their total. So the makespan is at least the least over ``K' = 1..K`` of
    the sorties' least total time, at least ``K'`` of them, over ``K'``.
    """
    if not vehicles:
        raise ValueError("makespan_bound needs at least one vehicle")
    geometry = [v.instance.geometry for v in vehicles]
    reach = pigeonhole = 0.0
    radius = None
    if all(g is not None for g in geometry):
        per_vehicle = []
        for vehicle, g in zip(vehicles, geometry, strict=True):
            assert g is not None
            hx, hy = vehicle.home_xy
            d = np.hypot(g.targets_xy[:, 0] - hx, g.targets_xy[:, 1] - hy)
            per_vehicle.append(vehicle.out_and_back_s(np.maximum(d - g.cone_radius_m, 0.0)))
        least = np.min(np.vstack(per_vehicle), axis=0)
        reach = float(least.max())
        radius = np.max(np.vstack([g.cone_radius_m for g in geometry if g is not None]), axis=0)
        pigeonhole = _pigeonhole_s(vehicles, radius, least)
    h1 = np.asarray(vehicles[0].home_xy)
    joins = math.fsum(float(np.hypot(*(np.asarray(v.home_xy) - h1))) for v in vehicles)
    length = 0.0
    if single_bound_m is not None:
        length = max(length, single_bound_m - 2.0 * joins)
    stops = 0
    g0 = geometry[0]
    if radius is not None and g0 is not None:
        length = max(length, tree_bound_m(g0.targets_xy, radius, vehicles[0].home_xy) - joins)
        stops = len(greedy_disjoint(g0.targets_xy, float(radius.max())))
    per_m = min(_seconds_per_metre(v.model) for v in vehicles)
    work = per_m * length + stops * min(v.model.stop_s for v in vehicles)
    share = 0.0
    if work > 0.0:
        each = work / len(vehicles)
        ends = [
            v.model.takeoff_s(v.altitude_rel_m) + v.model.landing_s(v.altitude_rel_m)
            for v in vehicles
        ]
        factor = min(
            e / (e - end) if e is not None and e > end else 1.0
            for e, end in zip((v.endurance_s for v in vehicles), ends, strict=True)
        )
        share = max(min(ends) + each, factor * each)
    shared = 0.0
    if sorties is not None:
        count = len(vehicles)
        shared = min(sorties.least_s(k) / k for k in range(1, count + 1))
    return MakespanBound(
        reach_s=reach, share_s=share, pigeonhole_s=pigeonhole, sorties_s=float(shared)
    )


# Targets tried for the pigeonhole bound beyond the K + 1 it needs; all subsets up to this K.
_PIGEON_SPARE = 3
_PIGEON_SUBSETS_MAX_K = 6
# Up to this K the targets farthest to reach are tried beside those chosen apart.
_PIGEON_BOTH_MAX_K = 4


def _pigeonhole_s(vehicles: Sequence[Vehicle], radius_m: FloatArray, reach_s: FloatArray) -> float:
    """Among K + 1 targets no point sees two of (their widest cones disjoint), some vehicle
    sees two, from two stops, in one sortie or two; either takes at least a take-off, the
    way out to one region, across to the other, back home and a landing, with two stops
    (two sorties take longer still: the way across is no longer than the two ways home).
    The least such flight over the pairs of the set and the vehicles bounds the makespan;
    the set is chosen among targets no point sees two of, taken farthest to reach first,
    and among the farthest to reach as they come."""
    k_count = len(vehicles)
    g = vehicles[0].instance.geometry
    assert g is not None
    m = len(g.targets_xy)
    if m < k_count + 1:
        return 0.0
    # The farthest to reach first, each kept if no point sees it and one already kept.
    chosen: list[int] = []
    for t in np.argsort(-reach_s, kind="stable").tolist():
        apart = (
            np.hypot(*(g.targets_xy[chosen] - g.targets_xy[t]).T) > radius_m[chosen] + radius_m[t]
        )
        if apart.all():
            chosen.append(int(t))
            if len(chosen) == k_count + 1 + _PIGEON_SPARE:
                break
    # And the farthest to reach as they come, whose subsets may be apart too.
    farthest = np.argsort(-reach_s, kind="stable")[: k_count + 1 + _PIGEON_SPARE].tolist()
    pool = list(dict.fromkeys(chosen + (farthest if k_count <= _PIGEON_BOTH_MAX_K else [])))
    if len(pool) < k_count + 1:
        return 0.0
    pick = np.asarray(pool, dtype=np.int64)
    xy, r = g.targets_xy[pick], radius_m[pick]
    across = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    disjoint = across > r[:, None] + r[None, :]
    gap = np.maximum(across - r[:, None] - r[None, :], 0.0)
    pair = np.full(across.shape, math.inf)
    for vehicle in vehicles:
        vg = vehicle.instance.geometry
        assert vg is not None
        hx, hy = vehicle.home_xy
        out = np.maximum(np.hypot(xy[:, 0] - hx, xy[:, 1] - hy) - vg.cone_radius_m[pick], 0.0)
        model = vehicle.model

        def fastest(d: FloatArray, model: FlightModel = model) -> FloatArray:
            f: FloatArray = np.minimum(model.leg_s(d), model.return_s(d))
            return f

        ends = model.takeoff_s(vehicle.altitude_rel_m) + model.landing_s(vehicle.altitude_rel_m)
        legs = fastest(out)
        flight = ends + 2.0 * model.stop_s + legs[:, None] + fastest(gap) + legs[None, :]
        pair = np.minimum(pair, flight)
    candidates = range(len(pick))
    subsets: Iterable[tuple[int, ...]] = (
        itertools.combinations(candidates, k_count + 1)
        if k_count <= _PIGEON_SUBSETS_MAX_K
        else [tuple(candidates)[: k_count + 1]]
    )
    best = 0.0
    for subset in subsets:
        idx = np.asarray(subset)
        block = disjoint[np.ix_(idx, idx)]
        np.fill_diagonal(block, True)
        if not block.all():
            continue
        values = pair[np.ix_(idx, idx)][np.triu_indices(len(idx), 1)]
        best = max(best, float(values.min()))
    return best


def _seconds_per_metre(model: FlightModel) -> float:
    """The least time a metre of flight can take: at most half of it at the return speed
    (a sortie's way home is no longer than its way out), the rest at the cruise speed."""
    cruise, back = model.cruise_m_s, model.return_m_s
    if back <= cruise:
        return 1.0 / cruise
    return 0.5 * (1.0 / cruise + 1.0 / back)
