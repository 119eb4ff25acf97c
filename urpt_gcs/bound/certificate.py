"""Certificate: how far, at most, a flight is from the shortest one any planner could find.

Every point of the flight plane that sees a target lies in the target's outer star (walked
on the DEM by the visibility package). A closed flight from home that photographs every
target enters every outer star, so the certified lower bound of
:mod:`urpt_gcs.bound.lower_bound` over those stars bounds the length of every such flight at
this altitude with this camera -- not only of tours over the planner's candidate viewpoints.
:func:`certify` takes the stars as regions and, optionally, what tightens them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.lower_bound import lower_bound
from urpt_gcs.bound.sorties import SortieBound
from urpt_gcs.problem.regions import RegionSet

__all__ = [
    "BOUND_SHARE",
    "BOUND_TIME_S",
    "PROVEN_GAP",
    "Certificate",
    "Tighten",
    "bound_time_s",
    "certify",
]

# Below this gap a tour is called optimal: its length is within it of the certified bound.
PROVEN_GAP = 1e-4
# Seconds the bound may spend by default, and its share of the solver's time limit.
BOUND_TIME_S = 5.0
BOUND_SHARE = 0.5
# Tighter regions where a relaxed tour meets them, within a time budget (None: nothing left
# to tighten).
Tighten = Callable[[RegionSet, FloatArray, float], "RegionSet | None"]


@dataclass(frozen=True, slots=True)
class Certificate:
    """A lower bound of every flight that photographs every target, and how it was found.

    ``lower_bound_m`` bounds every closed flight from ``depot`` (home; none: any closed
    flight) on the plane whose photos see every target; ``method`` and ``seconds`` say how
    the bound was reached, ``area_ratio`` how much wider the outer stars are than what is
    certainly seen (their areas, summed over the targets).
    """

    lower_bound_m: float
    method: str
    seconds: float
    sectors: int
    area_ratio: float
    # The bound's shortest relaxed tour: a closed polyline meeting every outer star it
    # bounded (None when the search met none), from which a tour may be read.
    relaxed_tour_xy: FloatArray | None = None
    # The bound of what the endurance forces on sorties from home (None: not computed);
    # ``lower_bound_m`` is then the larger of its length and the single flight's bound.
    sorties: SortieBound | None = None

    @property
    def single_flight_m(self) -> float:
        """The bound of one closed flight from home, the returns home of sorties aside."""
        return self.lower_bound_m if self.sorties is None else self.sorties.single_m

    def gap(self, length_m: float) -> float:
        """``(length - bound) / bound``: how much longer the flight may be than the shortest."""
        if self.lower_bound_m <= 0.0:
            return 0.0 if length_m <= 0.0 else math.inf
        return float(max(length_m - self.lower_bound_m, 0.0) / self.lower_bound_m)

    def proven(self, length_m: float) -> bool:
        """Whether the flight is within :data:`PROVEN_GAP` of the shortest possible."""
        return bool(self.gap(length_m) <= PROVEN_GAP)


def bound_time_s(time_limit_s: float) -> float:
    """The bound's default budget for a solver time limit."""
    return min(BOUND_TIME_S, BOUND_SHARE * time_limit_s)


def certify(
    regions: RegionSet,
    length_m: float,
    time_limit_s: float,
    also_m: float = 0.0,
    area_ratio: float = math.nan,
    tighten: Tighten | None = None,
    enough: float = PROVEN_GAP,
) -> Certificate:
    """The certified lower bound for a flight of ``length_m`` over ``regions``.

    ``also_m`` is another valid bound of the same problem (the depot's and the disc-packing
    bounds); the larger of the two is kept, never more than the flight itself. With
    ``tighten`` (such as the visibility package's ``finer_stars``), while time is left and
    the flight is more than ``enough`` (a share) longer than the bound, the regions are
    tightened where the relaxed tour meets them and bounded again.
    """
    started = time.perf_counter()
    # The first bound has all the time: the stars are tightened with what it leaves (a
    # share cut from it cost more on sites whose bound runs out of time than it won).
    bound = lower_bound(regions, length_m, time_limit_s)
    value, method, poly = bound.value, bound.method, bound.relaxed_tour_xy
    first = sum(float(np.mean(s.reach_m**2)) for s in regions.outer)
    sectors = int(regions.outer[0].reach_m.size) if regions.outer else 0
    # Where the relaxed tour meets a star near its edge the star may be loose there (a
    # sector's reach is its widest): walk those stars again, finer, and bound again.
    while tighten is not None and poly is not None and (length_m - value) > enough * value:
        left = time_limit_s - (time.perf_counter() - started)
        if left <= 0.0:
            break
        finer = tighten(regions, poly, 0.5 * left)
        if finer is None:
            break
        regions = finer
        spent = time.perf_counter() - started
        again = lower_bound(regions, length_m, max(time_limit_s - spent, 0.0))
        if again.value <= value:
            # Stopped by the time before it passed the last bound: keep that one's tour.
            break
        value, method = again.value, again.method
        poly = again.relaxed_tour_xy if again.relaxed_tour_xy is not None else poly
    if first > 0.0:
        area_ratio *= sum(float(np.mean(s.reach_m**2)) for s in regions.outer) / first
    if also_m > value:
        value, method = also_m, "geometric"
    return Certificate(
        min(value, length_m), method, time.perf_counter() - started, sectors, area_ratio, poly
    )
