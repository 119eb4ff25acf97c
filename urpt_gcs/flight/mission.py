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

__all__ = [
    "AUTOPILOT_OF",
    "DEFAULT_SPEED_M_S",
    "FIRMWARES",
    "FLOAT32_MAX",
    "GLOBAL_FRAMES",
    "LOCATION_ALT_MAX_M",
    "LOWEST_AMSL_M",
    "MAX_MISSION_ITEMS",
    "PHOTO_COMMANDS",
    "RELATIVE_ALT_FRAMES",
    "TERRAIN_ALT_FRAMES",
    "UINT16_SECONDS_MAX",
    "Firmware",
    "GeoPoint",
    "Mission",
    "MissionItem",
    "MissionSettings",
    "below_home",
    "build_mission",
    "command_name",
    "commanded_speed",
    "count_problem",
    "item_problem",
    "photo_flags",
    "photo_headings",
    "photo_positions",
    "round_e7",
    "stop_heights_rel",
    "upload_problem",
    "waypoint_positions",
]

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


# The one default cruise speed: the API's, the CLI's --speed, and a .waypoints file's without
# a DO_CHANGE_SPEED.
DEFAULT_SPEED_M_S = 5.0


@dataclass(frozen=True, slots=True)
class MissionSettings:
    """How the tour is flown and photographed."""

    firmware: Firmware = "ardupilot"
    hold_s: float = 2.0
    cruise_speed_m_s: float = DEFAULT_SPEED_M_S
    hover_speed_m_s: float = DEFAULT_SPEED_M_S

    def __post_init__(self) -> None:
        # The messages name the settings; the CLI shows their flags (SettingsError.naming).
        if self.firmware not in FIRMWARES:
            raise SettingsError.about(
                "{firmware} {value!r} is not supported; use one of {known}",
                value=self.firmware,
                known=", ".join(FIRMWARES),
            )
        if not (math.isfinite(self.hold_s) and 0.0 <= self.hold_s <= 3600.0):
            raise SettingsError.about(
                "{hold_s} {value} s is out of range; use 0 to 3600 seconds", value=self.hold_s
            )
        for name, value in (
            ("cruise_speed_m_s", self.cruise_speed_m_s),
            ("hover_speed_m_s", self.hover_speed_m_s),
        ):
            if not (math.isfinite(value) and 0.1 <= value <= 50.0):
                raise SettingsError.about(
                    "{" + name + "} {value} m/s is out of range; use 0.1 to 50 m/s", value=value
                )


def commanded_speed(items: Sequence[MissionItem]) -> float | None:
    """The horizontal speed the first DO_CHANGE_SPEED of ``items`` sets, or None.

    Speed types AIRSPEED and GROUNDSPEED set the horizontal speed on a multicopter (ArduCopter
    ``ModeAuto::do_change_speed``; PX4 uses param2 whatever the type); a speed of 0 or less
    changes nothing.
    """
    for item in items:
        horizontal = item.params[0] in (mavlink.SPEED_TYPE_AIRSPEED, mavlink.SPEED_TYPE_GROUNDSPEED)
        if item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED and horizontal and item.params[1] > 0:
            return item.params[1]
    return None


def waypoint_positions(mission: Mission) -> list[tuple[float, float]]:
    """(latitude, longitude) of the mission's NAV_WAYPOINT items, in flight order: its stops
    and the waypoints without a photo that follow the terrain between them."""
    return [
        (item.params[4], item.params[5])
        for item in mission.items
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT
    ]


# The items that take a photo at the waypoint before them.
PHOTO_COMMANDS = frozenset(
    {mavlink.MAV_CMD_DO_DIGICAM_CONTROL, mavlink.MAV_CMD_IMAGE_START_CAPTURE}
)


def photo_flags(mission: Mission) -> list[bool]:
    """Per NAV_WAYPOINT, in flight order, whether a photo is taken there (a photo item follows
    it before the next navigation item)."""
    flags: list[bool] = []
    for item in mission.items:
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT:
            flags.append(False)
        elif item.command in PHOTO_COMMANDS and flags:
            flags[-1] = True
    return flags


def stop_heights_rel(mission: Mission) -> list[float]:
    """Each photo waypoint's height above home, in flight order."""
    heights = [
        item.params[6] for item in mission.items if item.command == mavlink.MAV_CMD_NAV_WAYPOINT
    ]
    return [h for h, photo in zip(heights, photo_flags(mission), strict=True) if photo]


def photo_positions(mission: Mission) -> list[tuple[float, float]]:
    """(latitude, longitude) of the waypoints where a photo is taken, in flight order."""
    return [
        p
        for p, photo in zip(waypoint_positions(mission), photo_flags(mission), strict=True)
        if photo
    ]


def photo_headings(mission: Mission) -> list[float] | None:
    """The heading (true north, degrees) the mission turns the vehicle to for each photo
    waypoint, in flight order: the CONDITION_YAW before it (ArduPilot) or its own yaw
    (PX4). None when the mission turns it for none of them (a cone camera's mission)."""
    headings: list[float] = []
    pending = math.nan
    for item in mission.items:
        if item.command == mavlink.MAV_CMD_CONDITION_YAW and item.params[3] == 0:
            pending = item.params[0] % 360.0
        elif item.command == mavlink.MAV_CMD_NAV_WAYPOINT:
            yaw = item.params[3] if mission.firmware == "px4" else math.nan
            headings.append(yaw % 360.0 if math.isfinite(yaw) else pending)
            pending = math.nan
    headings = [h for h, photo in zip(headings, photo_flags(mission), strict=True) if photo]
    if all(math.isnan(h) for h in headings):
        return None
    return headings


def _item(command: int, frame: int, *params: float) -> MissionItem:
    padded = tuple(float(p) for p in params) + (0.0,) * (7 - len(params))
    return MissionItem(command=command, frame=frame, params=padded)  # type: ignore[arg-type]


def build_mission(
    home: GeoPoint,
    waypoints: Sequence[tuple[float, float]],
    altitude_rel_m: float,
    settings: MissionSettings,
    headings_deg: Sequence[float] | None = None,
    heights_rel_m: Sequence[float] | None = None,
    photos: Sequence[bool] | None = None,
) -> Mission:
    """Build the mission for a tour.

    With ``headings_deg`` (true north, clockwise, one per waypoint) the vehicle is turned
    before each photo, as each firmware honours it. ArduCopter ignores NAV_WAYPOINT's yaw
    (``ModeAuto::do_nav_wp``) and resets the yaw to WP_YAW_BEHAVIOR's when a waypoint starts
    (``wp_start``); a CONDITION_YAW right before the waypoint runs once that waypoint has
    started, holds the yaw fixed (``verify_yaw`` retakes it each cycle) until it is reached and
    keeps it through the hold, and the photo after the waypoint fires before the next one
    starts. PX4 turns to a NAV_WAYPOINT's param4 at the waypoint and counts it reached only
    within MIS_YAW_ERR of it.

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
    headings_deg
        The vehicle's heading for each photo; None leaves the yaw to the firmware.
    heights_rel_m
        Each waypoint's own height above home (a flight that follows the terrain); None:
        every waypoint at ``altitude_rel_m``, which is then also the take-off's height.
    photos
        Which waypoints take a photo (and hold); None: all of them. A waypoint without one
        only shapes the path (it follows the terrain between two stops).
    """
    if not waypoints:
        raise SettingsError("a mission needs at least one waypoint")
    photo_count = len(waypoints) if photos is None else sum(bool(p) for p in photos)
    if headings_deg is not None and len(headings_deg) != photo_count:
        raise SettingsError(
            f"{len(headings_deg)} headings for {photo_count} photos: give one per photo"
        )
    if not (math.isfinite(altitude_rel_m) and altitude_rel_m > 0.0):
        raise SettingsError(f"flight altitude {altitude_rel_m} m above home must be positive")
    heights = [altitude_rel_m] * len(waypoints) if heights_rel_m is None else list(heights_rel_m)
    shoots = [True] * len(waypoints) if photos is None else list(photos)
    if len(heights) != len(waypoints) or len(shoots) != len(waypoints):
        raise SettingsError("give one height and one photo flag per waypoint")
    if not all(math.isfinite(h) for h in heights):
        raise SettingsError("every waypoint's height above home must be a number")
    home = GeoPoint(round_e7(home.lat_deg), round_e7(home.lon_deg), home.amsl_m)
    rel = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    cmd_frame = mavlink.MAV_FRAME_MISSION
    items: list[MissionItem] = [
        _item(
            mavlink.MAV_CMD_NAV_TAKEOFF, rel, 0, 0, 0, 0, home.lat_deg, home.lon_deg, altitude_rel_m
        ),
        # Both firmwares run a "do" item once the navigation item before it completes: the
        # speed applies from the first leg on, when the climb is done. Ground speed; throttle
        # -1 is "no change" (ArduCopter ignores it, PX4 reads it only without a speed).
        _item(
            mavlink.MAV_CMD_DO_CHANGE_SPEED,
            cmd_frame,
            mavlink.SPEED_TYPE_GROUNDSPEED,
            settings.cruise_speed_m_s,
            -1,
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
    photo = 0
    for k, (lat, lon) in enumerate(waypoints):
        if not shoots[k]:
            # Only shapes the path: no hold, no turn, no photo.
            yaw = 0.0 if settings.firmware == "ardupilot" else math.nan
            items.append(
                _item(
                    mavlink.MAV_CMD_NAV_WAYPOINT,
                    rel,
                    0,
                    0,
                    0,
                    yaw,
                    round_e7(lat),
                    round_e7(lon),
                    heights[k],
                )
            )
            continue
        yaw = 0.0 if settings.firmware == "ardupilot" else math.nan
        if headings_deg is not None:
            heading = float(headings_deg[photo]) % 360.0
            if settings.firmware == "ardupilot":
                # Absolute heading (param4 0), the default turn rate (0), the shorter way (0).
                items.append(_item(mavlink.MAV_CMD_CONDITION_YAW, cmd_frame, heading, 0, 0, 0))
            else:
                yaw = heading
        photo += 1
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
                heights[k],
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


# --- what a vehicle can be given -----------------------------------------------------------

# MISSION_COUNT.count and every item's seq are uint16: a longer mission wraps to a short one.
MAX_MISSION_ITEMS = 65_535
# Below the lowest dry land (the Dead Sea shore, about -430 m), with room for an ellipsoidal
# vertical datum: no multirotor flies there.
LOWEST_AMSL_M = -500.0
# ArduPilot keeps a location's altitude in 24 bits of centimetres (AP_Mission's PackedLocation)
# and refuses larger values (MAV_MISSION_INVALID_PARAM7).
LOCATION_ALT_MAX_M = 83_000.0
# ArduPilot keeps NAV_WAYPOINT's hold and NAV_LOITER_TIME's time as a uint16 of whole seconds:
# -5 becomes 65531 (AP_Mission::mavlink_int_to_mission_cmd).
UINT16_SECONDS_MAX = 65_535.0
# params 1-4 and z travel as float32; anything larger arrives as infinity.
FLOAT32_MAX = 3.4028234663852886e38
_INT32_MAX = 2**31 - 1

RELATIVE_ALT_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
TERRAIN_ALT_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}
)
# ArduPilot accepts NaN ("unset") in params 1-4 only as param4 (yaw) of these commands.
_AP_NAN_PARAM4 = frozenset(
    {mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND}
)


@dataclass(frozen=True, slots=True)
class _Range:
    """A param a command uses: its name, unit, valid interval, and whether NaN means unset."""

    name: str
    unit: str
    low: float
    high: float
    nan_ok: bool = False
    low_open: bool = False
    fix: str = ""


def _angle(name: str, nan_ok: bool = False) -> _Range:
    return _Range(name, "deg", -360.0, 360.0, nan_ok, fix=f"give a {name} of -360 to 360 degrees")


def _seconds(name: str) -> _Range:
    return _Range(name, "s", 0.0, UINT16_SECONDS_MAX, fix=f"give a {name} of 0 to 65535 seconds")


_YAW = _angle("yaw", nan_ok=True)
# The params each command uses (None: not used) and what they may hold (MAVLink's MAV_CMD
# definitions; the uint16 limits are ArduPilot's storage).
_PARAMS: dict[int, tuple[_Range | None, _Range | None, _Range | None, _Range | None]] = {
    mavlink.MAV_CMD_NAV_WAYPOINT: (
        _seconds("hold"),
        _Range("acceptance radius", "m", 0.0, FLOAT32_MAX, fix="give a radius of 0 m or more"),
        None,
        _YAW,
    ),
    mavlink.MAV_CMD_NAV_LOITER_TIME: (_seconds("loiter time"), None, None, _YAW),
    mavlink.MAV_CMD_NAV_LOITER_UNLIM: (None, None, None, _YAW),
    mavlink.MAV_CMD_NAV_TAKEOFF: (None, None, None, _YAW),
    mavlink.MAV_CMD_NAV_LAND: (None, None, None, _YAW),
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: (None, None, None, None),
    mavlink.MAV_CMD_CONDITION_DELAY: (_seconds("delay"), None, None, None),
    mavlink.MAV_CMD_CONDITION_YAW: (
        _Range("heading", "deg", 0.0, 360.0, fix="give a heading of 0 to 360 degrees"),
        _Range("turn rate", "deg/s", 0.0, 360.0, fix="give 0 (default) to 360 deg/s"),
        _Range("direction", "", -1.0, 1.0, fix="give -1 (ccw), 0 (shorter) or 1 (cw)"),
        _Range("relative", "", 0.0, 1.0, fix="give 0 (absolute) or 1 (relative)"),
    ),
    mavlink.MAV_CMD_DO_CHANGE_SPEED: (
        _Range("speed type", "", 0.0, 3.0, fix="give a speed type of 0 to 3 (SPEED_TYPE)"),
        _Range(
            "speed",
            "m/s",
            0.0,
            FLOAT32_MAX,
            low_open=True,
            fix="give a speed above 0 m/s, or remove the item",
        ),
        _Range("throttle", "%", -2.0, 100.0, fix="give 0 to 100 %, or -1 for no change"),
        None,
    ),
    mavlink.MAV_CMD_DO_MOUNT_CONTROL: (_angle("pitch"), _angle("roll"), _angle("yaw"), None),
    mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: (
        _Range("pitch", "deg", -180.0, 180.0, True, fix="give a pitch of -180 to 180 degrees"),
        _angle("yaw", nan_ok=True),
        None,
        None,
    ),
    mavlink.MAV_CMD_IMAGE_START_CAPTURE: (
        None,
        _Range("interval", "s", 0.0, FLOAT32_MAX, fix="give an interval of 0 s or more"),
        _Range("image count", "", 0.0, FLOAT32_MAX, fix="give 0 (until stopped) or more images"),
        None,
    ),
}


def item_problem(item: MissionItem, home: GeoPoint, firmware: Firmware) -> str | None:
    """Why ``item`` must not be uploaded, or None if nothing is wrong with it.

    Parameters
    ----------
    item
        The mission item.
    home
        The mission's home; altitudes relative to home are judged against its ``amsl_m``.
    firmware
        Whose conventions apply (ArduPilot refuses NaN in most params and keeps holds as
        whole seconds in 16 bits).

    Returns
    -------
    str or None
        One clause naming the field, its value and the fix, e.g.
        ``"param1 (hold) -5 s is out of range: give a hold of 0 to 65535 seconds"``.
    """
    ranges = _PARAMS.get(item.command, (None, None, None, None))
    for index, (value, spec) in enumerate(zip(item.params[:4], ranges, strict=True)):
        field = f"param{index + 1}" + (f" ({spec.name})" if spec is not None else "")
        if math.isnan(value):
            allowed = spec.nan_ok if spec is not None else True
            if firmware == "ardupilot" and not (index == 3 and item.command in _AP_NAN_PARAM4):
                allowed = False
            if not allowed:
                return (
                    f"{field} is NaN (null in a .plan), which the vehicle cannot use: give a number"
                )
            continue
        if abs(value) > FLOAT32_MAX:
            return f"{field} {value:g} does not fit a MAVLink param: give a finite number"
        if spec is None:
            continue
        unit = f" {spec.unit}" if spec.unit else ""
        too_low = value <= spec.low if spec.low_open else value < spec.low
        if too_low or value > spec.high:
            kept = ""
            if firmware == "ardupilot" and spec.high == UINT16_SECONDS_MAX:
                kept = f" (ArduPilot would keep {int(value) % 65_536} s)"
            return f"{field} {value:g}{unit} is out of range{kept}: {spec.fix}"
    if not item.is_global:
        for name, value in (("param5 (x)", item.params[4]), ("param6 (y)", item.params[5])):
            if abs(value) > _INT32_MAX:
                return f"{name} {value:g} does not fit MAVLink's int32 field: give a smaller value"
        if abs(item.z) > FLOAT32_MAX:
            return f"param7 (z) {item.z:g} does not fit a MAVLink param: give a finite number"
        return None
    return _location_problem(item, home)


def _location_problem(item: MissionItem, home: GeoPoint) -> str | None:
    lat, lon, z = item.params[4], item.params[5], item.z
    if not -90.0 <= lat <= 90.0:
        return f"latitude (param5) {lat:g} is not in [-90, 90]: give the item's position"
    if not -180.0 <= lon <= 180.0:
        return f"longitude (param6) {lon:g} is not in [-180, 180]: give the item's position"
    if abs(z) >= LOCATION_ALT_MAX_M:
        return (
            f"altitude (param7) {z:g} m is beyond the {LOCATION_ALT_MAX_M:g} m a vehicle can "
            "store: give the altitude in metres"
        )
    if item.frame in TERRAIN_ALT_FRAMES:
        if z < 0.0:
            return (
                f"altitude (param7) {z:g} m above terrain is below the ground: give a height "
                "above the terrain of 0 m or more"
            )
        return None
    if item.frame in RELATIVE_ALT_FRAMES:
        amsl = home.amsl_m + z
        if amsl < LOWEST_AMSL_M:
            return (
                f"altitude (param7) {z:g} m relative to home ({home.amsl_m:g} m AMSL) is "
                f"{amsl:g} m AMSL, below the lowest ground on Earth: give an altitude of "
                f"{LOWEST_AMSL_M - home.amsl_m:g} m or more relative to home"
            )
    elif z < LOWEST_AMSL_M:
        return (
            f"altitude (param7) {z:g} m AMSL is below the lowest ground on Earth: give the "
            "altitude above mean sea level in metres"
        )
    return None


def count_problem(items: int, firmware: Firmware) -> str | None:
    """Why a mission of ``items`` items (home excluded) is too long for any vehicle, or None.

    MAVLink counts a mission's items in 16 bits; ArduPilot's home item counts too.
    """
    count = items + (1 if firmware == "ardupilot" else 0)
    if count <= MAX_MISSION_ITEMS:
        return None
    with_home = f" ({items} and ArduPilot's home item)" if firmware == "ardupilot" else ""
    return (
        f"{count} mission items{with_home} are more than the {MAX_MISSION_ITEMS} a MAVLink "
        "mission can hold: plan fewer targets or split the mission into sorties"
    )


def upload_problem(mission: Mission) -> str | None:
    """The first reason ``mission`` must not be uploaded, naming the item by its seq; or None."""
    problem = count_problem(len(mission.items), mission.firmware)
    if problem is not None:
        return problem
    first_seq = 1 if mission.firmware == "ardupilot" else 0
    for seq, item in enumerate(mission.items, start=first_seq):
        problem = item_problem(item, mission.home, mission.firmware)
        if problem is not None:
            return f"mission item seq {seq} ({command_name(item.command)}): {problem}"
    return None


def below_home(mission: Mission) -> tuple[str, ...]:
    """A warning for each item flown below home (relative altitude under 0), naming its seq.

    Legal in a valley, but a mission planned at one altitude over the site never does it, and a
    typo (-40 for 40) would fly into the ground.
    """
    first_seq = 1 if mission.firmware == "ardupilot" else 0
    return tuple(
        f"mission item seq {seq} ({command_name(item.command)}) flies {-item.z:g} m below "
        "home: make sure the ground there is lower still, or correct the altitude"
        for seq, item in enumerate(mission.items, start=first_seq)
        if item.frame in RELATIVE_ALT_FRAMES and item.z < 0.0
    )


def command_name(command: int) -> str:
    """``NAV_WAYPOINT`` for 16: the MAV_CMD name without its prefix."""
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {command}"
