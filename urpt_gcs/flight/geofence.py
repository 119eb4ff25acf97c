"""The geofence as it travels to the vehicle: a fence mission, and the check of its read-back.

A ``.plan`` carries its fence in ``geoFence`` (polygons of ``[lat, lon]`` vertices, circles
of a centre and a radius, each an inclusion or an exclusion zone). On the wire it is a mission
of type MAV_MISSION_TYPE_FENCE, as QGroundControl and MAVSDK's plan importer send it: one
NAV_FENCE_POLYGON_VERTEX_* item per vertex with the polygon's vertex count in param1, one
NAV_FENCE_CIRCLE_* item per circle with its radius in param1, frame GLOBAL, no altitude.

Nothing here is firmware-specific except :func:`compare_fence`'s allowance for what a
firmware changes on read-back (ArduPilot was seen to return ``autocontinue`` 0); the upload
itself is :func:`urpt_gcs.vehicle.link.upload_fence_verified`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import MissionFileError, SettingsError
from urpt_gcs.flight.mission import Firmware, GeoPoint, command_name
from urpt_gcs.flight.wire import Comparison, WireItem

__all__ = [
    "CIRCLE_COMMANDS",
    "FENCE_TYPE",
    "POLYGON_COMMANDS",
    "RADIUS_TOLERANCE_M",
    "FenceCircle",
    "FencePolygon",
    "Geofence",
    "compare_fence",
    "fence_items",
    "read_plan_geofence",
]

FENCE_TYPE = mavlink.MAV_MISSION_TYPE_FENCE
POLYGON_COMMANDS = {
    True: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    False: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
}
CIRCLE_COMMANDS = {
    True: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    False: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
}
# A radius comes back as a float32 param; a metre is far below anything that matters.
RADIUS_TOLERANCE_M = 0.01
_FIX = "save the plan from QGroundControl again, or plan it again with urpt-gcs"


@dataclass(frozen=True, slots=True)
class FencePolygon:
    """A polygon zone: vertices (latitude, longitude) in degrees, in order."""

    vertices: tuple[tuple[float, float], ...]
    inclusion: bool = True

    def __post_init__(self) -> None:
        if len(self.vertices) < 3:
            raise SettingsError(
                f"a fence polygon has {len(self.vertices)} vertices; give at least 3"
            )
        for lat, lon in self.vertices:
            GeoPoint(lat, lon, 0.0)


@dataclass(frozen=True, slots=True)
class FenceCircle:
    """A circle zone: centre (latitude, longitude) in degrees and radius in metres."""

    lat_deg: float
    lon_deg: float
    radius_m: float
    inclusion: bool = True

    def __post_init__(self) -> None:
        GeoPoint(self.lat_deg, self.lon_deg, 0.0)
        if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
            raise SettingsError(f"fence circle radius {self.radius_m} m must be positive")


@dataclass(frozen=True, slots=True)
class Geofence:
    """The zones of a plan's fence; empty when the plan has none."""

    polygons: tuple[FencePolygon, ...] = ()
    circles: tuple[FenceCircle, ...] = ()

    @property
    def empty(self) -> bool:
        """True when there is nothing to upload."""
        return not self.polygons and not self.circles

    @classmethod
    def inclusion(cls, vertices: Sequence[tuple[float, float]]) -> Geofence:
        """One inclusion polygon (what ``urpt-gcs plan`` writes), or no fence if empty."""
        if not vertices:
            return cls()
        return cls(polygons=(FencePolygon(tuple((float(a), float(b)) for a, b in vertices)),))

    def describe(self) -> str:
        """ "1 inclusion polygon (23 vertices)", for the operator."""
        parts = [
            f"{'inclusion' if p.inclusion else 'exclusion'} polygon ({len(p.vertices)} vertices)"
            for p in self.polygons
        ]
        parts += [
            f"{'inclusion' if c.inclusion else 'exclusion'} circle ({c.radius_m:g} m)"
            for c in self.circles
        ]
        return ", ".join(parts) or "no fence"


def fence_items(fence: Geofence) -> tuple[WireItem, ...]:
    """The fence as MISSION_ITEM_INTs of mission type FENCE, seq from 0."""
    rows: list[tuple[int, float, float, float]] = []
    for polygon in fence.polygons:
        command = POLYGON_COMMANDS[polygon.inclusion]
        rows += [(command, float(len(polygon.vertices)), lat, lon) for lat, lon in polygon.vertices]
    for circle in fence.circles:
        rows.append(
            (CIRCLE_COMMANDS[circle.inclusion], circle.radius_m, circle.lat_deg, circle.lon_deg)
        )
    return tuple(
        WireItem(
            seq=seq,
            frame=mavlink.MAV_FRAME_GLOBAL,
            command=command,
            current=0,
            autocontinue=1,
            param1=param1,
            param2=0.0,
            param3=0.0,
            param4=0.0,
            x=round(lat * 1e7),
            y=round(lon * 1e7),
            z=0.0,
            mission_type=FENCE_TYPE,
        )
        for seq, (command, param1, lat, lon) in enumerate(rows)
    )


def compare_fence(
    sent: Sequence[WireItem], got: Sequence[WireItem], firmware: Firmware
) -> Comparison:
    """Compare a downloaded fence with the uploaded one.

    Command, vertex count (or radius) and position must match exactly (position to 1e-7
    degrees). Frame, altitude, ``current`` and ``autocontinue`` mean nothing for a fence
    item and are not compared; ArduPilot returns ``autocontinue`` 0 and frame GLOBAL.
    ``firmware`` is for the allowances a firmware needs beyond those (none yet).
    """
    del firmware  # the same rules hold for ArduPilot; PX4 may need its own
    if len(got) != len(sent):
        return Comparison((f"the vehicle holds {len(got)} fence items, {len(sent)} were sent",), ())
    mismatches: list[str] = []
    for a, b in zip(sent, got, strict=True):
        where = f"fence seq {a.seq} ({command_name(a.command)})"
        if b.command != a.command:
            mismatches.append(f"{where}: read back as {command_name(b.command)}")
            continue
        circle = a.command in CIRCLE_COMMANDS.values()
        if circle and abs(a.param1 - b.param1) > RADIUS_TOLERANCE_M:
            mismatches.append(f"{where}: radius sent {a.param1:g} m, read back {b.param1:g} m")
        elif not circle and round(a.param1) != round(b.param1):
            mismatches.append(f"{where}: vertex count sent {a.param1:g}, read back {b.param1:g}")
        if (a.x, a.y) != (b.x, b.y):
            mismatches.append(f"{where}: position sent {a.x},{a.y}, read back {b.x},{b.y}")
    return Comparison(tuple(mismatches), ())


def read_plan_geofence(text: str, source: str) -> Geofence:
    """The ``geoFence`` of a QGroundControl ``.plan`` (JSON text); empty if it has none.

    Raises
    ------
    MissionFileError
        If the section is there but malformed; the message names the file and the zone.
    """
    try:
        root = json.loads(text.removeprefix("\ufeff"))
    except (ValueError, RecursionError) as exc:
        raise MissionFileError(f"{source}: not valid JSON ({exc}): {_FIX}") from None
    section = root.get("geoFence") if isinstance(root, dict) else None
    if section is None:
        return Geofence()
    if not isinstance(section, dict):
        raise MissionFileError(f"{source}: geoFence is not a JSON object: {_FIX}")
    polygons = tuple(
        _polygon(raw, index, source) for index, raw in enumerate(_list(section, "polygons", source))
    )
    circles = tuple(
        _circle(raw, index, source) for index, raw in enumerate(_list(section, "circles", source))
    )
    return Geofence(polygons, circles)


def _list(section: dict[str, object], key: str, source: str) -> list[object]:
    value = section.get(key, [])
    if not isinstance(value, list):
        raise MissionFileError(f"{source}: geoFence.{key} is not a list: {_FIX}")
    return value


def _inclusion(raw: dict[str, object], where: str) -> bool:
    value = raw.get("inclusion", True)
    if not isinstance(value, bool):
        raise MissionFileError(f"{where}: inclusion {value!r} is not true or false: {_FIX}")
    return value


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _latlon(value: object) -> tuple[float, float] | None:
    if not isinstance(value, list) or len(value) != 2:
        return None
    lat, lon = _number(value[0]), _number(value[1])
    return None if lat is None or lon is None else (lat, lon)


def _polygon(raw: object, index: int, source: str) -> FencePolygon:
    where = f"{source}: geoFence polygon {index}"
    if not isinstance(raw, dict) or not isinstance(raw.get("polygon"), list):
        raise MissionFileError(f"{where} has no list of [lat, lon] vertices: {_FIX}")
    vertices = [_latlon(v) for v in raw["polygon"]]
    if any(v is None for v in vertices):
        raise MissionFileError(f"{where}: a vertex is not [latitude, longitude]: {_FIX}")
    try:
        return FencePolygon(tuple(v for v in vertices if v is not None), _inclusion(raw, where))
    except SettingsError as exc:
        raise MissionFileError(f"{where}: {exc}: {_FIX}") from None


def _circle(raw: object, index: int, source: str) -> FenceCircle:
    where = f"{source}: geoFence circle {index}"
    body = raw.get("circle") if isinstance(raw, dict) else None
    centre = _latlon(body.get("center")) if isinstance(body, dict) else None
    radius = _number(body.get("radius")) if isinstance(body, dict) else None
    if not isinstance(raw, dict) or centre is None or radius is None:
        raise MissionFileError(f"{where} is not {{circle: {{center: [lat, lon], radius}}}}: {_FIX}")
    try:
        return FenceCircle(centre[0], centre[1], radius, _inclusion(raw, where))
    except SettingsError as exc:
        raise MissionFileError(f"{where}: {exc}: {_FIX}") from None
