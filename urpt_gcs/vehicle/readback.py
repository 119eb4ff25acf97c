"""The check of a vehicle's read-back: is the mission it holds the one that was sent?

An autopilot does not hand a mission back exactly as it was sent. What a real ArduPilot was
seen to change (``../shared/FACTS.md``) is treated as equal:

* seq 0 comes back as the vehicle's real home, so it is not compared;
* frame 6 (GLOBAL_RELATIVE_ALT_INT) as 3, 5 (GLOBAL_INT) as 0, 11 as 10, and the frame of a
  command without a location (sent as 2, MISSION) as 0;
* a NaN param4 as 0, ``current`` always 0.

Besides, ArduPilot stores each command compactly (``AP_Mission::mavlink_int_to_mission_cmd``
and ``mission_cmd_to_mavlink_int``) and returns only what that command uses. For the commands
below a field may also come back in that stored form: dropped fields as 0, NAV_WAYPOINT's hold
as whole seconds, DO_DIGICAM_CONTROL's fields as bytes, altitudes in whole centimetres. A field
that comes back changed in a way the vehicle would fly differently (a truncated hold) is
accepted with a warning. Anything else is a mismatch: command, frame, params to float32,
latitude/longitude to 1e-7 degrees, altitude to 1 cm, autocontinue.

PX4 (v1.16, seen against its SITL) keeps a located item as a position with an "altitude is
relative" flag, and a command without a location (frame 2, MISSION) verbatim. Treated as equal:

* frame 3 (GLOBAL_RELATIVE_ALT) as 6, 0 (GLOBAL) as 5; 5 and 6 as sent (PX4 refuses the
  terrain frames 10 and 11 with MAV_MISSION_UNSUPPORTED_FRAME, so they never come back);
* the params PX4 drops as 0: NAV_TAKEOFF's params 1-3, NAV_WAYPOINT's param3 (pass radius),
  NAV_LAND's params 1 and 3;
* a yaw (param4 of NAV_TAKEOFF, NAV_WAYPOINT and NAV_LAND) as the same heading in [0, 360)
  degrees, through float32 radians (-90 as 270, 400 as 39.99999);
* the altitude as float32; ``current`` is not compared (PX4 marks its current item).
Anything else must come back as sent.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.flight.mission import Firmware, command_name
from urpt_gcs.flight.wire import Comparison, WireItem

__all__ = ["ALTITUDE_TOLERANCE_M", "HEADING_TOLERANCE_DEG", "Store", "compare"]

ALTITUDE_TOLERANCE_M = 0.01 + 1e-4


# --- ArduPilot's storage of the commands a survey mission uses ------------------------------

Store = Callable[[float], float]


def _f32(value: float) -> float:
    return float(np.float32(value))


def _drop(_value: float) -> float:
    return 0.0


def _unsigned(bits: int) -> Store:
    def store(value: float) -> float:
        return float(int(value) % (1 << bits)) if math.isfinite(value) else 0.0

    return store


def _int8(value: float) -> float:
    if not math.isfinite(value):
        return 0.0
    wrapped = int(value) % 256
    return float(wrapped - 256 if wrapped >= 128 else wrapped)


def _sign(value: float) -> float:
    return -1.0 if value < 0 else 1.0


@dataclass(frozen=True, slots=True)
class _Stored:
    params: tuple[Store, Store, Store, Store]
    location: bool
    x: Store = _drop
    y: Store = _drop


_UINT16, _UINT8 = _unsigned(16), _unsigned(8)
_AP_STORED: dict[int, _Stored] = {
    mavlink.MAV_CMD_NAV_WAYPOINT: _Stored((_UINT16, _drop, _drop, _drop), True),
    mavlink.MAV_CMD_NAV_TAKEOFF: _Stored((_UINT16, _drop, _drop, _drop), True),
    mavlink.MAV_CMD_NAV_LAND: _Stored((_UINT16, _drop, _drop, _sign), True),
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: _Stored((_drop, _drop, _drop, _drop), False),
    mavlink.MAV_CMD_DO_MOUNT_CONTROL: _Stored((_f32, _f32, _f32, _drop), False),
    # speed_type uint8_t, target_ms and throttle_pct float (AP_Mission's Change_Speed_Command).
    mavlink.MAV_CMD_DO_CHANGE_SPEED: _Stored((_UINT8, _f32, _f32, _drop), False),
    mavlink.MAV_CMD_DO_DIGICAM_CONTROL: _Stored(
        (_UINT8, _UINT8, _int8, _UINT8), False, x=_UINT8, y=_UINT8
    ),
    # Yaw_Command: angle_deg and turn_rate_dps float, direction int8_t, relative_angle uint8_t.
    mavlink.MAV_CMD_CONDITION_YAW: _Stored((_f32, _f32, _int8, _UINT8), False),
}
_AP_FRAME = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mavlink.MAV_FRAME_MISSION: mavlink.MAV_FRAME_GLOBAL,
}


# Seen on PX4 v1.16 SITL: a located item comes back in the _INT frame of its altitude's kind
# (relative or above mean sea level).
_PX4_FRAME = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink.MAV_FRAME_GLOBAL: mavlink.MAV_FRAME_GLOBAL_INT,
}
# Headings within this are equal: PX4's float32 radians move 400 degrees to 39.99999.
HEADING_TOLERANCE_DEG = 1e-3


def _heading(value: float) -> float:
    """A yaw as PX4 keeps it: radians wrapped to [0, 2 pi), returned in degrees."""
    return value % 360.0 if math.isfinite(value) else value


def _same_heading(a: float, b: float) -> bool:
    return abs((a - b + 180.0) % 360.0 - 180.0) <= HEADING_TOLERANCE_DEG


_PX4_STORED: dict[int, _Stored] = {
    mavlink.MAV_CMD_NAV_TAKEOFF: _Stored((_drop, _drop, _drop, _heading), True),
    mavlink.MAV_CMD_NAV_WAYPOINT: _Stored((_f32, _f32, _drop, _heading), True),
    mavlink.MAV_CMD_NAV_LAND: _Stored((_drop, _f32, _drop, _heading), True),
}


def _ap_stored_z(z: float) -> float:
    """int32(z * 100.0f) centimetres, read back as alt / 100.0f."""
    return float(np.float32(int(np.float32(z) * np.float32(100.0))) / np.float32(100.0))


# --- the comparison ------------------------------------------------------------------------


def _same_param(sent: float, got: float) -> bool:
    if math.isnan(sent) or math.isnan(got):
        return math.isnan(sent) and math.isnan(got)
    return _f32(sent) == _f32(got)


def compare(sent: Sequence[WireItem], got: Sequence[WireItem], firmware: Firmware) -> Comparison:
    """Compare a downloaded mission with the uploaded one.

    Parameters
    ----------
    sent
        The items uploaded, seq from 0.
    got
        The items downloaded back.
    firmware
        Whose normalisation to allow for (see the module docstring).

    Returns
    -------
    Comparison
        Every difference that matters, one line each; empty when the vehicle holds the mission.
    """
    if len(got) != len(sent):
        return Comparison((f"the vehicle holds {len(got)} items, {len(sent)} were sent",), ())
    mismatches: list[str] = []
    warnings: list[str] = []
    ardupilot = firmware == "ardupilot"
    for a, b in zip(sent, got, strict=True):
        if ardupilot and a.seq == 0:
            continue  # home: the vehicle returns its own
        where = f"seq {a.seq} ({command_name(a.command)})"
        if b.seq != a.seq or b.command != a.command:
            mismatches.append(f"{where}: read back as seq {b.seq} {command_name(b.command)}")
            continue
        stored = (_AP_STORED if ardupilot else _PX4_STORED).get(a.command)
        _compare_item(a, b, stored, ardupilot, where, mismatches, warnings)
    return Comparison(tuple(mismatches), tuple(warnings))


def _compare_item(
    a: WireItem,
    b: WireItem,
    stored: _Stored | None,
    ardupilot: bool,
    where: str,
    mismatches: list[str],
    warnings: list[str],
) -> None:
    def differs(field: str, sent: object, got: object) -> None:
        mismatches.append(f"{where}: {field} sent {sent}, read back {got}")

    frame_a, frame_b = a.frame, b.frame
    frame_a = (_AP_FRAME if ardupilot else _PX4_FRAME).get(frame_a, frame_a)
    if frame_a != frame_b and not (stored is not None and not stored.location):
        differs("frame", a.frame, b.frame)
    if a.autocontinue != b.autocontinue:
        differs("autocontinue", a.autocontinue, b.autocontinue)
    for index, (sent, got) in enumerate(zip(a.params, b.params, strict=True)):
        name = f"param{index + 1}"
        if _same_param(sent, got):
            continue
        if ardupilot and index == 3 and math.isnan(sent) and got == 0.0:
            continue
        store = stored.params[index] if stored is not None else None
        if store is _heading and _same_heading(_heading(sent), got):
            continue  # the same heading
        if store is not None and _same_param(store(sent), got):
            if store is not _drop:
                warnings.append(f"{where}: the vehicle keeps {name} {sent:g} as {got:g}")
            continue
        differs(name, sent, got)
    xy_store = (stored.x, stored.y) if stored is not None and not stored.location else None
    for index, (label, sent_i, got_i) in enumerate(
        (("x (param5)", a.x, b.x), ("y (param6)", a.y, b.y))
    ):
        if sent_i == got_i:
            continue
        if xy_store is not None and xy_store[index](sent_i) == got_i:
            continue
        differs(label, sent_i, got_i)
    if abs(a.z - b.z) <= ALTITUDE_TOLERANCE_M:
        return
    if stored is not None and (not stored.location and b.z == 0.0):
        return
    if ardupilot and stored is not None and stored.location and _ap_stored_z(a.z) == _f32(b.z):
        return
    differs("z (param7)", a.z, b.z)
