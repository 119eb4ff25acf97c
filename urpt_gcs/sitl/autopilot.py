"""What AUTO and RTL fly: a mission item, or the return home, as a list of steps.

Mission order follows ArduPilot's ``AP_Mission``: when a navigation command completes, the
"do" commands after it run at once (a DO_DIGICAM_CONTROL after a NAV_WAYPOINT photographs at
that waypoint, after its hold), then the next navigation command starts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.sitl.events import Current
from urpt_gcs.sitl.store import Item

if TYPE_CHECKING:
    from urpt_gcs.sitl.model import Vehicle

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


@dataclass(slots=True)
class Plan:
    """The steps left of one navigation command (``seq`` None outside a mission)."""

    seq: int | None
    steps: list[Step] = field(default_factory=list)


def _target(vehicle: Vehicle, item: Item) -> tuple[float | None, float | None]:
    # ArduPilot: a location of 0, 0 means "here".
    if item.x == 0 and item.y == 0:
        return None, None
    return vehicle.to_east_north(item.x, item.y)


def _run_do(vehicle: Vehicle, item: Item) -> None:
    digicam = item.command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL and item.x == 1
    capture = item.command == mavlink.MAV_CMD_IMAGE_START_CAPTURE and item.param3 >= 1
    # Speed types 0 and 1 set the horizontal speed; 2 and 3 (climb, descent) are not simulated.
    horizontal = item.param1 in (mavlink.SPEED_TYPE_AIRSPEED, mavlink.SPEED_TYPE_GROUNDSPEED)
    if digicam or capture:
        vehicle.take_photo()
    elif item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED and item.param2 > 0.0 and horizontal:
        vehicle.speed_m_s = item.param2


def rtl_steps(vehicle: Vehicle) -> list[Step]:
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


def _nav_steps(vehicle: Vehicle, item: Item) -> list[Step]:
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


def mission_steps(vehicle: Vehicle, start_seq: int) -> Plan | None:
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
