"""Preflight safety: terrain clearance of every leg, height above ground, battery endurance
(split into sorties), and the geofence.

Everything here is checked in code on every plan, before any file is written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from urpt_gcs.errors import PlanError
from urpt_gcs.segments import segment_profile
from urpt_gcs.terrain import FloatArray, Terrain


@dataclass(frozen=True, slots=True)
class Leg:
    """One straight leg at the plane's altitude, with its terrain clearance."""

    start: str
    end: str
    length_m: float
    min_clearance_m: float
    unknown_m: float


@dataclass(frozen=True, slots=True)
class FlightModel:
    """How long flying takes: climb and descent at home, cruise, a full stop at each photo."""

    cruise_m_s: float
    climb_m_s: float
    descent_m_s: float
    accel_m_s2: float
    hold_s: float

    def sortie_s(self, path_m: float, stops: int, altitude_rel_m: float) -> float:
        """Flight time of a sortie: take-off, ``path_m`` of cruise with ``stops`` photo
        stops (accelerating and braking costs ``v / a`` each), return and landing."""
        return (
            altitude_rel_m / self.climb_m_s
            + path_m / self.cruise_m_s
            + stops * (self.hold_s + self.cruise_m_s / self.accel_m_s2)
            + altitude_rel_m / self.descent_m_s
        )


@dataclass(frozen=True, slots=True)
class Sortie:
    """Tour stops ``first`` to ``stop - 1`` flown from home and back on one battery."""

    first: int
    stop: int
    length_m: float
    flight_time_s: float


def leg_clearances(
    terrain: Terrain, path_xy: FloatArray, names: list[str], altitude_m: float
) -> tuple[Leg, ...]:
    """The terrain clearance of every leg of ``path_xy`` flown level at ``altitude_m``, exact
    on the DEM's bilinear surface (:func:`urpt_gcs.segments.segment_profile`)."""
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
        raise PlanError(f"{message}: lower --altitude/--clearance or raise --max-agl")
    return [message]


def split_sorties(
    stops_xy: FloatArray,
    home_xy: tuple[float, float],
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float | None,
    names: list[str],
) -> tuple[Sortie, ...]:
    """Cut the tour, in its order, into the sorties of least total flight time that each
    fit ``endurance_s`` (dynamic programming over cut points; one sortie if it fits)."""
    k = len(stops_xy)
    home = np.asarray(home_xy, dtype=np.float64)
    to_home = np.hypot(*(stops_xy - home).T)
    hops = np.hypot(*np.diff(stops_xy, axis=0).T) if k > 1 else np.zeros(0)
    along = np.concatenate([[0.0], np.cumsum(hops)])  # path length from stop 0 to stop j

    def sortie(i: int, j: int) -> Sortie:  # stops i .. j-1
        length = float(to_home[i] + along[j - 1] - along[i] + to_home[j - 1])
        return Sortie(i, j, length, model.sortie_s(length, j - i, altitude_rel_m))

    whole = sortie(0, k)
    if endurance_s is None or whole.flight_time_s <= endurance_s:
        return (whole,)
    best = np.full(k + 1, np.inf)
    cut = np.zeros(k + 1, dtype=np.int64)
    best[0] = 0.0
    for j in range(1, k + 1):
        for i in range(j - 1, -1, -1):
            s = sortie(i, j)
            if s.flight_time_s > endurance_s:
                if i == j - 1:
                    raise PlanError(
                        f"{names[i]} alone needs {s.flight_time_s / 60:.1f} min of flight, over "
                        f"--endurance {endurance_s / 60:g} min: move home closer or raise "
                        "--endurance"
                    )
                break  # longer sorties ending at j only get longer
            if best[i] + s.flight_time_s < best[j]:
                best[j] = best[i] + s.flight_time_s
                cut[j] = i
    out = []
    j = k
    while j > 0:
        out.append(sortie(int(cut[j]), j))
        j = int(cut[j])
    return tuple(reversed(out))


def geofence_polygon(points_xy: FloatArray, margin_m: float) -> FloatArray:
    """A convex inclusion fence around ``points_xy`` with ``margin_m`` to spare (closed ring
    without the repeated last vertex)."""
    hull = shapely.MultiPoint([tuple(p) for p in points_xy]).convex_hull
    fence = hull.buffer(margin_m, quad_segs=4).simplify(margin_m * 0.05)
    ring = np.asarray(fence.exterior.coords)[:-1]
    return ring
