"""The fleet's vehicles as the search sees them, and where the search starts.

The naive split cuts the single-vehicle tour into K contiguous pieces, one per vehicle, of
earliest last landing. A piece may be empty: a vehicle that cannot fly any stop of the tour
within its endurance, or whose flight would only land the fleet later (a vehicle far slower
than the others), is left idle rather than the fleet refused. Where no cut of the tour fits
every vehicle's endurance but the vehicles between them can reach every target (homes at
either end of a long site), :func:`reach_split` gives each target to a vehicle that can
fly to it and back. Only a target no vehicle can reach within its endurance makes the
fleet infeasible (:func:`unreachable`).

Nothing here sees a raster: only instances, points, distances and the flight model.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.problem.flight_time import FlightModel, split_sorties
from urpt_gcs.problem.instance import Instance

__all__ = [
    "Vehicle",
    "naive_split",
    "reach_split",
    "reachable",
    "refuse_unreachable",
    "unreachable",
]


@dataclass(frozen=True, slots=True)
class Vehicle:
    """One vehicle of the fleet as the solver sees it.

    ``instance`` holds the viewpoints of the vehicle's layer over every target, with its home
    as the depot; ``altitude_rel_m`` is the layer's height above that home.
    """

    instance: Instance
    model: FlightModel
    altitude_rel_m: float
    endurance_s: float | None

    def __post_init__(self) -> None:
        if self.instance.depot_xy is None or self.instance.points_xy is None:
            raise ValueError("a fleet vehicle's instance needs its home (depot) and points")

    @property
    def home_xy(self) -> tuple[float, float]:
        assert self.instance.depot_xy is not None
        return self.instance.depot_xy

    def time_s(self, stops_xy: FloatArray) -> float:
        """Flight time of the stops flown in this order, as sorties within the endurance
        (infinite when one stop alone does not fit)."""
        if len(stops_xy) == 0:
            return 0.0
        names = [f"stop {k}" for k in range(1, len(stops_xy) + 1)]
        try:
            sorties = split_sorties(
                stops_xy, self.home_xy, self.altitude_rel_m, self.model, self.endurance_s, names
            )
        except PlanError:
            return math.inf
        return math.fsum(s.flight_time_s for s in sorties)

    def alone_s(self) -> FloatArray:
        """Each viewpoint's flight time as a sortie of its own: take-off, out, the stop,
        back, landing (what :meth:`time_s` gives one stop, whatever the endurance)."""
        m = self.model
        assert self.instance.points_xy is not None
        d = np.hypot(*(self.instance.points_xy - np.asarray(self.home_xy)).T)
        ends = m.takeoff_s(self.altitude_rel_m) + m.stop_s + m.landing_s(self.altitude_rel_m)
        out: FloatArray = m.leg_s(d) + m.return_s(d) + ends
        return out

    def flyable(self) -> BoolArray:
        """The viewpoints it can fly to and back within its endurance."""
        alone = self.alone_s()
        fits: BoolArray = (
            np.ones(alone.shape, dtype=bool)
            if self.endurance_s is None
            else alone <= self.endurance_s
        )
        return fits

    def out_and_back_s(self, distance_m: FloatArray) -> FloatArray:
        """The least flight time of any sortie that reaches a point ``distance_m`` from home
        and stops there: take-off, a way out and a way back each at least that long (at the
        faster of the cruise and return speeds), one stop, the landing."""
        m = self.model
        d = np.asarray(distance_m, dtype=np.float64)
        fastest = np.minimum(m.leg_s(d), m.return_s(d))
        ends = m.takeoff_s(self.altitude_rel_m) + m.landing_s(self.altitude_rel_m)
        out: FloatArray = ends + m.stop_s + 2.0 * fastest
        return out


def reachable(vehicles: Sequence[Vehicle]) -> BoolArray:
    """``(K, targets)``: whether vehicle k can see target t from a viewpoint it can fly to
    and back within its endurance. Any share of such targets is a flight it can make (one
    sortie per stop, if need be)."""
    return np.vstack(
        [v.instance.covers.seen(np.flatnonzero(v.flyable()).tolist()) for v in vehicles]
    )


def unreachable(vehicles: Sequence[Vehicle]) -> IntArray:
    """The targets no vehicle can reach and come back from within its endurance: with none,
    some share of the targets among the vehicles fits every endurance."""
    out: IntArray = np.flatnonzero(~reachable(vehicles).any(axis=0))
    return out


def refuse_unreachable(vehicles: Sequence[Vehicle], names: Sequence[str] | None = None) -> None:
    """Refuse a fleet that no share of the targets fits: a target no vehicle can reach.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        One line naming the first such target (by ``names``, or its number from 1), how
        many there are, the vehicles and the fix.
    """
    out = unreachable(vehicles)
    if out.size == 0:
        return
    first = int(out[0])
    target = f"'{names[first]}'" if names is not None else f"{first + 1}"
    numbers = ", ".join(str(k) for k in range(1, len(vehicles) + 1))
    raise SettingsError.about(
        "no split of the targets among the vehicles fits every vehicle's endurance: none of "
        "vehicles {numbers} can fly to target {target} and back within its endurance "
        "({count} target{s} out of reach): raise the endurance in {fleet_file} or "
        "{endurance_min}, bring a home nearer, or add vehicles",
        numbers=numbers,
        target=target,
        count=out.size,
        s="s" if out.size != 1 else "",
    )


def reach_split(
    vehicles: Sequence[Vehicle], targets: Sequence[int], offsets_s: Sequence[float]
) -> list[list[int]]:
    """Per vehicle, viewpoints of its own instance in flight order that between them see
    every target: the targets taken in the order given (the single tour's, so that near
    ones go together), each not yet seen appended to the vehicle, among those that can reach
    it, whose flight then lands earliest (after its start delay ``offsets_s``).

    Raises
    ------
    urpt_gcs.errors.SettingsError
        A target no vehicle can reach within its endurance (see :func:`unreachable`).
    """
    near = [_flyable_by_target(v) for v in vehicles]
    orders: list[list[int]] = [[] for _ in vehicles]
    seen = np.zeros(vehicles[0].instance.n_targets, dtype=bool)
    for t in targets:
        if seen[t]:
            continue
        best: tuple[float, int, int] | None = None
        for k, vehicle in enumerate(vehicles):
            options = near[k][t]
            if options.size == 0:
                continue
            points = vehicle.instance.points_xy
            assert points is not None
            # Of its viewpoints of t, the one nearest where its flight now ends.
            last = points[orders[k][-1]] if orders[k] else np.asarray(vehicle.home_xy)
            v = int(options[np.argmin(np.hypot(*(points[options] - last).T))])
            order = [*orders[k], v]
            value = offsets_s[k] + vehicle.time_s(points[order])
            if best is None or value < best[0]:
                best = (value, k, v)
        if best is None:
            raise _no_split()
        _, k, v = best
        orders[k].append(v)
        seen |= vehicles[k].instance.covers.seen([v])
    return orders


def _flyable_by_target(vehicle: Vehicle) -> list[IntArray]:
    """Per target, the viewpoints of the vehicle that see it and that it can fly to and
    back within its endurance."""
    vp, tg = vehicle.instance.covers.pairs()
    keep = vehicle.flyable()[vp]
    vp, tg = vp[keep], tg[keep]
    by = np.argsort(tg, kind="stable")
    bounds = np.searchsorted(tg[by], np.arange(vehicle.instance.n_targets + 1))
    return [vp[by[bounds[t] : bounds[t + 1]]] for t in range(vehicle.instance.n_targets)]


def _no_split() -> SettingsError:
    return SettingsError.about(
        "no split of the targets among the vehicles fits every vehicle's endurance: "
        "raise the endurance in {fleet_file} or {endurance_min}, or add vehicles"
    )


def _naive_cut(
    vehicles: Sequence[Vehicle], stops_xy: FloatArray, offsets_s: Sequence[float]
) -> list[int]:
    """Cut points ``0 = c_0 <= ... <= c_K = n`` of the stops into K contiguous pieces, piece
    ``k`` flown by vehicle ``k`` in the given order from its home after its start delay
    ``offsets_s[k]``, the last landing earliest; an empty piece leaves its vehicle idle.

    A piece's time only grows as it takes in more stops at either end, so for a given longest
    flight the greedy cut (each vehicle in turn takes all it can) decides whether one exists;
    the least such longest flight is found by bisection between the pieces' times. Of cuts
    that land as early, one that gives every vehicle a stop is kept.
    """
    n, count = len(stops_xy), len(vehicles)

    def greedy(limit_s: float, least: int) -> list[int] | None:
        cuts = [0]
        for k, vehicle in enumerate(vehicles):
            first = cuts[-1]
            lo, hi = first, n - least * (count - k - 1)
            if hi < first + least:
                return None
            # The largest j whose piece first .. j - 1 fits; a piece only grows with j. A
            # piece that no sorties fit within the endurance takes infinitely long.
            while lo < hi:
                mid = (lo + hi + 1) // 2
                t = offsets_s[k] + vehicle.time_s(stops_xy[first:mid])
                if t <= limit_s and math.isfinite(t):
                    lo = mid
                else:
                    hi = mid - 1
            if lo < first + least:
                return None
            cuts.append(lo)
        return cuts if cuts[-1] == n else None

    def landing(cuts: list[int]) -> float:
        return max(
            (
                offsets_s[k] + v.time_s(stops_xy[cuts[k] : cuts[k + 1]])
                for k, v in enumerate(vehicles)
                if cuts[k + 1] > cuts[k]
            ),
            default=0.0,
        )

    found = greedy(math.inf, 0)
    if found is None:
        raise _no_split()
    low, high = 0.0, landing(found)
    while high - low > max(1e-3, 1e-6 * high):
        mid = 0.5 * (low + high)
        cuts = greedy(mid, 0)
        if cuts is None:
            low = mid
        else:
            high, found = mid, cuts
    if n >= count and any(a == b for a, b in itertools.pairwise(found)):
        busy = greedy(high, 1)
        if busy is not None:
            found = busy
    return found


def naive_split(
    vehicles: Sequence[Vehicle],
    single_order: Sequence[int],
    reference: Instance,
    offsets_s: Sequence[float] | None = None,
) -> tuple[list[list[int]], list[float], list[list[int]]]:
    """The single-vehicle tour (viewpoints of ``reference``) cut into K contiguous pieces of
    earliest last landing (after the start delays ``offsets_s``, none by default), each
    flown as cut from its vehicle's home: per vehicle the targets first seen in its piece,
    the pieces' flight times and the pieces themselves (empty for a vehicle left idle).

    Raises
    ------
    urpt_gcs.errors.SettingsError
        No cut of this tour fits every vehicle's endurance.
    """
    assert reference.points_xy is not None
    stops = reference.points_xy[list(single_order)]
    offsets = [0.0] * len(vehicles) if offsets_s is None else list(offsets_s)
    cuts = _naive_cut(vehicles, stops, offsets)
    covers = reference.covers.dense(list(single_order))
    first_seen = np.argmax(covers, axis=0)
    pieces, times, cut = [], [], []
    for k, vehicle in enumerate(vehicles):
        lo, hi = cuts[k], cuts[k + 1]
        pieces.append([int(t) for t in np.flatnonzero((first_seen >= lo) & (first_seen < hi))])
        times.append(vehicle.time_s(stops[lo:hi]))
        cut.append([int(v) for v in single_order[lo:hi]])
    return pieces, times, cut
