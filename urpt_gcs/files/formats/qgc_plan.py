"""QGroundControl ``.plan`` files (JSON).

The plan carries the mission items only; home travels as ``plannedHomePosition``. QGroundControl
and MAVSDK's importer put it back at seq 0 when the vehicle runs ArduPilot, so writing it as an
item too would fly it twice.

What a replay must check travels in the plan under the top-level key ``urptGcs``
(:class:`ReplayCheck`): QGroundControl validates only the keys it knows at the top level of a
plan (``PlanMasterController::loadFromFile``) and MAVSDK's importer reads only ``mission``,
``geoFence`` and ``rallyPoints``, so both ignore it; a plan saved again from QGroundControl
loses it, and replay then falls back to its flags.

The readers of both formats share the helpers at the end of this module: they turn parsed
values into a :class:`~urpt_gcs.flight.mission.Mission` and every validation failure into a
:class:`~urpt_gcs.errors.MissionFileError` naming the file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeGuard

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import MissionFileError, SettingsError
from urpt_gcs.flight.mission import (
    AUTOPILOT_OF,
    Firmware,
    GeoPoint,
    Mission,
    MissionItem,
    command_name,
    count_problem,
    item_problem,
)
from urpt_gcs.site.camera import Frame
from urpt_gcs.site.targets import Target

__all__ = [
    "ALTITUDE_MODE_OF_FRAME",
    "CHECK_KEY",
    "CHECK_VERSION",
    "FIRMWARE_OF",
    "GEOFENCE_VERSION",
    "GROUND_STATION",
    "MISSION_VERSION",
    "PLAN_FILE_VERSION",
    "POLYGON_VERSION",
    "RALLY_VERSION",
    "RELATIVE_FRAMES",
    "ReplayCheck",
    "assemble_mission",
    "check_item",
    "make_item",
    "plan_json",
    "read_plan",
    "read_replay_check",
    "show",
]

PLAN_FILE_VERSION = 1
MISSION_VERSION = 2
GEOFENCE_VERSION = 2
RALLY_VERSION = 2
POLYGON_VERSION = 1
GROUND_STATION = "urpt-gcs"

FIRMWARE_OF: dict[int, Firmware] = {value: key for key, value in AUTOPILOT_OF.items()}

RELATIVE_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)

# QGroundControl's AltitudeMode for a frame: 1 relative to home, 2 AMSL, 4 terrain frame.
ALTITUDE_MODE_OF_FRAME: dict[int, int] = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: 1,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: 1,
    mavlink.MAV_FRAME_GLOBAL: 2,
    mavlink.MAV_FRAME_GLOBAL_INT: 2,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT: 4,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: 4,
}

# The top-level key QGroundControl and MAVSDK leave alone, and its layout's version.
CHECK_KEY = "urptGcs"
CHECK_VERSION = 1

_SAVE_AS_PLAN = "save the mission from QGroundControl as a .plan file"
_FIX_ITEM = "correct that item, or save the plan from QGroundControl again"


@dataclass(frozen=True, slots=True)
class ReplayCheck:
    """What a replay of one sortie's plan must check, as the plan was made.

    Attributes
    ----------
    fov_deg
        The camera half-angle from nadir the plan was made for.
    min_clearance_m
        The least height above the terrain the legs were planned to keep.
    targets
        The targets this sortie must photograph (names and WGS84 positions).
    sortie, sorties
        Which sortie of how many (1 of 1 for a plan in one flight).
    frame, gsd_cm
        A frame camera (None: the cone of ``fov_deg``) and the ground resolution each photo
        had to reach (None: none asked for).
    """

    fov_deg: float
    min_clearance_m: float
    targets: tuple[Target, ...]
    sortie: int = 1
    sorties: int = 1
    frame: Frame | None = None
    gsd_cm: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError(f"camera half-angle {self.fov_deg} is outside (0, 90) degrees")
        if not (math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0.0):
            raise SettingsError(f"least clearance {self.min_clearance_m} must be 0 or more m")
        if not 1 <= self.sortie <= self.sorties:
            raise SettingsError(f"sortie {self.sortie} of {self.sorties} is not one of them")

    def as_json(self) -> dict[str, Any]:
        """The ``urptGcs`` value of a plan."""
        return {
            "version": CHECK_VERSION,
            "sortie": self.sortie,
            "sorties": self.sorties,
            "fovDeg": self.fov_deg,
            "minClearanceM": self.min_clearance_m,
            "targets": [{"name": t.name, "lat": t.lat_deg, "lon": t.lon_deg} for t in self.targets],
            **self._frame_json(),
        }

    def _frame_json(self) -> dict[str, Any]:
        if self.frame is None:
            return {}
        f = self.frame
        return {
            "frame": {
                "sensorMm": [f.sensor_w_mm, f.sensor_h_mm],
                "focalMm": f.focal_mm,
                "imagePx": [f.image_w_px, f.image_h_px],
                "gsdCm": self.gsd_cm,
            }
        }


def plan_json(
    mission: Mission,
    geofence: Sequence[tuple[float, float]] = (),
    check: ReplayCheck | None = None,
) -> str:
    """Write a mission as a QGroundControl ``.plan`` file.

    Parameters
    ----------
    mission
        The mission; its items are written as SimpleItems and its home as
        ``plannedHomePosition`` (AMSL altitude).
    geofence
        Vertices (latitude, longitude) in degrees of one inclusion polygon, or empty for none.
    check
        What a replay of the file must check, written under ``urptGcs``; None for nothing.

    Returns
    -------
    str
        The JSON text, ending with a newline. NaN params are written as ``null``.
    """
    if 0 < len(geofence) < 3:
        raise SettingsError(f"geofence has {len(geofence)} vertices; give at least 3 or none")
    polygons: list[dict[str, Any]] = []
    if geofence:
        vertices = [list(_fence_vertex(index, vertex)) for index, vertex in enumerate(geofence)]
        polygons.append({"inclusion": True, "polygon": vertices, "version": POLYGON_VERSION})
    plan = {
        "fileType": "Plan",
        "version": PLAN_FILE_VERSION,
        "groundStation": GROUND_STATION,
        "mission": {
            "version": MISSION_VERSION,
            "firmwareType": AUTOPILOT_OF[mission.firmware],
            "vehicleType": mavlink.MAV_TYPE_QUADROTOR,
            "cruiseSpeed": mission.cruise_speed_m_s,
            "hoverSpeed": mission.hover_speed_m_s,
            "plannedHomePosition": [
                mission.home.lat_deg,
                mission.home.lon_deg,
                mission.home.amsl_m,
            ],
            "items": [_simple_item(item, index) for index, item in enumerate(mission.items)],
        },
        "geoFence": {"version": GEOFENCE_VERSION, "polygons": polygons, "circles": []},
        "rallyPoints": {"version": RALLY_VERSION, "points": []},
    }
    if check is not None:
        plan[CHECK_KEY] = check.as_json()
    # allow_nan=False: NaN has already become null, and Infinity is not JSON.
    return json.dumps(plan, indent=4, allow_nan=False) + "\n"


def _fence_vertex(index: int, vertex: tuple[float, float]) -> tuple[float, float]:
    try:
        point = GeoPoint(float(vertex[0]), float(vertex[1]), 0.0)
    except (SettingsError, TypeError, ValueError, IndexError) as exc:
        raise SettingsError(f"geofence vertex {index} {vertex!r} is not usable: {exc}") from None
    return point.lat_deg, point.lon_deg


def _simple_item(item: MissionItem, index: int) -> dict[str, Any]:
    if any(math.isinf(p) for p in item.params):
        raise SettingsError(f"mission item {index + 1} has an infinite param: {item.params}")
    json_item: dict[str, Any] = {
        "type": "SimpleItem",
        "command": item.command,
        "frame": item.frame,
        "params": [None if math.isnan(p) else p for p in item.params],
        "autoContinue": item.autocontinue,
        "doJumpId": index + 1,
    }
    mode = ALTITUDE_MODE_OF_FRAME.get(item.frame)
    if mode is not None:
        json_item["AltitudeMode"] = mode
        json_item["Altitude"] = item.z
        json_item["AMSLAltAboveTerrain"] = None
    return json_item


def read_plan(text: str, source: str) -> Mission:
    """Read a QGroundControl ``.plan`` file.

    Parameters
    ----------
    text
        The file's contents.
    source
        Name of the file, used in error messages.

    Returns
    -------
    Mission
        Firmware from ``firmwareType``, home from ``plannedHomePosition``, the flight altitude
        from the first takeoff relative to home (else the highest relative altitude), speeds
        from ``cruiseSpeed`` and ``hoverSpeed``. The geofence and rally points are not read.

    Raises
    ------
    MissionFileError
        If the text is not a plan urpt-gcs can use; the message says why and what to do.
    """
    try:
        root = json.loads(text.removeprefix("\ufeff"), parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise MissionFileError(
            f"{source}: not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno}): "
            f"{_SAVE_AS_PLAN}"
        ) from None
    except (ValueError, RecursionError) as exc:
        raise MissionFileError(f"{source}: not valid JSON ({exc}): {_SAVE_AS_PLAN}") from None
    if not isinstance(root, dict):
        raise MissionFileError(f"{source}: not a plan (a JSON object is expected): {_SAVE_AS_PLAN}")
    if root.get("fileType") != "Plan":
        raise MissionFileError(
            f"{source}: fileType is {show(root.get('fileType'))}, not 'Plan': {_SAVE_AS_PLAN}"
        )
    mission = root.get("mission")
    if not isinstance(mission, dict):
        raise MissionFileError(f"{source}: the plan has no mission section: {_SAVE_AS_PLAN}")
    version = mission.get("version")
    if not _is_int(version) or version != MISSION_VERSION:
        raise MissionFileError(
            f"{source}: mission version {show(version)} is not supported (only "
            f"{MISSION_VERSION}): open it in a current QGroundControl and save it again"
        )
    firmware_type = mission.get("firmwareType")
    firmware = FIRMWARE_OF.get(firmware_type) if _is_int(firmware_type) else None
    if firmware is None:
        raise MissionFileError(
            f"{source}: firmwareType {show(firmware_type)} is not supported: set the vehicle "
            f"firmware to ArduPilot ({AUTOPILOT_OF['ardupilot']}) or PX4 "
            f"({AUTOPILOT_OF['px4']}) in QGroundControl and save the plan again"
        )
    home = _home(mission.get("plannedHomePosition"), source)
    raw_items = mission.get("items")
    if not isinstance(raw_items, list):
        raise MissionFileError(f"{source}: mission.items is missing or not a list: {_SAVE_AS_PLAN}")
    too_many = count_problem(len(raw_items), firmware)
    if too_many is not None:
        raise MissionFileError(f"{source}: {too_many}")
    items = tuple(
        _read_item(raw, index, source, home, firmware) for index, raw in enumerate(raw_items)
    )
    return assemble_mission(
        source,
        home=home,
        items=items,
        firmware=firmware,
        cruise_speed_m_s=_speed(mission, "cruiseSpeed", source),
        hover_speed_m_s=_speed(mission, "hoverSpeed", source),
    )


def read_replay_check(text: str, source: str) -> ReplayCheck | None:
    """What a plan says its replay must check (its ``urptGcs`` key), or None without one.

    Raises
    ------
    MissionFileError
        If the key is there but not usable; the message names the file and the fix.
    """
    try:
        root = json.loads(text.removeprefix("\ufeff"), parse_constant=_reject_constant)
    except (ValueError, RecursionError):
        return None  # read_plan says what is wrong with the file itself
    if not isinstance(root, dict) or CHECK_KEY not in root:
        return None
    value = root[CHECK_KEY]
    fix = f"remove the {CHECK_KEY} key (replay then uses its flags) or plan again"
    where = f"{source}: {CHECK_KEY}"
    if not isinstance(value, dict) or value.get("version") != CHECK_VERSION:
        raise MissionFileError(f"{where} is not version {CHECK_VERSION} of urpt-gcs's: {fix}")
    raw_targets = value.get("targets")
    numbers = _numbers([value.get("fovDeg"), value.get("minClearanceM")])
    sortie, sorties = value.get("sortie"), value.get("sorties")
    if (
        numbers is None
        or None in numbers
        or not isinstance(raw_targets, list)
        or not (_is_int(sortie) and _is_int(sorties))
    ):
        raise MissionFileError(f"{where} lacks fovDeg, minClearanceM, sortie or targets: {fix}")
    targets = []
    for index, raw in enumerate(raw_targets):
        place = _numbers([raw.get("lat"), raw.get("lon")]) if isinstance(raw, dict) else None
        name = raw.get("name") if isinstance(raw, dict) else None
        if place is None or None in place or not isinstance(name, str):
            raise MissionFileError(f"{where}: target {index} is not a name, lat and lon: {fix}")
        lat, lon = (n for n in place if n is not None)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise MissionFileError(f"{where}: target {name!r} is not a WGS84 position: {fix}")
        targets.append(Target(name, lat, lon))
    fov, clearance = (n for n in numbers if n is not None)
    try:
        frame, gsd = _frame(value.get("frame"), where, fix)
        return ReplayCheck(fov, clearance, tuple(targets), sortie, sorties, frame, gsd)
    except SettingsError as exc:
        raise MissionFileError(f"{where}: {exc}: {fix}") from None


def _frame(value: object, where: str, fix: str) -> tuple[Frame | None, float | None]:
    """The frame camera of a plan's check (None, None for the cone)."""
    if value is None:
        return None, None
    bad = MissionFileError(f"{where}: frame is not sensorMm, focalMm, imagePx and gsdCm: {fix}")
    if not isinstance(value, dict):
        raise bad
    sensor = _numbers(value.get("sensorMm"))
    image = _numbers(value.get("imagePx"))
    focal = _numbers([value.get("focalMm")])
    gsd = value.get("gsdCm")
    if (
        sensor is None
        or image is None
        or focal is None
        or len(sensor) != 2
        or len(image) != 2
        or None in (*sensor, *image, *focal)
        or not all(float(p or 0).is_integer() for p in image)
        or not (gsd is None or (isinstance(gsd, int | float) and not isinstance(gsd, bool)))
    ):
        raise bad
    w, h = (float(v or 0.0) for v in sensor)
    iw, ih = (int(v or 0) for v in image)
    frame = Frame(w, h, float(focal[0] or 0.0), iw, ih)
    return frame, None if gsd is None else float(gsd)


def _reject_constant(name: str) -> float:
    # Python's json reads NaN/Infinity; QGroundControl and MAVSDK do not.
    raise ValueError(f"{name} is not a JSON value")


def _home(value: object, source: str) -> GeoPoint:
    numbers = _numbers(value)
    if numbers is None or len(numbers) != 3 or any(n is None for n in numbers):
        raise MissionFileError(
            f"{source}: mission.plannedHomePosition is missing or not [latitude, longitude, "
            f"altitude]: set the planned home in QGroundControl and save the plan again"
        )
    lat, lon, alt = (n for n in numbers if n is not None)
    try:
        return GeoPoint(lat, lon, alt)
    except SettingsError as exc:
        raise MissionFileError(
            f"{source}: mission.plannedHomePosition is not usable ({exc}): set the planned home "
            f"in QGroundControl and save the plan again"
        ) from None


def _speed(mission: dict[str, Any], key: str, source: str) -> float:
    value = mission.get(key)
    numbers = _numbers([value])
    if numbers is not None and numbers[0] is not None and numbers[0] > 0.0:
        return numbers[0]
    raise MissionFileError(
        f"{source}: mission.{key} {show(value)} is not a positive speed in m/s: set the "
        f"vehicle speeds in QGroundControl and save the plan again"
    )


def _read_item(
    raw: object, index: int, source: str, home: GeoPoint, firmware: Firmware
) -> MissionItem:
    where = f"{source}: mission item at index {index}"
    if not isinstance(raw, dict):
        raise MissionFileError(f"{where} is not a JSON object: {_SAVE_AS_PLAN}")
    kind = raw.get("type")
    if kind != "SimpleItem":
        detail = f" ({show(raw.get('complexItemType'))})" if "complexItemType" in raw else ""
        raise MissionFileError(
            f"{source}: unsupported item type {show(kind)}{detail} at index {index}: flatten it "
            f"in QGroundControl into simple waypoints and save the plan again"
        )
    command = raw.get("command")
    frame = raw.get("frame")
    if not (_is_int(command) and 0 <= command <= 65535):
        raise MissionFileError(
            f"{where}: command {show(command)} is not a MAV_CMD number: {_FIX_ITEM}"
        )
    if not (_is_int(frame) and 0 <= frame <= 255):
        raise MissionFileError(
            f"{where}: frame {show(frame)} is not a MAV_FRAME number: {_FIX_ITEM}"
        )
    params = _numbers(raw.get("params"))
    if params is None or len(params) != 7:
        raise MissionFileError(
            f"{where}: params must be a list of 7 numbers (null for unset), got "
            f"{show(raw.get('params'))}: {_SAVE_AS_PLAN}"
        )
    autocontinue = raw.get("autoContinue")
    if not isinstance(autocontinue, bool):
        raise MissionFileError(
            f"{where}: autoContinue {show(autocontinue)} is not true or false: {_FIX_ITEM}"
        )
    item = make_item(
        where,
        command=command,
        frame=frame,
        params=[math.nan if p is None else p for p in params],
        autocontinue=autocontinue,
    )
    check_item(where, item, home, firmware)
    return item


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)


def _numbers(value: object) -> list[float | None] | None:
    """A JSON list of finite numbers or nulls, else None."""
    if not isinstance(value, list):
        return None
    numbers: list[float | None] = []
    for element in value:
        if element is None:
            numbers.append(None)
            continue
        if not isinstance(element, (int, float)) or isinstance(element, bool):
            return None
        try:
            number = float(element)
        except OverflowError:
            return None
        if not math.isfinite(number):
            return None
        numbers.append(number)
    return numbers


# --- shared by the .plan and .waypoints readers -------------------------------------------


def show(value: object, limit: int = 40) -> str:
    """A short one-line rendering of a value read from a file, for error messages."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def make_item(
    where: str, *, command: int, frame: int, params: Sequence[float], autocontinue: bool
) -> MissionItem:
    """Build a :class:`MissionItem`, reporting a bad one as a :class:`MissionFileError`."""
    p = tuple(params)
    if len(p) != 7:
        raise MissionFileError(f"{where}: {len(p)} params, expected 7")
    try:
        return MissionItem(
            command=command,
            frame=frame,
            params=(p[0], p[1], p[2], p[3], p[4], p[5], p[6]),
            autocontinue=autocontinue,
        )
    except SettingsError:
        raise MissionFileError(
            f"{where}: params 5-7 (x, y, z) must be numbers, not null or NaN: give that item "
            f"a position and altitude"
        ) from None


def check_item(where: str, item: MissionItem, home: GeoPoint, firmware: Firmware) -> None:
    """Refuse an item no vehicle should be given (see
    :func:`urpt_gcs.flight.mission.item_problem`)."""
    problem = item_problem(item, home, firmware)
    if problem is not None:
        raise MissionFileError(f"{where} ({command_name(item.command)}): {problem}")


def assemble_mission(
    source: str,
    *,
    home: GeoPoint,
    items: tuple[MissionItem, ...],
    firmware: Firmware,
    cruise_speed_m_s: float,
    hover_speed_m_s: float,
) -> Mission:
    """Build the :class:`Mission` read from ``source``, with its flight altitude.

    The altitude is that of the first takeoff relative to home, or else the highest
    altitude of an item relative to home.
    """
    if not items:
        raise MissionFileError(f"{source}: the mission has no items: add waypoints and save again")
    takeoffs = [
        item.z
        for item in items
        if item.command == mavlink.MAV_CMD_NAV_TAKEOFF and item.frame in RELATIVE_FRAMES
    ]
    relative = [item.z for item in items if item.frame in RELATIVE_FRAMES]
    if takeoffs:
        altitude_rel_m = takeoffs[0]
    elif relative:
        altitude_rel_m = max(relative)
    else:
        raise MissionFileError(
            f"{source}: no item has an altitude relative to home (frame 3): plan the mission "
            f"with relative altitudes"
        )
    if not (math.isfinite(altitude_rel_m) and altitude_rel_m > 0.0):
        raise MissionFileError(
            f"{source}: flight altitude {altitude_rel_m} m above home is not positive: fix the "
            f"takeoff or waypoint altitudes"
        )
    try:
        return Mission(
            home=home,
            items=items,
            firmware=firmware,
            altitude_rel_m=altitude_rel_m,
            cruise_speed_m_s=cruise_speed_m_s,
            hover_speed_m_s=hover_speed_m_s,
        )
    except SettingsError as exc:
        raise MissionFileError(f"{source}: {exc}") from None
