"""The simulated vehicle's mission storage: what it accepts and what it reads back.

ArduPilot (``AP_Mission``, ``MissionItemProtocol_Waypoints``) does not keep a MISSION_ITEM_INT
as sent: it converts each item to a compact command that holds only the fields that command
uses, and converts it back on download. This module does the same for the commands a survey
mission uses, so a read-back here differs from the upload exactly where ArduPilot's would:

* seq 0 is home: writing it is accepted and ignored; reading it returns the vehicle's home
  (NAV_WAYPOINT, frame GLOBAL, AMSL altitude);
* locations keep x and y exactly, the altitude in whole centimetres (truncated, as the C cast
  does), and come back in frame GLOBAL (0), GLOBAL_RELATIVE_ALT (3) or GLOBAL_TERRAIN_ALT (10);
  any other frame on a location command is refused with MAV_MISSION_UNSUPPORTED_FRAME;
* commands without a location come back in frame 0 with x, y, z zero unless they store them;
* NaN is refused in params 1-4, except param4 of NAV_WAYPOINT, NAV_TAKEOFF and NAV_LAND;
* NAV_WAYPOINT / NAV_TAKEOFF keep param1 as a whole number (uint16), drop params 2-4;
  DO_MOUNT_CONTROL keeps params 1-3; DO_CHANGE_SPEED param1 as a byte and params 2-3;
  DO_DIGICAM_CONTROL keeps params 1-4 and x, y as bytes; CONDITION_YAW keeps params 1-2,
  param3 as a signed and param4 as an unsigned byte;
* ``current`` always reads 0, ``autocontinue`` always 1.

In PX4 mode there is no home item, and items are kept as PX4 v1.16 SITL was seen to keep
them:

* a location command is accepted in frames 0/3/5/6 and comes back in 5 (GLOBAL_INT) or 6
  (GLOBAL_RELATIVE_ALT_INT); the terrain frames 10/11 and any other frame are refused with
  MAV_MISSION_UNSUPPORTED_FRAME, frame 2 (MISSION) with MAV_MISSION_UNSUPPORTED;
* a command without a location is accepted only in frame 2 (else MAV_MISSION_UNSUPPORTED)
  and kept verbatim;
* NAV_TAKEOFF drops params 1-3, NAV_WAYPOINT param3, NAV_LAND params 1 and 3; their yaw
  (param4) is kept as float32 radians wrapped to [0, 2 pi) and returned in degrees;
* params and altitude travel as float32, ``autocontinue`` as sent.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = [
    "ABSOLUTE_FRAMES",
    "LOCATION_COMMANDS",
    "NAN_PARAM4_COMMANDS",
    "RELATIVE_FRAMES",
    "TERRAIN_FRAMES",
    "Home",
    "Item",
    "MissionStore",
    "ParamStore",
    "ardupilot_check",
    "ardupilot_stored",
    "centimetres",
    "px4_check",
    "px4_stored",
]

ABSOLUTE_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_MISSION}
)
RELATIVE_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
TERRAIN_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}
)
# Commands whose x/y/z are a location (AP_Mission::stored_in_location, the ones simulated).
LOCATION_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_NAV_WAYPOINT,
        mavlink.MAV_CMD_NAV_LOITER_UNLIM,
        mavlink.MAV_CMD_NAV_LOITER_TIME,
        mavlink.MAV_CMD_NAV_LAND,
        mavlink.MAV_CMD_NAV_TAKEOFF,
        mavlink.MAV_CMD_DO_SET_ROI,
    }
)
NAN_PARAM4_COMMANDS = frozenset(
    {mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND}
)
# ArduPilot stores a location's latitude/longitude only inside these limits (degrees * 1e7).
_LAT_LIMIT_E7 = 90 * 10**7
_LON_LIMIT_E7 = 180 * 10**7
_LOCATION_ALT_MAX_M = 83_000.0
_INVALID_PARAM = (
    mavlink.MAV_MISSION_INVALID_PARAM1,
    mavlink.MAV_MISSION_INVALID_PARAM2,
    mavlink.MAV_MISSION_INVALID_PARAM3,
    mavlink.MAV_MISSION_INVALID_PARAM4,
)


@dataclass(frozen=True, slots=True)
class Item:
    """One mission item in MISSION_ITEM_INT form (x, y as integers)."""

    command: int
    frame: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    autocontinue: int = 1

    @property
    def params(self) -> tuple[float, float, float, float]:
        """param1..param4."""
        return (self.param1, self.param2, self.param3, self.param4)


def _f32(value: float) -> float:
    return float(np.float32(value))


def _uint(value: float, bits: int) -> float:
    """A float param stored in an unsigned C integer field (truncated, wrapped)."""
    if not math.isfinite(value):
        return 0.0
    return float(int(value) % (1 << bits))


def _int8(value: float) -> float:
    if not math.isfinite(value):
        return 0.0
    wrapped = int(value) % 256
    return float(wrapped - 256 if wrapped >= 128 else wrapped)


def _keep(value: float) -> float:
    return _f32(value)


def _zero(_value: float) -> float:
    return 0.0


ParamStore = Callable[[float], float]
# How each simulated command stores params 1-4 (AP_Mission::mavlink_int_to_mission_cmd and
# mission_cmd_to_mavlink_int, Copter build).
_PARAM_STORAGE: dict[int, tuple[ParamStore, ParamStore, ParamStore, ParamStore]] = {
    mavlink.MAV_CMD_NAV_WAYPOINT: (lambda v: _uint(v, 16), _zero, _zero, _zero),
    mavlink.MAV_CMD_NAV_TAKEOFF: (lambda v: _uint(v, 16), _zero, _zero, _zero),
    mavlink.MAV_CMD_NAV_LAND: (
        lambda v: _uint(v, 16),
        _zero,
        _zero,
        lambda v: -1.0 if v < 0 else 1.0,
    ),
    mavlink.MAV_CMD_NAV_LOITER_TIME: (
        lambda v: _uint(v, 16),
        _zero,
        lambda v: -1.0 if v < 0 else 1.0,
        lambda v: 1.0 if v > 0 else 0.0,
    ),
    mavlink.MAV_CMD_NAV_LOITER_UNLIM: (_zero, _zero, lambda v: _uint(abs(v), 16), _zero),
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: (_zero, _zero, _zero, _zero),
    # Change_Speed_Command: speed_type uint8_t, target_ms and throttle_pct float.
    mavlink.MAV_CMD_DO_CHANGE_SPEED: (lambda v: _uint(v, 8), _keep, _keep, _zero),
    mavlink.MAV_CMD_DO_SET_ROI: (lambda v: _uint(v, 16), _zero, _zero, _zero),
    mavlink.MAV_CMD_CONDITION_DELAY: (_keep, _zero, _zero, _zero),
    # Yaw_Command: angle_deg and turn_rate_dps float, direction int8_t, relative_angle uint8_t.
    mavlink.MAV_CMD_CONDITION_YAW: (_keep, _keep, _int8, lambda v: _uint(v, 8)),
    mavlink.MAV_CMD_DO_MOUNT_CONTROL: (_keep, _keep, _keep, _zero),
    mavlink.MAV_CMD_DO_DIGICAM_CONTROL: (
        lambda v: _uint(v, 8),
        lambda v: _uint(v, 8),
        _int8,
        lambda v: _uint(v, 8),
    ),
}


def ardupilot_check(item: Item) -> int:
    """The MAV_MISSION_RESULT ArduPilot answers when this item is uploaded."""
    storage = _PARAM_STORAGE.get(item.command)
    if storage is None:
        return int(mavlink.MAV_MISSION_UNSUPPORTED)
    for index, value in enumerate(item.params):
        nan_allowed = index == 3 and item.command in NAN_PARAM4_COMMANDS
        if math.isinf(value) or (math.isnan(value) and not nan_allowed):
            return int(_INVALID_PARAM[index])
    if item.command in LOCATION_COMMANDS:
        if abs(item.x) > _LAT_LIMIT_E7:
            return int(mavlink.MAV_MISSION_INVALID_PARAM5_X)
        if abs(item.y) > _LON_LIMIT_E7:
            return int(mavlink.MAV_MISSION_INVALID_PARAM6_Y)
        if math.isnan(item.z) or abs(item.z) >= _LOCATION_ALT_MAX_M:
            return int(mavlink.MAV_MISSION_INVALID_PARAM7)
        if item.frame not in ABSOLUTE_FRAMES | RELATIVE_FRAMES | TERRAIN_FRAMES:
            return int(mavlink.MAV_MISSION_UNSUPPORTED_FRAME)
    return int(mavlink.MAV_MISSION_ACCEPTED)


def centimetres(z_m: float) -> float:
    """An altitude as ArduPilot keeps it: ``int32(z * 100.0f)`` read back as ``alt / 100.0f``."""
    cm = int(np.float32(z_m) * np.float32(100.0))
    return float(np.float32(cm) / np.float32(100.0))


def ardupilot_stored(item: Item) -> Item:
    """What ArduPilot returns on download for an item it accepted."""
    storage = _PARAM_STORAGE[item.command]
    p1, p2, p3, p4 = (store(value) for store, value in zip(storage, item.params, strict=True))
    if item.command in LOCATION_COMMANDS:
        if item.frame in TERRAIN_FRAMES:
            frame = mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT
        elif item.frame in RELATIVE_FRAMES:
            frame = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
        else:
            frame = mavlink.MAV_FRAME_GLOBAL
        x, y, z = item.x, item.y, centimetres(item.z)
    else:
        frame, x, y, z = mavlink.MAV_FRAME_GLOBAL, 0, 0, 0.0
        if item.command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL:
            x, y = int(_uint(item.x, 8)), int(_uint(item.y, 8))
    return Item(item.command, frame, p1, p2, p3, p4, x, y, z, 1)


# PX4's located frames and what each is returned as.
_PX4_LOCATED_FRAME = {
    mavlink.MAV_FRAME_GLOBAL: mavlink.MAV_FRAME_GLOBAL_INT,
    mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL_INT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
}


def _px4_yaw(value: float) -> float:
    """wrap_2pi(radians(yaw)) in float32, read back in degrees."""
    if not math.isfinite(value):
        return value
    radians = np.float32(math.radians(value)) % np.float32(2.0 * math.pi)
    return _f32(math.degrees(float(np.float32(radians))))


_PX4_PARAM_STORAGE: dict[int, tuple[ParamStore, ParamStore, ParamStore, ParamStore]] = {
    mavlink.MAV_CMD_NAV_TAKEOFF: (_zero, _zero, _zero, _px4_yaw),
    mavlink.MAV_CMD_NAV_WAYPOINT: (_keep, _keep, _zero, _px4_yaw),
    mavlink.MAV_CMD_NAV_LAND: (_zero, _keep, _zero, _px4_yaw),
}


def px4_check(item: Item) -> int:
    """The MAV_MISSION_RESULT PX4 answers when this item is uploaded."""
    if item.command in LOCATION_COMMANDS:
        if item.frame == mavlink.MAV_FRAME_MISSION:
            return int(mavlink.MAV_MISSION_UNSUPPORTED)
        if item.frame not in _PX4_LOCATED_FRAME:
            return int(mavlink.MAV_MISSION_UNSUPPORTED_FRAME)
    elif item.frame != mavlink.MAV_FRAME_MISSION:
        return int(mavlink.MAV_MISSION_UNSUPPORTED)
    return int(mavlink.MAV_MISSION_ACCEPTED)


def px4_stored(item: Item) -> Item:
    """What PX4 returns on download for an item it accepted."""
    if item.command not in LOCATION_COMMANDS:
        return item  # already float32 from the wire
    storage = _PX4_PARAM_STORAGE.get(item.command, (_keep, _keep, _keep, _keep))
    p1, p2, p3, p4 = (store(value) for store, value in zip(storage, item.params, strict=True))
    frame = _PX4_LOCATED_FRAME[item.frame]
    return Item(
        item.command, frame, p1, p2, p3, p4, item.x, item.y, _f32(item.z), item.autocontinue
    )


@dataclass(frozen=True, slots=True)
class Home:
    """The vehicle's home: degrees * 1e7 and metres above mean sea level."""

    lat_e7: int
    lon_e7: int
    amsl_m: float


class MissionStore:
    """The mission held by the vehicle, with ArduPilot's (or PX4's) storage rules.

    Parameters
    ----------
    home
        Returned as seq 0 in ArduPilot mode.
    capacity
        Most items the vehicle holds, home included (ArduPilot's ``num_commands_max``).
    px4
        Store items verbatim and keep no home item.
    """

    def __init__(self, home: Home, capacity: int, px4: bool = False) -> None:
        self.home = home
        self.capacity = capacity
        self.px4 = px4
        self._items: list[Item] = []
        self.corrupt_seq: int | None = None
        self.changes = 0

    def __len__(self) -> int:
        if self.px4:
            return len(self._items)
        return 1 + len(self._items)

    @property
    def first_seq(self) -> int:
        """Seq of the first item a mission flies (1 after ArduPilot's home, else 0)."""
        return 0 if self.px4 else 1

    def check(self, item: Item) -> int:
        """MAV_MISSION_RESULT for uploading ``item``."""
        if self.px4:
            return px4_check(item)
        return ardupilot_check(item)

    def truncate(self, count: int) -> None:
        """Drop everything from seq ``count`` on, as a new upload of ``count`` items does."""
        keep = count if self.px4 else max(count - 1, 0)
        del self._items[keep:]
        self.changes += 1

    def clear(self) -> None:
        """MISSION_CLEAR_ALL: keep home only."""
        self._items.clear()
        self.changes += 1

    def write(self, seq: int, item: Item) -> None:
        """Store an accepted item at ``seq`` (replace or append); ArduPilot ignores seq 0."""
        if self.px4:
            item = px4_stored(item)
        else:
            if seq == 0:
                return
            item = ardupilot_stored(item)
            seq -= 1
        if seq < len(self._items):
            self._items[seq] = item
        elif seq == len(self._items):
            self._items.append(item)
        else:
            raise IndexError(f"mission item {seq} written past the end")
        self.changes += 1

    def read(self, seq: int) -> Item:
        """The item at ``seq`` as a download returns it."""
        if not self.px4 and seq == 0:
            item = Item(
                mavlink.MAV_CMD_NAV_WAYPOINT,
                mavlink.MAV_FRAME_GLOBAL,
                0.0,
                0.0,
                0.0,
                0.0,
                self.home.lat_e7,
                self.home.lon_e7,
                centimetres(self.home.amsl_m),
            )
        else:
            item = self._items[seq if self.px4 else seq - 1]
        if seq == self.corrupt_seq:
            # A fault the read-back comparison must catch: about 1 m further north.
            item = replace(item, x=item.x + 90)
        return item

    def items(self) -> list[Item]:
        """Every item, seq 0 first, as a download returns them."""
        return [self.read(seq) for seq in range(len(self))]
