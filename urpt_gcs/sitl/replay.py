"""Replay: fly a mission on the simulated copter through the real link code, then judge it.

:func:`fly` starts the simulator in a thread on a free loopback port and drives it as a ground
station would, through MAVSDK: the verified upload of :mod:`urpt_gcs.link`, parameters, arming,
AUTO, and the telemetry the GCS receives (GLOBAL_POSITION_INT for the track, CAMERA_FEEDBACK
for the photos). With ``px4`` set it starts PX4's own SITL instead
(:mod:`urpt_gcs.sitl.px4_sitl`), arms, sends MAV_CMD_MISSION_START and takes the photos from
CAMERA_IMAGE_CAPTURED. :func:`replay` then hands the flight to :mod:`urpt_gcs.sitl.judge`.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.exceptions import MavsdkError
from mavsdk.plugins.action import ActionError
from mavsdk.plugins.mavlink_direct import MavlinkMessage
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import LinkError, MissionFileError, SettingsError
from urpt_gcs.formats import read_plan, read_waypoints
from urpt_gcs.inputs import MISSION_FILE_MAX_BYTES, read_capped
from urpt_gcs.link import UploadReport, UploadSettings, upload_verified
from urpt_gcs.mavsdk_link import MavsdkLink, connect
from urpt_gcs.mission import Mission, command_name
from urpt_gcs.sitl.judge import ReplayReport, judge
from urpt_gcs.sitl.params import AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE
from urpt_gcs.sitl.server import SitlServer
from urpt_gcs.sitl.settings import VehicleSettings
from urpt_gcs.targets import read_targets
from urpt_gcs.terrain import open_dem

Progress = Callable[[str], None]
TakeoffMethod = Literal["auto-options", "guided"]
GUIDED_TAKEOFF_M = 10.0
CONNECT_TIMEOUT_S = 10.0
# A real ArduCopter SITL needs about half a minute after boot before it will arm.
ARM_WAIT_S = 90.0
ARM_RETRY_S = 2.0
AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
# SIH keeps time at 20x, but on 2 cores some CAMERA_IMAGE_CAPTURED never reached MAVSDK;
# at 15x none was lost in three demo flights.
PX4_MAX_SPEEDUP = 15.0


@dataclass(frozen=True, slots=True)
class ReplaySettings:
    """How the replay flies and what it requires.

    Attributes
    ----------
    speedup
        Simulated seconds per wall second.
    fov_deg
        Camera half-angle from nadir, as planned.
    min_clearance_m
        Least height above the terrain the cruise legs must keep.
    takeoff
        ``auto-options``: set AUTO_OPTIONS bit 1 so AUTO takes off by itself; ``guided``:
        take off in GUIDED first, then switch to AUTO.
    timeout_s
        Wall-clock limit for the flight; None estimates it from the mission.
    position_rate_hz
        GLOBAL_POSITION_INT rate asked of the vehicle (per simulated second).
    connect
        Fly on the vehicle at this MAVSDK connection string (an ArduPilot SITL) instead of
        starting the simulator; ``speedup`` should then be the SITL's.
    px4
        Start PX4's SITL from this folder (the one with ``run.sh``) at ``speedup`` and fly
        the PX4 mission on it; ``takeoff`` does not apply.
    """

    speedup: float = 50.0
    fov_deg: float = 30.0
    min_clearance_m: float = 10.0
    takeoff: TakeoffMethod = "auto-options"
    timeout_s: float | None = None
    position_rate_hz: float = 10.0
    connect: str | None = None
    px4: Path | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speedup) and 1.0 <= self.speedup <= 1000.0):
            raise SettingsError(f"--speedup {self.speedup} is out of range; use 1 to 1000")
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError(f"--fov {self.fov_deg} is outside (0, 90) degrees")
        if not (math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0.0):
            raise SettingsError(f"--min-clearance {self.min_clearance_m} must be 0 or more m")
        if self.takeoff not in ("auto-options", "guided"):
            raise SettingsError(f"--takeoff {self.takeoff!r}: use auto-options or guided")
        if self.timeout_s is not None and not (
            math.isfinite(self.timeout_s) and self.timeout_s > 0.0
        ):
            raise SettingsError(f"--timeout {self.timeout_s} s must be positive")
        if not (math.isfinite(self.position_rate_hz) and 0.5 <= self.position_rate_hz <= 50.0):
            raise SettingsError(f"position rate {self.position_rate_hz} Hz: use 0.5 to 50")
        if self.px4 is not None and self.connect is not None:
            raise SettingsError("--px4 starts its own SITL: give --px4 or --connect, not both")


@dataclass(frozen=True, slots=True)
class PhotoFix:
    """A photo as CAMERA_FEEDBACK (PX4: CAMERA_IMAGE_CAPTURED) reported it."""

    index: int
    lat_deg: float
    lon_deg: float
    alt_rel_m: float
    time_s: float


@dataclass(frozen=True, slots=True)
class TrackPoint:
    """A position as GLOBAL_POSITION_INT reported it (time in simulated seconds)."""

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_rel_m: float


@dataclass(frozen=True, slots=True)
class Flight:
    """What the ground station saw of one flight."""

    upload: UploadReport
    photos: tuple[PhotoFix, ...]
    track: tuple[TrackPoint, ...]
    sim_time_s: float
    wall_time_s: float


def read_mission(path: Path, flag: str = "--plan") -> Mission:
    """A ``.plan`` or ``.waypoints`` file (by extension), of at most 16 MiB.

    ``flag`` is where the operator gave the path, for the messages.
    """
    data = read_capped(
        path,
        "mission file",
        flag,
        MissionFileError,
        MISSION_FILE_MAX_BYTES,
        "give the mission urpt-gcs plan wrote",
    )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MissionFileError(f"mission file '{path}' cannot be read: {exc}") from None
    if path.suffix.lower() == ".waypoints":
        return read_waypoints(text, str(path))
    if path.suffix.lower() == ".plan":
        return read_plan(text, str(path))
    raise MissionFileError(
        f"'{path}' is neither a .plan nor a .waypoints file: give the mission urpt-gcs plan wrote"
    )


def free_udp_port() -> int:
    """A loopback UDP port that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


def estimate_wall_timeout_s(mission: Mission, settings: ReplaySettings) -> float:
    """A generous wall-clock limit: three times a rough flight time, plus start-up."""
    from urpt_gcs.sitl.model import EARTH_RADIUS_M

    points = [(mission.home.lat_deg, mission.home.lon_deg)]
    holds = 0.0
    for item in mission.items:
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT:
            points.append((item.params[4], item.params[5]))
            holds += max(item.params[0], 0.0)
    points.append(points[0])
    scale = math.cos(math.radians(mission.home.lat_deg))
    length = sum(
        math.hypot(math.radians(b[0] - a[0]), math.radians(b[1] - a[1]) * scale) * EARTH_RADIUS_M
        for a, b in itertools.pairwise(points)
    )
    altitude = max(mission.altitude_rel_m, 15.0)
    sim_s = length / mission.cruise_speed_m_s + holds + altitude / 2.5 + altitude / 0.5 + 30.0
    return 20.0 + 3.0 * sim_s / settings.speedup


class _Watch:
    """Messages the ground station receives, gathered in the background."""

    def __init__(self, link: MavsdkLink, system_id: int, px4: bool = False) -> None:
        self.link = link
        self.system_id = system_id
        self.px4 = px4
        self.track: list[TrackPoint] = []
        self.photos: list[PhotoFix] = []
        self.armed = False
        self.was_armed = False
        self.armed_at_s: float | None = None
        self.disarmed_at_s: float | None = None
        self.disarmed = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []

    async def _follow(self, name: str, handle: Callable[[dict[str, Any]], None]) -> None:
        messages = self.link.direct.subscribe_message(name)
        try:
            async for message in messages:
                if message.system_id == self.system_id and message.component_id == AUTOPILOT:
                    handle(json.loads(message.fields_json))
        finally:
            await messages.aclose()

    def _now_s(self) -> float:
        return self.track[-1].time_s if self.track else 0.0

    def _position(self, fields: dict[str, Any]) -> None:
        self.track.append(
            TrackPoint(
                fields["time_boot_ms"] / 1000.0,
                fields["lat"] * 1e-7,
                fields["lon"] * 1e-7,
                fields["relative_alt"] / 1000.0,
            )
        )

    def _photo(self, fields: dict[str, Any]) -> None:
        self.photos.append(
            PhotoFix(
                int(fields["img_idx"]),
                fields["lat"] * 1e-7,
                fields["lng"] * 1e-7,
                float(fields["alt_rel"]),
                fields["time_usec"] / 1e6,
            )
        )

    def _captured(self, fields: dict[str, Any]) -> None:
        self.photos.append(
            PhotoFix(
                int(fields["image_index"]),
                fields["lat"] * 1e-7,
                fields["lon"] * 1e-7,
                fields["relative_alt"] / 1000.0,
                fields["time_boot_ms"] / 1000.0,
            )
        )

    def _heartbeat(self, fields: dict[str, Any]) -> None:
        armed = bool(fields["base_mode"] & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed and not self.armed:
            self.was_armed, self.armed_at_s = True, self._now_s()
        if self.was_armed and self.armed and not armed:
            self.disarmed_at_s = self._now_s()
            self.disarmed.set()
        self.armed = armed

    async def start(self) -> None:
        """Subscribe to position, camera feedback (PX4: images captured) and heartbeat."""
        photos = ("CAMERA_IMAGE_CAPTURED", self._captured) if self.px4 else None
        for name, handle in (
            ("GLOBAL_POSITION_INT", self._position),
            photos or ("CAMERA_FEEDBACK", self._photo),
            ("HEARTBEAT", self._heartbeat),
        ):
            self._tasks.append(asyncio.create_task(self._follow(name, handle)))
        await asyncio.sleep(0)

    async def stop(self) -> None:
        """End the subscriptions."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)


async def _fly(
    link: MavsdkLink, mission: Mission, settings: ReplaySettings, timeout_s: float, say: Progress
) -> Flight:
    upload = await upload_verified(link, mission, UploadSettings(), say)
    param, telemetry, action = (
        ParamAsync(link.system),
        TelemetryAsync(link.system),
        ActionAsync(link.system),
    )
    watch = _Watch(link, await link.system.get_system_id())
    await watch.start()
    try:
        await param.set_param_float("WPNAV_SPEED", float(mission.cruise_speed_m_s * 100.0))
        await telemetry.set_rate_position(settings.position_rate_hz)
        if settings.takeoff == "auto-options":
            await param.set_param_int("AUTO_OPTIONS", AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE)
        say("arming")
        started = time.monotonic()
        await _arm_when_ready(action, ARM_WAIT_S)
        if settings.takeoff == "guided":
            await action.set_takeoff_altitude(GUIDED_TAKEOFF_M)
            await action.takeoff()
            while not watch.track or watch.track[-1].alt_rel_m < GUIDED_TAKEOFF_M * 0.95:
                await asyncio.sleep(0.05)
        say("flying the mission in AUTO")
        await link.mission.start_mission()
        await asyncio.wait_for(watch.disarmed.wait(), timeout_s)
    except asyncio.TimeoutError:
        raise LinkError(
            f"the simulated vehicle did not land within {timeout_s:.0f} s of wall time"
        ) from None
    except MavsdkError as exc:
        raise LinkError(f"the simulated vehicle refused a step of the flight: {exc}") from None
    finally:
        await watch.stop()
        for plugin in (param, telemetry, action):
            plugin.destroy()
    sim_s = (watch.disarmed_at_s or 0.0) - (watch.armed_at_s or 0.0)
    return Flight(
        upload, tuple(watch.photos), tuple(watch.track), sim_s, time.monotonic() - started
    )


async def _fly_px4(
    link: MavsdkLink, mission: Mission, settings: ReplaySettings, timeout_s: float, say: Progress
) -> Flight:
    """Arm and MAV_CMD_MISSION_START: PX4 then takes off and flies the mission in AUTO."""
    upload = await upload_verified(link, mission, UploadSettings(), say)
    param, telemetry, action = (
        ParamAsync(link.system),
        TelemetryAsync(link.system),
        ActionAsync(link.system),
    )
    system_id = await link.system.get_system_id()
    watch = _Watch(link, system_id, px4=True)
    await watch.start()
    try:
        # As WPNAV_SPEED for ArduCopter: the cruise speed the plan's timing assumed.
        await param.set_param_float("MPC_XY_CRUISE", float(mission.cruise_speed_m_s))
        await telemetry.set_rate_position(settings.position_rate_hz)
        say("arming")
        started = time.monotonic()
        await _arm_when_ready(action, ARM_WAIT_S)
        say("flying the mission (MAV_CMD_MISSION_START)")
        await _command(link, system_id, mavlink.MAV_CMD_MISSION_START)
        await asyncio.wait_for(watch.disarmed.wait(), timeout_s)
    except asyncio.TimeoutError:
        raise LinkError(f"PX4 did not land within {timeout_s:.0f} s of wall time") from None
    except MavsdkError as exc:
        raise LinkError(f"PX4 refused a step of the flight: {exc}") from None
    finally:
        await watch.stop()
        for plugin in (param, telemetry, action):
            plugin.destroy()
    sim_s = (watch.disarmed_at_s or 0.0) - (watch.armed_at_s or 0.0)
    return Flight(
        upload, tuple(watch.photos), tuple(watch.track), sim_s, time.monotonic() - started
    )


async def _command(link: MavsdkLink, system_id: int, command: int) -> None:
    """COMMAND_LONG without params; LinkError with the vehicle's MAV_RESULT unless accepted."""
    fields = {"target_system": system_id, "target_component": AUTOPILOT, "command": command}
    fields |= {"confirmation": 0} | {f"param{i}": 0.0 for i in range(1, 8)}
    message = MavlinkMessage("COMMAND_LONG", 0, 0, system_id, AUTOPILOT, json.dumps(fields))
    ack = json.loads((await link.direct.send_command(message)).fields_json or "{}")
    result = ack.get("result")
    if result != mavlink.MAV_RESULT_ACCEPTED:
        entry = mavlink.enums["MAV_RESULT"].get(result) if isinstance(result, int) else None
        name = entry.name if entry is not None else "no answer"
        raise LinkError(f"the vehicle did not accept {command_name(command)}: {name}")


async def _arm_when_ready(action: ActionAsync, wait_s: float) -> None:
    """Arm; a real SITL refuses until its position estimate is good, so ask again."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            await action.arm()
            return
        except ActionError as exc:
            if time.monotonic() > deadline:
                raise LinkError(f"the vehicle refused to arm for {wait_s:g} s ({exc})") from None
        await asyncio.sleep(ARM_RETRY_S)


def fly(mission: Mission, settings: ReplaySettings, progress: Progress | None = None) -> Flight:
    """Fly ``mission`` on a simulated ArduCopter started for the purpose, on the vehicle
    at ``settings.connect`` (an ArduPilot SITL) if given, or on PX4's SITL started from
    ``settings.px4``.

    Raises
    ------
    LinkError
        If the upload is not verified or the vehicle does not complete the flight.
    """
    if settings.px4 is not None and mission.firmware != "px4":
        raise SettingsError("--px4 flies on PX4: plan the mission with --firmware px4")
    if settings.px4 is None and mission.firmware != "ardupilot":
        raise SettingsError(
            "replay flies an ArduCopter: plan the mission with --firmware ardupilot, or fly "
            "a PX4 mission on PX4's SITL with --px4 PATH"
        )
    say = progress or (lambda _msg: None)
    if settings.px4 is not None and settings.speedup > PX4_MAX_SPEEDUP:
        say(
            f"PX4 SITL at {PX4_MAX_SPEEDUP:g}x, not {settings.speedup:g}x: faster, photo "
            "messages were lost on the way"
        )
        settings = replace(settings, speedup=PX4_MAX_SPEEDUP)
    timeout_s = settings.timeout_s or estimate_wall_timeout_s(mission, settings)

    async def run(url: str) -> Flight:
        async with connect(url, CONNECT_TIMEOUT_S) as link:
            if mission.firmware == "px4":
                return await _fly_px4(link, mission, settings, timeout_s, say)
            return await _fly(link, mission, settings, timeout_s, say)

    if settings.px4 is not None:
        from urpt_gcs.sitl import px4_sitl

        say(f"starting PX4 SITL from {settings.px4} (speed-up {settings.speedup:g}x)")
        with px4_sitl.launch(settings.px4, mission.home, settings.speedup) as sitl:
            say(f"PX4 SITL running (pid {sitl.pid}) on {sitl.url}")
            return asyncio.run(run(sitl.url))

    if settings.connect is not None:
        say(f"flying on the vehicle at {settings.connect}")
        return asyncio.run(run(settings.connect))
    port = free_udp_port()
    vehicle = VehicleSettings(home=mission.home, speedup=settings.speedup)
    say(f"starting the simulated ArduCopter (speed-up {settings.speedup:g}x)")
    with SitlServer(vehicle, f"udpout://127.0.0.1:{port}"):
        return asyncio.run(run(f"udpin://127.0.0.1:{port}"))


def replay(
    dem_path: Path,
    targets_path: Path,
    plan_path: Path,
    settings: ReplaySettings | None = None,
    progress: Progress | None = None,
) -> ReplayReport:
    """Fly the mission in ``plan_path`` and check it against the DEM and the targets.

    Returns
    -------
    ReplayReport
        Photos, which photo sees each target, the least clearance, times; ``ok`` only if
        every target was seen and every cruise leg kept its clearance.
    """
    settings = settings or ReplaySettings()
    mission = read_mission(plan_path)
    # Refuse a bad DEM or target file before flying, not after.
    open_dem(dem_path)
    read_targets(targets_path)
    flight = fly(mission, settings, progress)
    return judge(flight, mission, dem_path, targets_path, settings, str(plan_path))
