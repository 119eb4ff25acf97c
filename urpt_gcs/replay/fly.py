"""Replay: fly a mission on a copter through the real link code, then judge it.

:func:`fly` flies on one of three vehicles: the simulated copter, started in a thread on a
free loopback port; ArduPilot's own ArduCopter SITL, started from ``--ardupilot PATH`` in a
scratch folder (:mod:`urpt_gcs.replay.ardupilot`); or any vehicle at ``--connect``. It
drives the vehicle as a ground station would, through MAVSDK: the verified upload of
:mod:`urpt_gcs.vehicle.link`, parameters, GUIDED, arming, AUTO, and the telemetry the GCS receives
(GLOBAL_POSITION_INT for the track, CAMERA_FEEDBACK for the photos). :func:`replay` then hands
the flight to :mod:`urpt_gcs.replay.judge`.

The flight time is the vehicle's own clock (``time_boot_ms``) from arming to the disarm
after landing. The copter is put in GUIDED before arming: after a mission ArduCopter stays in
AUTO, where MAVSDK's ``arm()`` would first switch to Hold, which is BRAKE on a copter, a mode
ArduCopter does not arm in.
With ``px4`` set it starts PX4's own SITL instead (:mod:`urpt_gcs.replay.px4`), arms, sends
MAV_CMD_MISSION_START and takes the photos from CAMERA_IMAGE_CAPTURED.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import socket
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.info import InfoAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.exceptions import MavsdkError
from mavsdk.plugins.action import ActionError
from mavsdk.plugins.info import InfoError, Version
from mavsdk.plugins.mavlink_direct import MavlinkMessage
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.flight.mission import Mission, command_name
from urpt_gcs.progress import Progress
from urpt_gcs.replay import ardupilot as ardupilot_sitl
from urpt_gcs.replay import px4 as px4_sitl
from urpt_gcs.replay.judge import ReplayReport, SetReport, expected_checks, judge, judge_set
from urpt_gcs.replay.record import SIMULATED, Flight, PhotoFix, TrackPoint, VehicleIdentity
from urpt_gcs.sim.model import EARTH_RADIUS_M
from urpt_gcs.sim.params import AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE
from urpt_gcs.sim.server import SitlServer
from urpt_gcs.sim.settings import VehicleSettings
from urpt_gcs.site.dem import open_dem
from urpt_gcs.site.targets import read_targets
from urpt_gcs.vehicle.link import UploadSettings, upload_verified
from urpt_gcs.vehicle.mavsdk_link import MavsdkLink, connect

__all__ = [
    "ARMING_MODE",
    "ARMING_TEXT_PREFIXES",
    "ARM_RETRY_S",
    "ARM_RETRY_TOGETHER_S",
    "ARM_WAIT_S",
    "AUTOPILOT",
    "CONNECT_TIMEOUT_S",
    "GUIDED_TAKEOFF_M",
    "MISSION_START_RETRY_S",
    "MISSION_START_TRIES",
    "PX4_MAX_SPEEDUP",
    "STATUS_WAIT_S",
    "VERSION_WAIT_S",
    "ReplaySettings",
    "TakeoffMethod",
    "estimate_wall_timeout_s",
    "fly",
    "fly_connected",
    "free_udp_port",
    "identify",
    "replay",
    "replay_set",
]

TakeoffMethod = Literal["auto-options", "guided"]
GUIDED_TAKEOFF_M = 10.0
CONNECT_TIMEOUT_S = 10.0
# A real ArduCopter SITL needs about half a minute after boot before it will arm.
ARM_WAIT_S = 90.0
ARM_RETRY_S = 2.0
# Vehicles of a fleet that are to take off together ask again sooner.
ARM_RETRY_TOGETHER_S = 0.1
# MAV_CMD_MISSION_START asked again while PX4 denies it, at most this often, this far apart.
MISSION_START_TRIES = 10
MISSION_START_RETRY_S = 0.3
_ASK_AGAIN = (mavlink.MAV_RESULT_DENIED, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
# ArduCopter arms in GUIDED once it has a position, and AUTO can take off from it.
ARMING_MODE = mavlink.COPTER_MODE_GUIDED
# MAVSDK asks for AUTOPILOT_VERSION itself on connecting; give the answer this long to come.
VERSION_WAIT_S = 5.0
# The vehicle's words on why it does not arm ("PreArm: ...", "Arm: ...").
ARMING_TEXT_PREFIXES = ("PreArm:", "Arm:")
# SIH keeps time at 20x, but on 2 cores some CAMERA_IMAGE_CAPTURED never reached MAVSDK;
# at 15x none was lost in three demo flights.
PX4_MAX_SPEEDUP = 15.0
# How long a vehicle may take to send its first SYS_STATUS before it is armed regardless.
STATUS_WAIT_S = 3.0


@dataclass(frozen=True, slots=True)
class ReplaySettings:
    """How the replay flies and what it requires.

    Attributes
    ----------
    speedup
        Simulated seconds per wall second.
    fov_deg
        Camera half-angle from nadir; None: as the mission says it was planned, else 30.
    min_clearance_m
        Least height above the terrain the cruise legs must keep; None: as planned, else 10.
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
    ardupilot
        Start ArduPilot's ArduCopter SITL from this binary (or its folder) at the plan's home
        with ``speedup``, fly on it and stop it again, instead of the simulator.
    px4
        Start PX4's SITL from this folder (the one with ``run.sh``) at ``speedup`` and fly
        the PX4 mission on it; ``takeoff`` does not apply.
    """

    speedup: float = 50.0
    fov_deg: float | None = None
    min_clearance_m: float | None = None
    takeoff: TakeoffMethod = "auto-options"
    timeout_s: float | None = None
    position_rate_hz: float = 10.0
    connect: str | None = None
    ardupilot: Path | None = None
    px4: Path | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speedup) and 1.0 <= self.speedup <= 1000.0):
            raise SettingsError(f"--speedup {self.speedup} is out of range; use 1 to 1000")
        if self.fov_deg is not None and not (
            math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0
        ):
            raise SettingsError(f"--fov {self.fov_deg} is outside (0, 90) degrees")
        if self.min_clearance_m is not None and not (
            math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0.0
        ):
            raise SettingsError(f"--min-clearance {self.min_clearance_m} must be 0 or more m")
        if self.takeoff not in ("auto-options", "guided"):
            raise SettingsError(f"--takeoff {self.takeoff!r}: use auto-options or guided")
        if self.timeout_s is not None and not (
            math.isfinite(self.timeout_s) and self.timeout_s > 0.0
        ):
            raise SettingsError(f"--timeout {self.timeout_s} s must be positive")
        if not (math.isfinite(self.position_rate_hz) and 0.5 <= self.position_rate_hz <= 50.0):
            raise SettingsError(f"position rate {self.position_rate_hz} Hz: use 0.5 to 50")
        if self.connect is not None and self.ardupilot is not None:
            raise SettingsError(
                "--connect and --ardupilot both name the vehicle: give one (--ardupilot starts "
                "the SITL itself)"
            )
        if self.px4 is not None and self.connect is not None:
            raise SettingsError("--px4 starts its own SITL: give --px4 or --connect, not both")
        if self.px4 is not None and self.ardupilot is not None:
            raise SettingsError("--px4 and --ardupilot both name the vehicle: give one")


def free_udp_port() -> int:
    """A loopback UDP port that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


def estimate_wall_timeout_s(mission: Mission, settings: ReplaySettings) -> float:
    """A generous wall-clock limit: three times a rough flight time, plus start-up."""
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
        self.texts: list[str] = []
        self.armed = False
        self.mode: int | None = None
        self.armed_at_s: float | None = None
        self.armed_at_wall: float | None = None
        self.disarmed_at_s: float | None = None
        self.disarmed_at_wall: float | None = None
        self.disarmed = asyncio.Event()
        # SYS_STATUS's pre-arm bit: None until a vehicle that reports it has spoken.
        self.armable: bool | None = None
        self._arm_unclocked = False
        self._tasks: list[asyncio.Task[None]] = []

    async def _follow(self, name: str, handle: Callable[[dict[str, Any]], None]) -> None:
        messages = self.link.direct.subscribe_message(name)
        try:
            async for message in messages:
                if message.system_id == self.system_id and message.component_id == AUTOPILOT:
                    handle(json.loads(message.fields_json))
        finally:
            await messages.aclose()

    def _position(self, fields: dict[str, Any]) -> None:
        if fields["lat"] == 0 and fields["lon"] == 0:
            # No position yet: ArduCopter sends 0, 0 until its EKF has an origin (the first
            # few simulated seconds, which a loaded machine stretches past the upload).
            return
        point = TrackPoint(
            fields["time_boot_ms"] / 1000.0,
            fields["lat"] * 1e-7,
            fields["lon"] * 1e-7,
            fields["relative_alt"] / 1000.0,
            time.monotonic(),
        )
        self.track.append(point)
        if self._arm_unclocked:
            # Armed before any position came: the first fix after it is the nearest clock.
            self.armed_at_s, self._arm_unclocked = point.time_s, False

    def _photo(self, fields: dict[str, Any]) -> None:
        self.photos.append(
            PhotoFix(
                int(fields["img_idx"]),
                fields["lat"] * 1e-7,
                fields["lng"] * 1e-7,
                float(fields["alt_rel"]),
                fields["time_usec"] / 1e6,
                float(fields.get("yaw", math.nan)) % 360.0,
            )
        )

    def _text(self, fields: dict[str, Any]) -> None:
        self.texts.append(str(fields.get("text", "")).rstrip("\0"))

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
        self.mode = int(fields["custom_mode"])
        now = self.track[-1].time_s if self.track else None
        if armed and not self.armed and self.armed_at_s is None:
            self.armed_at_s, self.armed_at_wall = now, time.monotonic()
            self._arm_unclocked = now is None
        if self.armed and not armed and self.armed_at_wall is not None:
            self.disarmed_at_s, self.disarmed_at_wall = now, time.monotonic()
            self.disarmed.set()
        self.armed = armed

    def _status(self, fields: dict[str, Any]) -> None:
        bit = mavlink.MAV_SYS_STATUS_PREARM_CHECK
        if int(fields["onboard_control_sensors_present"]) & bit:
            self.armable = bool(int(fields["onboard_control_sensors_health"]) & bit)

    def arming_words(self) -> str:
        """The vehicle's last words on arming, or ''."""
        said = [t for t in self.texts if t.startswith(ARMING_TEXT_PREFIXES)]
        return said[-1] if said else ""

    async def start(self) -> None:
        """Subscribe to position, photos (CAMERA_FEEDBACK; PX4: CAMERA_IMAGE_CAPTURED),
        status text and heartbeat."""
        photos = ("CAMERA_IMAGE_CAPTURED", self._captured) if self.px4 else None
        for name, handle in (
            ("GLOBAL_POSITION_INT", self._position),
            photos or ("CAMERA_FEEDBACK", self._photo),
            ("STATUSTEXT", self._text),
            ("HEARTBEAT", self._heartbeat),
            ("SYS_STATUS", self._status),
        ):
            self._tasks.append(asyncio.create_task(self._follow(name, handle)))
        await asyncio.sleep(0)

    async def stop(self) -> None:
        """End the subscriptions."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)


async def identify(link: MavsdkLink, where: str) -> VehicleIdentity:
    """The autopilot (HEARTBEAT) and its version (AUTOPILOT_VERSION, through MAVSDK's Info)."""
    names = {"ardupilot": "ArduPilot", "px4": "PX4", "unknown": "an unknown autopilot"}
    autopilot = names[await link.autopilot()]
    info = InfoAsync(link.system)
    version = ""
    deadline = time.monotonic() + VERSION_WAIT_S
    try:
        while True:
            try:
                version = _version_text(await info.get_version())
                break
            except InfoError:
                if time.monotonic() > deadline:
                    break
                await asyncio.sleep(0.2)
    finally:
        info.destroy()
    return VehicleIdentity(autopilot, version, where)


def _version_text(version: Version) -> str:
    kinds = Version.FlightSoftwareVersionType
    suffix = {
        kinds.DEV: "-dev",
        kinds.ALPHA: "-alpha",
        kinds.BETA: "-beta",
        kinds.RC: "-rc",
    }.get(version.flight_sw_version_type, "")
    number = f"{version.flight_sw_major}.{version.flight_sw_minor}.{version.flight_sw_patch}"
    return "" if number == "0.0.0" else number + suffix


async def fly_connected(
    link: MavsdkLink,
    mission: Mission,
    settings: ReplaySettings,
    timeout_s: float,
    say: Progress,
    where: str,
    before_arming: Callable[[], Awaitable[None]] | None = None,
    start_delay_s: float = 0.0,
    after_arming: Callable[[], None] | None = None,
) -> Flight:
    """Fly ``mission`` on the vehicle at ``link``, already connected: upload, arm and fly.

    ``before_arming``, if given, is awaited once the vehicle is ready to arm (a fleet's
    vehicles wait there for each other), and the vehicle then waits ``start_delay_s`` more on
    its own clock before it arms; ``after_arming`` is called once it is armed.
    """
    upload = await upload_verified(link, mission, UploadSettings(), say)
    vehicle = await identify(link, where)
    param, telemetry, action = (
        ParamAsync(link.system),
        TelemetryAsync(link.system),
        ActionAsync(link.system),
    )
    system_id = await link.system.get_system_id()
    watch = _Watch(link, system_id, px4=mission.firmware == "px4")
    await watch.start()
    try:
        await telemetry.set_rate_position(settings.position_rate_hz)
        if mission.firmware == "px4":
            await _start_px4(
                link, system_id, param, action, mission, say, before_arming, after_arming
            )
        else:
            await _start_ardupilot(
                link, param, action, watch, settings, say, before_arming, start_delay_s,
                after_arming,
            )  # fmt: skip
        await asyncio.wait_for(watch.disarmed.wait(), timeout_s)
    except asyncio.TimeoutError:
        raise LinkError(
            f"{vehicle.describe()} did not land within {timeout_s:g} s of wall time"
            + ardupilot_sitl.unreachable_hint(mission)
        ) from None
    except MavsdkError as exc:
        words = watch.arming_words() or (watch.texts[-1] if watch.texts else "")
        raise LinkError(
            f"{vehicle.describe()} refused a step of the flight: {exc}"
            + (f" (it said '{words}')" if words else "")
        ) from None
    finally:
        await watch.stop()
        for plugin in (param, telemetry, action):
            plugin.destroy()
    sim_s = (watch.disarmed_at_s or 0.0) - (watch.armed_at_s or 0.0)
    wall_s = (watch.disarmed_at_wall or 0.0) - (watch.armed_at_wall or 0.0)
    return Flight(upload, tuple(watch.photos), tuple(watch.track), sim_s, wall_s, vehicle)


async def _start_ardupilot(
    link: MavsdkLink,
    param: ParamAsync,
    action: ActionAsync,
    watch: _Watch,
    settings: ReplaySettings,
    say: Progress,
    before_arming: Callable[[], Awaitable[None]] | None = None,
    start_delay_s: float = 0.0,
    after_arming: Callable[[], None] | None = None,
) -> None:
    """Arm in GUIDED and start AUTO, taking off as ``settings.takeoff`` says; with
    ``before_arming``, arm ``start_delay_s`` after it returns, timed on the vehicle's clock;
    ``after_arming`` is called once armed."""
    if settings.takeoff == "auto-options":
        await param.set_param_int("AUTO_OPTIONS", AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE)
    retry_s = ARM_RETRY_S
    if before_arming is not None:
        # Ready everything but the arming itself, so the vehicles wait for each other as late
        # as possible and then take off within moments of each other.
        if watch.mode != ARMING_MODE:
            await _set_mode(link, ARMING_MODE)
        await _until_armable(link, watch, ARM_WAIT_S)
        await before_arming()
        if start_delay_s > 0.0:
            say(f"waiting {start_delay_s:g} s on the vehicle's clock, as planned")
            await _wait_on_vehicle_clock(watch, start_delay_s, settings.speedup)
        retry_s = ARM_RETRY_TOGETHER_S
    say("arming")
    await _arm_when_ready(link, action, watch, ARM_WAIT_S, retry_s, say)
    if after_arming is not None:
        after_arming()
    if settings.takeoff == "guided":
        await action.set_takeoff_altitude(GUIDED_TAKEOFF_M)
        await action.takeoff()
        while not watch.track or watch.track[-1].alt_rel_m < GUIDED_TAKEOFF_M * 0.95:
            await asyncio.sleep(0.05)
    say("flying the mission in AUTO")
    await link.mission.start_mission()


async def _wait_on_vehicle_clock(watch: _Watch, seconds: float, speedup: float) -> None:
    """Until the vehicle's own clock (``time_boot_ms`` of its positions) has moved on by
    ``seconds``: a simulator slower than its speed-up still waits the planned time. With no
    position heard yet, the wall-clock time at the nominal speed-up is waited first."""
    if not watch.track:
        await asyncio.sleep(seconds / speedup)
        return
    start = watch.track[-1].time_s
    while watch.track[-1].time_s - start < seconds:
        await asyncio.sleep(0.01)


async def _start_px4(
    link: MavsdkLink,
    system_id: int,
    param: ParamAsync,
    action: ActionAsync,
    mission: Mission,
    say: Progress,
    before_arming: Callable[[], Awaitable[None]] | None = None,
    after_arming: Callable[[], None] | None = None,
) -> None:
    """Arm and MAV_CMD_MISSION_START: PX4 then takes off and flies the mission in AUTO."""
    # MPC_XY_CRUISE is the speed PX4 flies between waypoints until the mission's own speed
    # item applies; the plan's timing assumes that speed.
    await param.set_param_float("MPC_XY_CRUISE", float(mission.cruise_speed_m_s))
    if before_arming is not None:
        await before_arming()
    say("arming")
    await _arm_retrying(action, ARM_WAIT_S)
    if after_arming is not None:
        after_arming()
    say("flying the mission (MAV_CMD_MISSION_START)")
    # PX4 denies the start until its navigator has published the uploaded mission as valid,
    # which can come just after arming; it disarms again if left on the ground, so each try
    # arms first (accepted at once when armed).
    for attempt in range(MISSION_START_TRIES):
        result = await _send_command(link, system_id, mavlink.MAV_CMD_MISSION_START)
        if result not in _ASK_AGAIN or attempt == MISSION_START_TRIES - 1:
            _accepted(mavlink.MAV_CMD_MISSION_START, result, attempt + 1)
            return
        say("the start was refused: asking again")
        await asyncio.sleep(MISSION_START_RETRY_S)
        await _arm_retrying(action, ARM_WAIT_S)


async def _send_command(
    link: MavsdkLink, system_id: int, command: int, *params: float
) -> int | None:
    """COMMAND_LONG to the autopilot; the MAV_RESULT it answered, None without an answer."""
    values = [*params, *(0.0,) * (7 - len(params))]
    fields: dict[str, Any] = {
        "target_system": system_id,
        "target_component": AUTOPILOT,
        "command": command,
        "confirmation": 0,
    }
    fields |= {f"param{i}": float(v) for i, v in enumerate(values, start=1)}
    message = MavlinkMessage("COMMAND_LONG", 0, 0, system_id, AUTOPILOT, json.dumps(fields))
    ack = json.loads((await link.direct.send_command(message)).fields_json or "{}")
    result = ack.get("result")
    return result if isinstance(result, int) else None


async def _command(link: MavsdkLink, system_id: int, command: int) -> None:
    """COMMAND_LONG without params; LinkError with the vehicle's MAV_RESULT unless accepted."""
    _accepted(command, await _send_command(link, system_id, command))


def _accepted(command: int, result: int | None, tries: int = 1) -> None:
    """LinkError naming the vehicle's MAV_RESULT unless it accepted ``command``."""
    if result != mavlink.MAV_RESULT_ACCEPTED:
        entry = mavlink.enums["MAV_RESULT"].get(result) if result is not None else None
        name = entry.name if entry is not None else "no answer"
        times = f" (asked {tries} times)" if tries > 1 else ""
        raise LinkError(f"the vehicle did not accept {command_name(command)}: {name}{times}")


async def _until_armable(link: MavsdkLink, watch: _Watch, wait_s: float) -> None:
    """Wait until SYS_STATUS says the pre-arm checks pass (at most ``wait_s``); a vehicle that
    does not report them is not waited for."""
    system_id = await link.system.get_system_id()
    interval_us = 200_000.0
    with contextlib.suppress(MavsdkError):
        await _send_command(
            link, system_id, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS, interval_us,
        )  # fmt: skip
    deadline = time.monotonic() + wait_s
    first_word = time.monotonic() + STATUS_WAIT_S
    while not watch.armable and time.monotonic() < deadline:
        if watch.armable is None and time.monotonic() > first_word:
            return
        await asyncio.sleep(0.05)


async def _arm_retrying(action: ActionAsync, wait_s: float) -> None:
    """Arm; PX4's SITL refuses until its position estimate is good, so ask again."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            await action.arm()
            return
        except ActionError as exc:
            if time.monotonic() > deadline:
                raise LinkError(f"the vehicle refused to arm for {wait_s:g} s ({exc})") from None
        await asyncio.sleep(ARM_RETRY_S)


async def _set_mode(link: MavsdkLink, mode: int) -> bool:
    """MAV_CMD_DO_SET_MODE with an ArduCopter custom mode; True if the vehicle accepted it."""
    flag = float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    system_id = await link.system.get_system_id()
    try:
        result = await _send_command(link, system_id, mavlink.MAV_CMD_DO_SET_MODE, flag, mode)
    except MavsdkError:
        return False
    return bool(result == mavlink.MAV_RESULT_ACCEPTED)


async def _arm_when_ready(
    link: MavsdkLink,
    action: ActionAsync,
    watch: _Watch,
    wait_s: float,
    retry_s: float = ARM_RETRY_S,
    say: Progress | None = None,
) -> None:
    """Put the copter in GUIDED and arm; a real SITL refuses until its position estimate is
    good, so ask again. The vehicle's own "PreArm:"/"Arm:" words go into the error."""
    deadline = time.monotonic() + wait_s
    problem = ""
    while True:
        if watch.mode != ARMING_MODE and not await _set_mode(link, ARMING_MODE):
            problem = "it did not switch to GUIDED"
        else:
            try:
                await action.arm()
                return
            except ActionError as exc:
                problem = exc.result.name
        if time.monotonic() > deadline:
            words = watch.arming_words()
            raise LinkError(
                f"the vehicle on {link.url} refused to arm for {wait_s:g} s ({problem}"
                + (f"; it said '{words}'" if words else "")
                + "): check its pre-arm checks"
            ) from None
        if say is not None:
            words = watch.arming_words()
            say(f"not armed yet ({problem}{'; ' + words if words else ''}): asking again")
        await asyncio.sleep(retry_s)


def fly(mission: Mission, settings: ReplaySettings, progress: Progress | None = None) -> Flight:
    """Fly ``mission`` on a simulated ArduCopter started for the purpose, on ArduCopter SITL
    started from ``settings.ardupilot``, on PX4's SITL started from ``settings.px4``, or on
    the vehicle at ``settings.connect``.

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

    async def run(url: str, where: str) -> Flight:
        async with connect(url, CONNECT_TIMEOUT_S) as link:
            return await fly_connected(link, mission, settings, timeout_s, say, where)

    if settings.px4 is not None:
        say(f"starting PX4 SITL from {settings.px4} (speed-up {settings.speedup:g}x)")
        with px4_sitl.launch(settings.px4, mission.home, settings.speedup) as px4:
            say(f"PX4 SITL running (pid {px4.pid}) on {px4.url}")
            return asyncio.run(run(px4.url, f"PX4 SITL, pid {px4.pid}, instance {px4.instance}"))

    if settings.connect is not None:
        say(f"flying on the vehicle at {settings.connect}")
        return asyncio.run(run(settings.connect, settings.connect))
    if settings.ardupilot is not None:
        say(f"starting ArduCopter SITL from {settings.ardupilot} (speed-up {settings.speedup:g}x)")
        with ardupilot_sitl.launch(settings.ardupilot, mission.home, settings.speedup) as sitl:
            where = f"ArduCopter SITL, pid {sitl.pid}, instance {sitl.instance}"
            return asyncio.run(run(sitl.url, where))
    port = free_udp_port()
    vehicle = VehicleSettings(home=mission.home, speedup=settings.speedup)
    say(f"starting the simulated ArduCopter (speed-up {settings.speedup:g}x)")
    with SitlServer(vehicle, f"udpout://127.0.0.1:{port}"):
        return asyncio.run(run(f"udpin://127.0.0.1:{port}", SIMULATED))


def replay(
    dem_path: Path,
    targets_path: Path,
    plan_path: Path,
    settings: ReplaySettings | None = None,
    progress: Progress | None = None,
    alone: bool = True,
) -> ReplayReport:
    """Fly the mission in ``plan_path`` and check it against the DEM and the targets.

    Returns
    -------
    ReplayReport
        Photos, which photo sees each target, the least clearance, times; ``ok`` only if every
        target (all of the file's, for a plan's only sortie ``alone``) was seen, every leg clear.
    """
    settings = settings or ReplaySettings()
    mission = read_mission(plan_path)
    # Refuse a bad DEM or target file before flying, not after.
    open_dem(dem_path)
    read_targets(targets_path)
    expected = expected_checks(plan_path, mission, settings.fov_deg, settings.min_clearance_m)
    flight = fly(mission, settings, progress)
    return judge(flight, mission, dem_path, targets_path, expected, str(plan_path), alone)


def replay_set(
    dem_path: Path,
    targets_path: Path,
    plan_paths: Sequence[Path],
    settings: ReplaySettings | None = None,
    progress: Progress | None = None,
) -> SetReport:
    """Replay each mission file on its own simulator, judge each on its own targets, and all
    of them together on every target of ``targets_path``."""
    reports = [replay(dem_path, targets_path, p, settings, progress, False) for p in plan_paths]
    return judge_set(reports, dem_path, targets_path)
