"""Preflight safety: terrain clearance of every leg, height above ground, and the geofence
(battery endurance and the split into sorties are :mod:`urpt_gcs.problem.flight_time`'s).

Everything here is checked in code on every plan, before any file is written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import PlanError

# The flight-time model and the sortie cut are terrain-free (the solvers' fleet search uses
# them); they are imported back here so that every preflight check is found in one module.
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.segments import segment_profile

__all__ = [
    "Leg",
    "check_height_above_ground",
    "check_legs",
    "geofence_polygon",
    "leg_clearances",
]


@dataclass(frozen=True, slots=True)
class Leg:
    """One straight leg at the plane's altitude, with its terrain clearance."""

    start: str
    end: str
    length_m: float
    min_clearance_m: float
    unknown_m: float


def leg_clearances(
    terrain: Terrain, path_xy: FloatArray, names: list[str], altitude_m: float
) -> tuple[Leg, ...]:
    """The terrain clearance of every leg of ``path_xy`` flown level at ``altitude_m``, exact
    on the DEM's bilinear surface (:func:`urpt_gcs.visibility.segments.segment_profile`)."""
    a = np.column_stack([path_xy[:-1], np.full(len(path_xy) - 1, altitude_m)])
    b = np.column_stack([path_xy[1:], np.full(len(path_xy) - 1, altitude_m)])
    profile = segment_profile(terrain, a, b)
    lengths = np.hypot(*(path_xy[1:] - path_xy[:-1]).T)
    return tuple(
        Leg(
            names[i],
            names[i + 1],
            float(lengths[i]),
            -float(profile.excess_m[i]) if math.isfinite(profile.excess_m[i]) else math.nan,
            float(profile.unknown_fraction[i] * lengths[i]),
        )
        for i in range(len(path_xy) - 1)
    )


def check_legs(legs: tuple[Leg, ...], min_clearance_m: float) -> list[str]:
    """Refuse a leg too close to the terrain; warn about legs over unknown ground."""
    warnings = []
    for number, leg in enumerate(legs, start=1):
        if math.isfinite(leg.min_clearance_m) and leg.min_clearance_m < min_clearance_m:
            how = (
                f"cuts {-leg.min_clearance_m:.1f} m into the terrain"
                if leg.min_clearance_m < 0.0
                else f"passes only {leg.min_clearance_m:.1f} m above the terrain"
            )
            raise PlanError(
                f"leg {number} ({leg.start} -> {leg.end}) {how}, under --min-clearance "
                f"{min_clearance_m:g} m: raise --altitude or --clearance"
            )
        if leg.unknown_m > 0.0:
            warnings.append(
                f"leg {number} ({leg.start} -> {leg.end}) crosses {leg.unknown_m:.0f} m without "
                "elevation data: its clearance there is not verified"
            )
    return warnings


def check_height_above_ground(
    altitude_m: float,
    ground_m: FloatArray,
    names: list[str],
    home_ground_m: float,
    max_agl_m: float,
    strict: bool,
) -> list[str]:
    """Height above the ground under every stop and above home against ``max_agl_m``."""
    problems = [
        f"{name} flies {altitude_m - g:.1f} m above the ground"
        for name, g in zip(names, ground_m, strict=True)
        if altitude_m - g > max_agl_m
    ]
    if altitude_m - home_ground_m > max_agl_m:
        problems.insert(0, f"the plane is {altitude_m - home_ground_m:.1f} m above home")
    if not problems:
        return []
    message = (
        f"{problems[0]}{f' (and {len(problems) - 1} more)' if len(problems) > 1 else ''}, over "
        f"--max-agl {max_agl_m:g} m"
    )
    if strict:
        raise PlanError(
            f"{message}: lower --altitude/--clearance, raise --max-agl, or follow the terrain "
            "with --agl FLOOR:CEILING"
        )
    return [f"{message}; --agl FLOOR:CEILING (e.g. 30:120) follows the terrain instead"]


def geofence_polygon(points_xy: FloatArray, margin_m: float) -> FloatArray:
    """A convex inclusion fence around ``points_xy`` with ``margin_m`` to spare (closed ring
    without the repeated last vertex)."""
    hull = shapely.MultiPoint([tuple(p) for p in points_xy]).convex_hull
    fence = hull.buffer(margin_m, quad_segs=4).simplify(margin_m * 0.05)
    ring = np.asarray(fence.exterior.coords)[:-1]
    return ring
