"""Preflight safety: terrain clearance of every leg, height above ground, battery endurance
(split into sorties), and the geofence.

Everything here is checked in code on every plan, before any file is written.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
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
    """How long flying takes, as a copter flies a survey mission in AUTO.

    Climb to the plane at ``climb_m_s``; every level leg from rest to rest (the copter stops to
    hold at each photo, and over home), accelerating and braking at ``accel_m_s2`` with
    ``cruise_m_s`` between; ``hold_s`` at each stop; the descent at ``descent_m_s``.

    Two things ArduCopter's RTL does are left out, and they about cancel for a return of
    150-200 m at the defaults: it flies home at RTL_SPEED, or WPNAV_SPEED (10 m/s) when that is
    0, whatever DO_CHANGE_SPEED set, while the estimate charges ``cruise_m_s``; and over home
    it loiters RTL_LOIT_TIME (5 s) and lands the last LAND_ALT_LOW (10 m) at LAND_SPEED
    (0.5 m/s), about 18 s the estimate does not charge.
    """

    cruise_m_s: float
    climb_m_s: float
    descent_m_s: float
    accel_m_s2: float
    hold_s: float

    def leg_s(self, length_m: FloatArray | float) -> FloatArray:
        """Time of a level leg from rest to rest: a trapezoid of speed, or a triangle when the
        leg is too short to reach ``cruise_m_s``."""
        d = np.asarray(length_m, dtype=np.float64)
        v, a = self.cruise_m_s, self.accel_m_s2
        out: FloatArray = np.where(d >= v * v / a, d / v + v / a, 2.0 * np.sqrt(d / a))
        return out

    def takeoff_s(self, altitude_rel_m: float) -> float:
        """The climb from home to the plane."""
        return altitude_rel_m / self.climb_m_s

    def landing_s(self, altitude_rel_m: float) -> float:
        """The descent from the plane to home."""
        return altitude_rel_m / self.descent_m_s

    def sortie_s(self, legs_m: Sequence[float] | FloatArray, altitude_rel_m: float) -> float:
        """Flight time of a sortie from arming to landing: its level legs (home to the first
        stop, ..., the last stop to home) with a hold at every stop between them."""
        legs = np.asarray(legs_m, dtype=np.float64)
        stops = max(len(legs) - 1, 0)
        return (
            self.takeoff_s(altitude_rel_m)
            + float(self.leg_s(legs).sum())
            + stops * self.hold_s
            + self.landing_s(altitude_rel_m)
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
    # Time of the hops from stop 0 to stop j, holds included; a sortie adds its two legs from
    # and to home, the climb and the landing.
    hop_s = np.concatenate([[0.0], np.cumsum(model.leg_s(hops) + model.hold_s)])
    home_s = model.leg_s(to_home)
    ends_s = model.takeoff_s(altitude_rel_m) + model.hold_s + model.landing_s(altitude_rel_m)

    def sortie(i: int, j: int) -> Sortie:  # stops i .. j-1
        length = float(to_home[i] + along[j - 1] - along[i] + to_home[j - 1])
        time_s = float(home_s[i] + hop_s[j - 1] - hop_s[i] + home_s[j - 1] + ends_s)
        return Sortie(i, j, length, time_s)

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
