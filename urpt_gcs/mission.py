"""Mission: the planned tour as MAVLink mission items.

The mission flies at one altitude relative to home (frame GLOBAL_RELATIVE_ALT), so the DEM's
vertical datum cancels out: ``relative = H - ground(home)``. Home itself is kept apart from the
items; :meth:`Mission.upload_items` puts the placeholder home at seq 0 where the autopilot
(ArduPilot) expects one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import SettingsError

Firmware = Literal["ardupilot", "px4"]
FIRMWARES: tuple[Firmware, ...] = ("ardupilot", "px4")

# Frames whose x/y are latitude/longitude (sent as degrees * 1e7 in MISSION_ITEM_INT).
GLOBAL_FRAMES = frozenset(
    {
        mavlink.MAV_FRAME_GLOBAL,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mavlink.MAV_FRAME_GLOBAL_INT,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
        mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
    }
)

# QGroundControl firmwareType / vehicleType values (MAV_AUTOPILOT / MAV_TYPE).
AUTOPILOT_OF: dict[Firmware, int] = {
    "ardupilot": mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
    "px4": mavlink.MAV_AUTOPILOT_PX4,
}


def round_e7(degrees: float) -> float:
    """Round an angle in degrees to the 1e-7 degree grid MAVLink stores."""
    return round(degrees * 1e7) / 1e7


@dataclass(frozen=True, slots=True)
class GeoPoint:
    """A WGS84 position with an altitude above mean sea level (the DEM's vertical datum)."""

    lat_deg: float
    lon_deg: float
    amsl_m: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat_deg) and -90.0 <= self.lat_deg <= 90.0):
            raise SettingsError(f"latitude {self.lat_deg} is not in [-90, 90]")
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise SettingsError(f"longitude {self.lon_deg} is not in [-180, 180]")
        if not math.isfinite(self.amsl_m):
            raise SettingsError(f"altitude {self.amsl_m} is not a finite number")


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One MAVLink mission item in the QGroundControl parameter layout.

    ``params`` are param1..param7. For a global frame param5/param6 are latitude/longitude in
    degrees and param7 the altitude in metres; otherwise they are the command's raw params.
    NaN means "unset" and is only used where the firmware accepts it.
    """

    command: int
    frame: int
    params: tuple[float, float, float, float, float, float, float]
    autocontinue: bool = True

    def __post_init__(self) -> None:
        if len(self.params) != 7:
            raise SettingsError(f"mission item needs 7 params, got {len(self.params)}")
        if any(math.isnan(p) for p in self.params[4:]):
            raise SettingsError("mission item params 5-7 may not be NaN")

    @property
    def is_global(self) -> bool:
        return self.frame in GLOBAL_FRAMES

    @property
    def x_int(self) -> int:
        """param5 as MISSION_ITEM_INT sends it (degrees * 1e7 for a global frame)."""
        return round(self.params[4] * 1e7) if self.is_global else round(self.params[4])

    @property
    def y_int(self) -> int:
        """param6 as MISSION_ITEM_INT sends it (degrees * 1e7 for a global frame)."""
        return round(self.params[5] * 1e7) if self.is_global else round(self.params[5])

    @property
    def z(self) -> float:
        return self.params[6]


@dataclass(frozen=True, slots=True)
class Mission:
    """A mission ready to write or upload.

    ``items`` exclude home. ``home`` is the launch point with its ground elevation (AMSL, in
    the DEM's datum); it is written as ``plannedHomePosition`` and line 0 of a ``.waypoints``
    file, and sent as the placeholder at seq 0 to ArduPilot.
    """

    home: GeoPoint
    items: tuple[MissionItem, ...]
    firmware: Firmware
    altitude_rel_m: float
    cruise_speed_m_s: float
    hover_speed_m_s: float

    def __post_init__(self) -> None:
        if self.firmware not in FIRMWARES:
            raise SettingsError(f"firmware {self.firmware!r} is not one of {', '.join(FIRMWARES)}")
        if not self.items:
            raise SettingsError("a mission needs at least one item")

    @property
    def home_item(self) -> MissionItem:
        """Home as ArduPilot stores it at seq 0: NAV_WAYPOINT, frame GLOBAL, AMSL altitude."""
        return MissionItem(
            command=mavlink.MAV_CMD_NAV_WAYPOINT,
            frame=mavlink.MAV_FRAME_GLOBAL,
            params=(0.0, 0.0, 0.0, 0.0, self.home.lat_deg, self.home.lon_deg, self.home.amsl_m),
        )

    def upload_items(self) -> tuple[MissionItem, ...]:
        """Items in upload order: for ArduPilot the home placeholder first (seq 0)."""
        if self.firmware == "ardupilot":
            return (self.home_item, *self.items)
        return self.items


@dataclass(frozen=True, slots=True)
class MissionSettings:
    """How the tour is flown and photographed."""

    firmware: Firmware = "ardupilot"
    hold_s: float = 2.0
    cruise_speed_m_s: float = 8.0
    hover_speed_m_s: float = 5.0

    def __post_init__(self) -> None:
        if self.firmware not in FIRMWARES:
            raise SettingsError(
                f"--firmware {self.firmware!r} is not supported; use one of {', '.join(FIRMWARES)}"
            )
        if not (math.isfinite(self.hold_s) and 0.0 <= self.hold_s <= 3600.0):
            raise SettingsError(f"--hold {self.hold_s} s is out of range; use 0 to 3600 seconds")
        for name, value in (
            ("--speed", self.cruise_speed_m_s),
            ("hover speed", self.hover_speed_m_s),
        ):
            if not (math.isfinite(value) and 0.1 <= value <= 50.0):
                raise SettingsError(f"{name} {value} m/s is out of range; use 0.1 to 50 m/s")


def waypoint_positions(mission: Mission) -> list[tuple[float, float]]:
    """(latitude, longitude) of the mission's NAV_WAYPOINT items, in flight order."""
    return [
        (item.params[4], item.params[5])
        for item in mission.items
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT
    ]


def _item(command: int, frame: int, *params: float) -> MissionItem:
    padded = tuple(float(p) for p in params) + (0.0,) * (7 - len(params))
    return MissionItem(command=command, frame=frame, params=padded)  # type: ignore[arg-type]


def build_mission(
    home: GeoPoint,
    waypoints: Sequence[tuple[float, float]],
    altitude_rel_m: float,
    settings: MissionSettings,
) -> Mission:
    """Build the mission for a tour.

    Parameters
    ----------
    home
        Launch point; its ``amsl_m`` is the ground elevation there.
    waypoints
        Viewpoints in flight order as (latitude, longitude) in degrees.
    altitude_rel_m
        Flight-plane altitude above home.
    settings
        Firmware, hold time and speeds.
    """
    if not waypoints:
        raise SettingsError("a mission needs at least one waypoint")
    if not (math.isfinite(altitude_rel_m) and altitude_rel_m > 0.0):
        raise SettingsError(f"flight altitude {altitude_rel_m} m above home must be positive")
    home = GeoPoint(round_e7(home.lat_deg), round_e7(home.lon_deg), home.amsl_m)
    rel = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    cmd_frame = mavlink.MAV_FRAME_MISSION
    items: list[MissionItem] = [
        _item(
            mavlink.MAV_CMD_NAV_TAKEOFF, rel, 0, 0, 0, 0, home.lat_deg, home.lon_deg, altitude_rel_m
        ),
    ]
    if settings.firmware == "ardupilot":
        # Pitch -90 (nadir), roll 0, yaw 0; param7 the mount mode.
        items.append(
            _item(
                mavlink.MAV_CMD_DO_MOUNT_CONTROL,
                cmd_frame,
                -90,
                0,
                0,
                0,
                0,
                0,
                mavlink.MAV_MOUNT_MODE_MAVLINK_TARGETING,
            )
        )
    else:
        # PX4 drives gimbals through the gimbal manager: pitch -90, yaw 0, rates NaN.
        items.append(
            _item(
                mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                cmd_frame,
                -90,
                0,
                math.nan,
                math.nan,
                0,
                0,
                0,
            )
        )
    for lat, lon in waypoints:
        yaw = 0.0 if settings.firmware == "ardupilot" else math.nan
        items.append(
            _item(
                mavlink.MAV_CMD_NAV_WAYPOINT,
                rel,
                settings.hold_s,
                0,
                0,
                yaw,
                round_e7(lat),
                round_e7(lon),
                altitude_rel_m,
            )
        )
        if settings.firmware == "ardupilot":
            # param5 = 1: take one photo now.
            items.append(_item(mavlink.MAV_CMD_DO_DIGICAM_CONTROL, cmd_frame, 0, 0, 0, 0, 1))
        else:
            # Camera id 0 (all), interval 0, one image.
            items.append(_item(mavlink.MAV_CMD_IMAGE_START_CAPTURE, cmd_frame, 0, 0, 1))
    items.append(_item(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, cmd_frame))
    return Mission(
        home=home,
        items=tuple(items),
        firmware=settings.firmware,
        altitude_rel_m=altitude_rel_m,
        cruise_speed_m_s=settings.cruise_speed_m_s,
        hover_speed_m_s=settings.hover_speed_m_s,
    )
