"""Mission Planner ``.waypoints`` files (``QGC WPL 110``).

One item a line, 12 tab-separated fields::

    seq  current  frame  command  param1  param2  param3  param4  x  y  z  autocontinue

Line 0 is home for both firmwares, as Mission Planner, QGroundControl and pymavlink's
``MAVWPLoader`` expect: frame GLOBAL, NAV_WAYPOINT, AMSL altitude, ``current`` 1 (Mission
Planner marks home that way; pymavlink keeps the flag and MAVSDK's importer resets it). The
mission items follow with seq 1..n. MAVSDK's importer turns that line into items of its own
(see ``tests/files/test_formats.py``), so upload :meth:`Mission.upload_items`, never this file.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal

from urpt_gcs.errors import MissionFileError, SettingsError
from urpt_gcs.files.formats.qgc_plan import assemble_mission, check_item, make_item, show
from urpt_gcs.flight.mission import (
    DEFAULT_SPEED_M_S,
    FIRMWARES,
    Firmware,
    GeoPoint,
    Mission,
    MissionItem,
    commanded_speed,
    count_problem,
)

__all__ = [
    "FIELD_COUNT",
    "FIELD_NAMES",
    "HEADER",
    "MIN_DECIMALS",
    "NAN_TEXT",
    "read_waypoints",
    "waypoints_text",
]

HEADER = "QGC WPL 110"
FIELD_COUNT = 12
FIELD_NAMES = (
    "seq",
    "current",
    "frame",
    "command",
    "param1",
    "param2",
    "param3",
    "param4",
    "x",
    "y",
    "z",
    "autocontinue",
)

# NaN is written as "NaN": pymavlink's loader (Python float) and MAVSDK's importer (strtod)
# read any case, and "NaN" is also what .NET (Mission Planner) writes and reads. Only PX4
# missions carry NaN (unset yaw, unset gimbal rates); writing 0 instead would change their
# meaning (yaw north, rate zero).
NAN_TEXT = "NaN"
# Fewest decimals written: 8 is about 1 mm in latitude, finer than MAVLink's 1e-7 degrees.
MIN_DECIMALS = 8

_SAVE_AS_WAYPOINTS = "save the mission from Mission Planner as a .waypoints file"
_FIX_LINE = "correct that line, or save the mission from Mission Planner again"
_INT_RE = re.compile(r"[+-]?[0-9]{1,10}")
_FLOAT_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?nan", re.I)


def waypoints_text(mission: Mission) -> str:
    """Write a mission as a Mission Planner ``.waypoints`` file.

    Parameters
    ----------
    mission
        The mission; home is written on line 0, its items from seq 1.

    Returns
    -------
    str
        The text: LF line ends, tab-separated, every number in fixed notation with at least
        8 decimals and as many more as it needs to read back exactly.
    """
    lines = [HEADER, _line(0, mission.home_item, current=True)]
    lines.extend(_line(seq, item) for seq, item in enumerate(mission.items, start=1))
    return "\n".join(lines) + "\n"


def _line(seq: int, item: MissionItem, *, current: bool = False) -> str:
    if any(math.isinf(p) for p in item.params):
        raise SettingsError(f"mission item {seq} has an infinite param: {item.params}")
    fields = [str(seq), str(int(current)), str(item.frame), str(item.command)]
    fields.extend(_number_text(p) for p in item.params)
    fields.append(str(int(item.autocontinue)))
    return "\t".join(fields)


def _number_text(value: float) -> str:
    if math.isnan(value):
        return NAN_TEXT
    # The shortest digits that read back exactly, in positional notation (no exponent).
    whole, _, decimals = format(Decimal(repr(float(value))), "f").partition(".")
    return f"{whole}.{decimals.ljust(MIN_DECIMALS, '0')}"


def read_waypoints(text: str, source: str, firmware: Firmware = "ardupilot") -> Mission:
    """Read a Mission Planner ``.waypoints`` file.

    Parameters
    ----------
    text
        The file's contents.
    source
        Name of the file, used in error messages.
    firmware
        The firmware the mission is for; the format does not record it.

    Returns
    -------
    Mission
        Home from the line of seq 0 (its x, y, z), the items from the lines after it (seq
        1, 2, ... in order; their ``current`` flags are not kept), the flight altitude from the
        first takeoff relative to home (else the highest relative altitude). The format has no
        speed fields: the speed is the first DO_CHANGE_SPEED's, else ``DEFAULT_SPEED_M_S``.

    Raises
    ------
    MissionFileError
        If the text is not a file urpt-gcs can use, or an item holds a value no vehicle
        should be given (:func:`~urpt_gcs.flight.mission.item_problem`); the message names the line
        and the fix.
    """
    if firmware not in FIRMWARES:
        raise SettingsError(f"firmware {firmware!r} is not one of {', '.join(FIRMWARES)}")
    # A byte-order mark is how some Windows editors save; nothing else in the file changes.
    lines = text.removeprefix("\ufeff").split("\n")
    header = lines[0].strip()
    if header != HEADER:
        raise MissionFileError(
            f"{source}: line 1 is {show(header)}, not {HEADER!r}: {_SAVE_AS_WAYPOINTS}"
        )
    rows: list[tuple[int, list[str]]] = []
    for number, line in enumerate(lines[1:], start=2):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            rows.append((number, stripped.split()))
    if not rows:
        raise MissionFileError(f"{source}: no home line after the header: {_SAVE_AS_WAYPOINTS}")
    too_many = count_problem(len(rows) - 1, firmware)
    if too_many is not None:
        raise MissionFileError(f"{source}: {too_many}")
    home_line, home_fields = rows[0]
    home_item = _read_item(home_line, home_fields, source, seq=0)
    try:
        home = GeoPoint(home_item.params[4], home_item.params[5], home_item.params[6])
    except SettingsError as exc:
        raise MissionFileError(
            f"{source}: line {home_line} (home) is not usable: {exc}: set the home position "
            f"in Mission Planner and save again"
        ) from None
    items: list[MissionItem] = []
    for seq, (number, fields) in enumerate(rows[1:], start=1):
        item = _read_item(number, fields, source, seq)
        check_item(f"{source}: line {number}", item, home, firmware)
        items.append(item)
    speed = commanded_speed(items) or DEFAULT_SPEED_M_S
    return assemble_mission(
        source,
        home=home,
        items=tuple(items),
        firmware=firmware,
        cruise_speed_m_s=speed,
        hover_speed_m_s=speed,
    )


def _read_item(number: int, fields: list[str], source: str, seq: int) -> MissionItem:
    where = f"{source}: line {number}"
    if len(fields) != FIELD_COUNT:
        raise MissionFileError(
            f"{where} has {len(fields)} fields, expected {FIELD_COUNT} (seq current frame "
            f"command p1 p2 p3 p4 x y z autocontinue): {_SAVE_AS_WAYPOINTS}"
        )
    for index in (0, 1, 2, 3, 11):
        if not _INT_RE.fullmatch(fields[index]):
            raise MissionFileError(
                f"{where}: {FIELD_NAMES[index]} {show(fields[index])} is not an integer: "
                f"{_FIX_LINE}"
            )
    frame, command, autocontinue = int(fields[2]), int(fields[3]), int(fields[11])
    # The vehicle numbers items by position: a line repeated or lost must not shift the rest.
    if int(fields[0]) != seq:
        raise MissionFileError(
            f"{where}: seq {int(fields[0])}, expected {seq}: seq must count 0 (home), 1, 2, ... "
            f"one line per item, so a line is repeated or missing: {_FIX_LINE}"
        )
    if int(fields[1]) not in (0, 1):
        raise MissionFileError(f"{where}: current {int(fields[1])} is not 0 or 1: {_FIX_LINE}")
    if not 0 <= frame <= 255:
        raise MissionFileError(f"{where}: frame {frame} is not a MAV_FRAME number: {_FIX_LINE}")
    if not 0 <= command <= 65535:
        raise MissionFileError(f"{where}: command {command} is not a MAV_CMD number: {_FIX_LINE}")
    if autocontinue not in (0, 1):
        raise MissionFileError(f"{where}: autocontinue {autocontinue} is not 0 or 1: {_FIX_LINE}")
    params: list[float] = []
    for index in range(4, 11):
        value = float(fields[index]) if _FLOAT_RE.fullmatch(fields[index]) else math.inf
        if math.isinf(value):
            raise MissionFileError(
                f"{where}: {FIELD_NAMES[index]} {show(fields[index])} is not a finite number: "
                f"{_FIX_LINE}"
            )
        params.append(value)
    return make_item(
        where, command=command, frame=frame, params=params, autocontinue=bool(autocontinue)
    )
