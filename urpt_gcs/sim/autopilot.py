"""What AUTO and RTL fly: a mission item, or the return home, as a list of steps.

Mission order follows ArduPilot's ``AP_Mission``: when a navigation command completes, the
"do" commands after it run at once (a DO_DIGICAM_CONTROL after a NAV_WAYPOINT photographs at
that waypoint, after its hold), then the next navigation command starts. A CONDITION_YAW turns
the vehicle at once and stays in force through the next waypoint's hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.sim.events import Current, Event
from urpt_gcs.sim.params import Params
from urpt_gcs.sim.store import Item, MissionStore

__all__ = [
    "FOREVER_S",
    "NAV_COMMANDS",
    "AutoVehicle",
    "Plan",
    "SCurve",
    "Step",
    "mission_steps",
    "rtl_steps",
]

NAV_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_NAV_WAYPOINT,
        mavlink.MAV_CMD_NAV_LOITER_UNLIM,
        mavlink.MAV_CMD_NAV_LOITER_TIME,
        mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        mavlink.MAV_CMD_NAV_LAND,
        mavlink.MAV_CMD_NAV_TAKEOFF,
    }
)
FOREVER_S = float("inf")


class AutoVehicle(Protocol):
    """What AUTO and RTL read and change of the copter (:class:`urpt_gcs.sim.model.Vehicle`)."""

    params: Params
    store: MissionStore
    events: list[Event]
    alt_m: float
    speed_m_s: float | None
    heading_deg: float
    current_seq: int

    def to_east_north(self, lat_e7: int, lon_e7: int) -> tuple[float, float]:
        """Metres east and north of home of a point in degrees * 1e7."""
        ...

    def mission_item_alt(self, frame: int, z: float) -> float:
        """An item's altitude as metres above home."""
        ...

    def take_photo(self) -> None:
        """Record a photo here."""
        ...


@dataclass(frozen=True, slots=True)
class SCurve:
    """Speed along a straight leg from rest to rest, as ArduCopter 4.x's S-curves fly it.

    The acceleration builds up at ``jerk_m_s3`` to at most ``accel_m_s2`` and eases off to
    zero at ``peak_m_s``: the leg's speed when it is long enough, else the highest speed its
    length allows. Braking mirrors it. Build it with :meth:`for_leg`.
    """

    length_m: float
    peak_m_s: float
    accel_m_s2: float
    jerk_m_s3: float
    ramp_s: float
    duration_s: float

    @staticmethod
    def ramp_time_s(speed_m_s: float, accel_m_s2: float, jerk_m_s3: float) -> float:
        """Time from rest to ``speed_m_s``; speeding up covers half that times the speed."""
        a, j = accel_m_s2, jerk_m_s3
        if speed_m_s <= a * a / j:
            return 2.0 * math.sqrt(speed_m_s / j)
        return speed_m_s / a + a / j

    @classmethod
    def for_leg(
        cls, length_m: float, speed_m_s: float, accel_m_s2: float, jerk_m_s3: float
    ) -> SCurve:
        """The profile of a leg of ``length_m`` at ``speed_m_s``."""

        def ramp(v: float) -> float:
            return cls.ramp_time_s(v, accel_m_s2, jerk_m_s3)

        peak = speed_m_s
        if peak * ramp(peak) > length_m:
            low, high = 0.0, speed_m_s
            for _ in range(60):  # bisection: the ramps' length grows with the peak speed
                mid = 0.5 * (low + high)
                low, high = (mid, high) if mid * ramp(mid) < length_m else (low, mid)
            peak = 0.5 * (low + high)
        duration = length_m / peak + ramp(peak) if peak > 0.0 else 0.0
        return cls(length_m, peak, accel_m_s2, jerk_m_s3, ramp(peak), duration)

    def speed_at(self, time_s: float) -> float:
        """Speed ``time_s`` into the leg."""
        if time_s <= 0.0 or time_s >= self.duration_s:
            return 0.0
        u = min(time_s, self.duration_s - time_s, self.ramp_s)  # into a ramp, from rest
        j = self.jerk_m_s3
        # How long the acceleration builds up (0 for an unlimited jerk: a trapezoid).
        jerk_s = min(self.accel_m_s2 / j, self.ramp_s / 2.0)
        if u >= self.ramp_s:
            return self.peak_m_s
        if u <= jerk_s:
            return 0.5 * j * u * u
        if u >= self.ramp_s - jerk_s:
            return self.peak_m_s - 0.5 * j * (self.ramp_s - u) ** 2
        return self.accel_m_s2 * (u - 0.5 * jerk_s)


@dataclass(slots=True)
class Step:
    """Fly to a point (None keeps the current east/north), then hold or land."""

    east_m: float | None
    north_m: float | None
    alt_m: float
    hold_s: float = 0.0
    land: bool = False
    takeoff: bool = False
    speed_m_s: float | None = None
    arrived: bool = False
    # The horizontal profile of the leg to this step once it has started, and the time and
    # distance flown along it.
    profile: SCurve | None = None
    leg_s: float = 0.0
    along_m: float = 0.0
    # The same for a climb or descent to this step's altitude (not a landing's descent).
    climb: SCurve | None = None
    climb_s: float = 0.0
    climbed_m: float = 0.0
    # A leg that moves and climbs (or descends) at once flies the straight line between its
    # ends, as ArduCopter's waypoint controller does: the altitude it started from and the
    # horizontal distance then left (None: the leg is level, or only climbs).
    start_alt_m: float | None = None
    start_distance_m: float = 0.0
    # Time on the ground after a landing step touched down.
    landed_s: float = 0.0


@dataclass(slots=True)
class Plan:
    """The steps left of one navigation command (``seq`` None outside a mission)."""

    seq: int | None
    steps: list[Step] = field(default_factory=list)


def _target(vehicle: AutoVehicle, item: Item) -> tuple[float | None, float | None]:
    # ArduPilot: a location of 0, 0 means "here".
    if item.x == 0 and item.y == 0:
        return None, None
    return vehicle.to_east_north(item.x, item.y)


def _run_do(vehicle: AutoVehicle, item: Item) -> None:
    digicam = item.command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL and item.x == 1
    capture = item.command == mavlink.MAV_CMD_IMAGE_START_CAPTURE and item.param3 >= 1
    # Speed types 0 and 1 set the horizontal speed; 2 and 3 (climb, descent) are not simulated.
    horizontal = item.param1 in (mavlink.SPEED_TYPE_AIRSPEED, mavlink.SPEED_TYPE_GROUNDSPEED)
    if digicam or capture:
        vehicle.take_photo()
    elif item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED and item.param2 > 0.0 and horizontal:
        vehicle.speed_m_s = item.param2
    elif item.command == mavlink.MAV_CMD_CONDITION_YAW:
        # param4 1: relative to the heading now, turned the way param3 says (-1 ccw).
        if item.param4 > 0:
            turn = item.param1 * (-1.0 if item.param3 < 0 else 1.0)
            vehicle.heading_deg = (vehicle.heading_deg + turn) % 360.0
        else:
            vehicle.heading_deg = item.param1 % 360.0


def rtl_steps(vehicle: AutoVehicle) -> list[Step]:
    """ArduCopter RTL: climb to RTL_ALT (or keep a higher altitude), fly home at RTL_SPEED (or
    WPNAV_SPEED), loiter, land."""
    params = vehicle.params
    alt = max(params["RTL_ALT"] / 100.0, vehicle.alt_m)
    # ModeRTL::init sets the waypoint speed to RTL_SPEED, or WPNAV_SPEED when that is 0: a
    # mission's DO_CHANGE_SPEED does not carry over into RTL.
    speed = (params["RTL_SPEED"] or params["WPNAV_SPEED"]) / 100.0
    final = params["RTL_ALT_FINAL"] / 100.0
    steps = [
        Step(None, None, alt),
        Step(0.0, 0.0, alt, hold_s=params["RTL_LOIT_TIME"] / 1000.0, speed_m_s=speed),
    ]
    if final > 0.0:
        steps.append(Step(0.0, 0.0, final, hold_s=FOREVER_S))
    else:
        steps.append(Step(0.0, 0.0, 0.0, land=True))
    return steps


def _nav_steps(vehicle: AutoVehicle, item: Item) -> list[Step]:
    east, north = _target(vehicle, item)
    alt = vehicle.mission_item_alt(item.frame, item.z)
    command = item.command
    if command == mavlink.MAV_CMD_NAV_TAKEOFF:
        return [Step(None, None, max(alt, vehicle.alt_m), takeoff=True)]
    if command == mavlink.MAV_CMD_NAV_WAYPOINT:
        return [Step(east, north, alt, hold_s=max(item.param1, 0.0))]
    if command == mavlink.MAV_CMD_NAV_LOITER_TIME:
        return [Step(east, north, alt, hold_s=max(item.param1, 0.0))]
    if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
        return [Step(east, north, alt, hold_s=FOREVER_S)]
    if command == mavlink.MAV_CMD_NAV_LAND:
        return [Step(east, north, vehicle.alt_m), Step(None, None, 0.0, land=True)]
    if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return rtl_steps(vehicle)
    return []


def mission_steps(vehicle: AutoVehicle, start_seq: int) -> Plan | None:
    """Run the "do" commands from ``start_seq`` on and plan the next navigation command.

    Returns None when the mission has no navigation command left.
    """
    store = vehicle.store
    for seq in range(max(start_seq, store.first_seq), len(store)):
        item = store.read(seq)
        if item.command in NAV_COMMANDS:
            vehicle.current_seq = seq
            vehicle.events.append(Current(seq))
            return Plan(seq, _nav_steps(vehicle, item))
        _run_do(vehicle, item)
    return None
