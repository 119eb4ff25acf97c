"""How long a copter takes to fly a survey, free of terrain: the flight-time model and the
cut of a tour into sorties that each fit one battery.

:class:`FlightModel` times a sortie as a copter flies a survey mission in AUTO and returns in
RTL; :func:`split_sorties` cuts a tour, in its order, into the sorties of least total flight
time that each fit the endurance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import PlanError

__all__ = [
    "ARDUCOPTER_CLIMB_ACCEL_M_S2",
    "ARDUCOPTER_JERK_M_S3",
    "ARDUCOPTER_LAND_SLOW_M",
    "ARDUCOPTER_LAND_SLOW_M_S",
    "ARDUCOPTER_LOITER_S",
    "ARDUCOPTER_RETURN_M_S",
    "ARDUCOPTER_SETTLE_S",
    "ARDUCOPTER_START_S",
    "ARDUCOPTER_TOUCHDOWN_S",
    "FlightModel",
    "Sortie",
    "SortieLegs",
    "cut_sorties",
    "split_sorties",
]

# ArduCopter 4.x defaults (its parameter documentation), checked against flights of the demo
# and of a sortie split on ArduCopter 4.7 SITL at 20x.
# WPNAV_SPEED (m/s): RTL flies home at RTL_SPEED, which is 0 ("use WPNAV_SPEED"); a
# mission's DO_CHANGE_SPEED does not carry over into RTL.
ARDUCOPTER_RETURN_M_S = 10.0
# WPNAV_JERK (m/s/s/s): waypoint legs are S-curves. At 5 m/s this, not WPNAV_ACCEL, limits
# the speeding up: 4.5 s to cruise speed where a trapezoid at 2.5 m/s/s takes 2 s.
ARDUCOPTER_JERK_M_S3 = 1.0
# WPNAV_ACCEL_Z (m/s/s): how the take-off and the descent start and end.
ARDUCOPTER_CLIMB_ACCEL_M_S2 = 1.0
# RTL_LOIT_TIME (s) over home before the descent.
ARDUCOPTER_LOITER_S = 5.0
# LAND_ALT_LOW (m) and LAND_SPEED (m/s): the last part of the descent is slow; above it the
# copter descends at LAND_SPEED_HIGH, which is 0 ("use WPNAV_SPEED_DN").
ARDUCOPTER_LAND_SLOW_M = 10.0
ARDUCOPTER_LAND_SLOW_M_S = 0.5
# Measured: arming to the take-off starting, when a ground station arms and then starts the
# mission (4.1 s in every replay); a stop's arrival check before its hold counts (0.4-0.8 s
# per stop); the land detector's time on the ground before the disarm (2.5-3.1 s).
ARDUCOPTER_START_S = 4.0
ARDUCOPTER_SETTLE_S = 0.5
ARDUCOPTER_TOUCHDOWN_S = 3.0


@dataclass(frozen=True, slots=True)
class FlightModel:
    """How long flying takes, as a copter flies a survey mission in AUTO and returns in RTL.

    A sortie, from arming to the disarm after landing: ``start_s`` until the take-off starts;
    the climb to the plane at ``climb_m_s``, speeding up and slowing down at
    ``climb_accel_m_s2``; every level leg from rest to rest (the copter stops at each photo)
    at ``cruise_m_s``, speeding up and braking within ``accel_m_s2`` and ``jerk_m_s3`` (an
    S-curve of speed; a trapezoid when the jerk is unlimited, a triangle or its S-curve
    counterpart when the leg is too short to reach the speed); ``settle_s`` and ``hold_s`` at
    each stop; the leg home at ``return_m_s``; ``settle_s`` and ``loiter_s`` over home; the
    descent at ``descent_m_s`` down to ``land_slow_m`` above home, then at
    ``land_slow_m_s``; ``touchdown_s`` on the ground until the copter disarms.

    :meth:`arducopter` and :meth:`px4` are the firmwares' models.

    Attributes
    ----------
    cruise_m_s
        Horizontal speed of the survey legs (the mission's DO_CHANGE_SPEED).
    hold_s
        Hold at each stop (NAV_WAYPOINT param1).
    climb_m_s
        Climb rate of the take-off.
    descent_m_s
        Descent rate over home, above ``land_slow_m``.
    accel_m_s2
        Horizontal acceleration and braking limit.
    return_m_s
        Horizontal speed of the leg home.
    jerk_m_s3
        Horizontal jerk limit; infinite for none.
    climb_accel_m_s2
        Vertical acceleration limit of the climb and the descent; infinite for none.
    start_s
        From arming until the take-off starts.
    settle_s
        What a stop costs beyond its hold: the vehicle making sure it has arrived.
    loiter_s
        Hover over home before the descent.
    land_slow_m
        Height above home of the slow, last part of the descent; 0 for none.
    land_slow_m_s
        Descent rate below ``land_slow_m``.
    touchdown_s
        From reaching the ground until the vehicle disarms.
    """

    cruise_m_s: float
    hold_s: float
    climb_m_s: float
    descent_m_s: float
    accel_m_s2: float
    return_m_s: float
    jerk_m_s3: float = math.inf
    climb_accel_m_s2: float = math.inf
    start_s: float = 0.0
    settle_s: float = 0.0
    loiter_s: float = 0.0
    land_slow_m: float = 0.0
    land_slow_m_s: float = 0.5
    touchdown_s: float = 0.0

    @classmethod
    def arducopter(
        cls,
        cruise_m_s: float,
        hold_s: float,
        climb_m_s: float = 2.5,
        descent_m_s: float = 1.5,
        accel_m_s2: float = 2.5,
    ) -> FlightModel:
        """ArduCopter 4.x at its default parameters, its speeds (WPNAV_SPEED_UP,
        WPNAV_SPEED_DN, WPNAV_ACCEL) as given: the mission's legs as S-curves, RTL home at
        WPNAV_SPEED, RTL_LOIT_TIME over home, LAND_SPEED below LAND_ALT_LOW."""
        return cls(
            cruise_m_s=cruise_m_s,
            hold_s=hold_s,
            climb_m_s=climb_m_s,
            descent_m_s=descent_m_s,
            accel_m_s2=accel_m_s2,
            return_m_s=ARDUCOPTER_RETURN_M_S,
            jerk_m_s3=ARDUCOPTER_JERK_M_S3,
            climb_accel_m_s2=ARDUCOPTER_CLIMB_ACCEL_M_S2,
            start_s=ARDUCOPTER_START_S,
            settle_s=ARDUCOPTER_SETTLE_S,
            loiter_s=ARDUCOPTER_LOITER_S,
            land_slow_m=ARDUCOPTER_LAND_SLOW_M,
            land_slow_m_s=ARDUCOPTER_LAND_SLOW_M_S,
            touchdown_s=ARDUCOPTER_TOUCHDOWN_S,
        )

    @classmethod
    def px4(
        cls,
        cruise_m_s: float,
        hold_s: float,
        climb_m_s: float = 2.5,
        descent_m_s: float = 1.5,
        accel_m_s2: float = 2.5,
    ) -> FlightModel:
        """PX4, not yet measured: trapezoids of speed, home at the cruise speed, no loiter
        over home and one descent rate."""
        return cls(
            cruise_m_s=cruise_m_s,
            hold_s=hold_s,
            climb_m_s=climb_m_s,
            descent_m_s=descent_m_s,
            accel_m_s2=accel_m_s2,
            return_m_s=cruise_m_s,
        )

    @property
    def stop_s(self) -> float:
        """What each stop costs on top of its legs."""
        return self.settle_s + self.hold_s

    @property
    def stop_cost_m(self) -> float:
        """What one more stop adds to a flight, as cruise metres: its settle and hold, and the
        braking and speeding up of one more leg that reaches the cruise speed."""
        return self.cruise_m_s * (self.stop_s + self.cruise_overhead()[1])

    def _ramp_s(self, speed_m_s: FloatArray) -> FloatArray:
        """Time from rest to ``speed_m_s`` (or back): the acceleration builds up at the jerk
        limit, and holds at ``accel_m_s2`` once the speed needs it."""
        a, j = self.accel_m_s2, self.jerk_m_s3
        out: FloatArray = np.where(
            speed_m_s <= a * a / j, 2.0 * np.sqrt(speed_m_s / j), speed_m_s / a + a / j
        )
        return out

    def leg_s(self, length_m: FloatArray | float, speed_m_s: float | None = None) -> FloatArray:
        """Time of a level leg from rest to rest at ``speed_m_s`` (default ``cruise_m_s``).

        Speeding up to ``v`` covers ``v * ramp / 2`` (the profile is symmetric about half the
        speed), so a leg of at least ``v * ramp`` cruises and takes ``d / v + ramp``; a
        shorter one peaks at the speed ``p`` whose ``p * ramp(p)`` is its length and takes
        twice that ramp.
        """
        d = np.asarray(length_m, dtype=np.float64)
        v = self.cruise_m_s if speed_m_s is None else speed_m_s
        a, j = self.accel_m_s2, self.jerk_m_s3
        ramp = float(self._ramp_s(np.asarray(v)))
        # Peak speed of a short leg: in the acceleration-limited branch p * (p / a + a / j)
        # = d; below 2 a^3 / j^2 (the acceleration never reaches a) 2 p^1.5 / sqrt(j) = d.
        peak = 0.5 * a * (np.sqrt((a / j) ** 2 + 4.0 * d / a) - a / j)
        if math.isfinite(j):
            peak = np.where(d <= 2.0 * a**3 / j**2, np.cbrt(d * d * j / 4.0), peak)
        out: FloatArray = np.where(d >= v * ramp, d / v + ramp, 2.0 * self._ramp_s(peak))
        return out

    def cruise_overhead(self) -> tuple[float, float]:
        """From which length a level leg reaches the cruise speed, and what it then takes
        beyond its length over that speed (speeding up and braking).

        Returns
        -------
        tuple of float
            The length (m) and the extra time (s): every leg at least that long takes
            ``length / cruise_m_s`` plus that time, exactly.
        """
        ramp = float(self._ramp_s(np.asarray(self.cruise_m_s)))
        return self.cruise_m_s * ramp, ramp

    def return_s(self, length_m: FloatArray | float) -> FloatArray:
        """Time of the leg home, from rest at the last stop to rest over home."""
        return self.leg_s(length_m, self.return_m_s)

    def climb_s(self, rise_m: FloatArray | float) -> FloatArray:
        """Time of a change of height alone: up at ``climb_m_s``, down at ``descent_m_s``."""
        dz = np.asarray(rise_m, dtype=np.float64)
        out: FloatArray = np.where(dz > 0.0, dz / self.climb_m_s, -dz / self.descent_m_s)
        return out

    def leg3_s(
        self,
        length_m: FloatArray | float,
        rise_m: FloatArray | float,
        vertical_s: FloatArray | float | None = None,
    ) -> FloatArray:
        """Time of a leg from rest to rest that also climbs ``rise_m`` (negative: descends).

        The firmware holds the horizontal speed within the cruise speed and the vertical
        within the climb or descent rate: where the height changes faster than the cruise
        allows, the leg takes the vertical time instead. ``vertical_s``, when given, is the
        time the leg's pieces need for their climbs and descents beyond their horizontal
        time (a path that follows the terrain); else that of one straight piece.
        """
        d = np.asarray(length_m, dtype=np.float64)
        if vertical_s is None:
            vertical_s = np.maximum(self.climb_s(rise_m) - d / self.cruise_m_s, 0.0)
        out: FloatArray = self.leg_s(d) + np.asarray(vertical_s, dtype=np.float64)
        return out

    def least_vertical_s(
        self,
        length_m: FloatArray,
        start_m: FloatArray,
        end_m: FloatArray,
        peak_m: FloatArray,
        trough_m: FloatArray,
    ) -> FloatArray:
        """What a leg's climbs and descents take beyond its horizontal time, at the least.

        The vehicle must rise to ``peak_m`` and sink to ``trough_m`` somewhere along the leg
        (a flight inside a height band: the floor over the highest ground under the leg, the
        ceiling over the lowest), in one order or the other, between its start and end
        heights: the cheaper order's climbs at the climb rate and descents at the descent
        rate, less what the leg's horizontal time covers.
        """
        hi = np.maximum(np.maximum(start_m, end_m), peak_m)
        lo = np.minimum(np.minimum(start_m, end_m), trough_m)
        best = np.full(np.shape(length_m), np.inf)
        for first, second in ((hi, lo), (lo, hi)):
            steps = (first - start_m, second - first, end_m - second)
            up = sum(np.maximum(x, 0.0) for x in steps)
            down = sum(np.maximum(-x, 0.0) for x in steps)
            best = np.minimum(best, up / self.climb_m_s + down / self.descent_m_s)
        out: FloatArray = np.maximum(best - np.asarray(length_m) / self.cruise_m_s, 0.0)
        return out

    def vertical_excess_s(self, length_m: FloatArray, rise_m: FloatArray) -> float:
        """What the pieces of one path spend climbing or descending beyond their horizontal
        time: each piece takes the slower of the two."""
        return float(
            np.maximum(self.climb_s(rise_m) - np.asarray(length_m) / self.cruise_m_s, 0.0).sum()
        )

    def takeoff_s(self, altitude_rel_m: float) -> float:
        """From arming to the plane: the start, and the climb from rest to rest."""
        v, a = self.climb_m_s, self.climb_accel_m_s2
        h = max(altitude_rel_m, 0.0)
        climb = h / v + v / a if h >= v * v / a else 2.0 * math.sqrt(h / a)
        return self.start_s + climb

    def landing_s(self, altitude_rel_m: float) -> float:
        """From arriving over home to the disarm: settling, the loiter, the descent (from
        rest, into the slow part without stopping) and the touchdown."""
        h = max(altitude_rel_m, 0.0)
        slow = min(self.land_slow_m, h)
        fast = h - slow
        v = self.descent_m_s
        start = v / (2.0 * self.climb_accel_m_s2) if fast > 0.0 else 0.0
        return (
            self.settle_s
            + self.loiter_s
            + fast / v
            + start
            + slow / self.land_slow_m_s
            + self.touchdown_s
        )

    def sortie_s(self, legs_m: Sequence[float] | FloatArray, altitude_rel_m: float) -> float:
        """Flight time of a sortie from arming to the disarm after landing: its level legs
        (home to the first stop, ..., the last stop to home, at ``return_m_s``) with a stop
        at every point between them."""
        legs = np.asarray(legs_m, dtype=np.float64)
        stops = max(len(legs) - 1, 0)
        return (
            self.takeoff_s(altitude_rel_m)
            + float(self.leg_s(legs[:-1]).sum())
            + float(self.return_s(legs[-1:]).sum())
            + stops * self.stop_s
            + self.landing_s(altitude_rel_m)
        )


@dataclass(frozen=True, slots=True)
class Sortie:
    """Tour stops ``first`` to ``stop - 1`` flown from home and back on one battery."""

    first: int
    stop: int
    length_m: float
    flight_time_s: float


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
    # A sortie adds its legs from home (at the cruise speed) and back (at the return speed),
    # its last stop, the take-off and the landing to the hops between its stops.
    return cut_sorties(
        SortieLegs(
            out_m=to_home,
            hop_m=hops,
            back_m=to_home,
            out_s=model.leg_s(to_home),
            hop_s=model.leg_s(hops) + model.stop_s,
            back_s=model.return_s(to_home),
            ends_s=model.takeoff_s(altitude_rel_m) + model.stop_s + model.landing_s(altitude_rel_m),
        ),
        endurance_s,
        names,
    )


@dataclass(frozen=True, slots=True)
class SortieLegs:
    """What flying the tour's stops in order costs, for cutting it into sorties.

    Attributes
    ----------
    out_m, out_s
        From home to each stop: length and time (take-off aside).
    hop_m, hop_s
        From each stop to the next (one fewer): length, and time with the stop at its start.
    back_m, back_s
        From each stop back over home: length and time (landing aside).
    ends_s
        What every sortie adds: the take-off, its last stop and the landing.
    """

    out_m: FloatArray
    hop_m: FloatArray
    back_m: FloatArray
    out_s: FloatArray
    hop_s: FloatArray
    back_s: FloatArray
    ends_s: float


def cut_sorties(
    legs: SortieLegs, endurance_s: float | None, names: list[str]
) -> tuple[Sortie, ...]:
    """Cut stops flown in order into the sorties of least total flight time that each fit
    ``endurance_s`` (dynamic programming over cut points; one sortie if it fits).

    Raises
    ------
    PlanError
        A stop that alone takes a sortie over the endurance.
    """
    k = len(legs.out_m)
    along = np.concatenate([[0.0], np.cumsum(legs.hop_m)])  # path length from stop 0 to j
    hop_s = np.concatenate([[0.0], np.cumsum(legs.hop_s)])

    def sortie(i: int, j: int) -> Sortie:  # stops i .. j-1
        length = float(legs.out_m[i] + along[j - 1] - along[i] + legs.back_m[j - 1])
        time_s = float(legs.out_s[i] + hop_s[j - 1] - hop_s[i] + legs.back_s[j - 1] + legs.ends_s)
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
