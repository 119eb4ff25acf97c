"""A real flight's log, read through pymavlink: its photos, its track, its vehicle, its mission.

Three kinds of log are read:

- a telemetry log (``.tlog``) as QGroundControl and MAVProxy record it: every MAVLink message
  the ground station received or sent, each after its arrival time. Photos come from
  CAMERA_FEEDBACK (ArduPilot) or CAMERA_IMAGE_CAPTURED (PX4), the track from
  GLOBAL_POSITION_INT, the mission from the MISSION_ITEM_INT messages of its upload or
  download;
- an ArduPilot DataFlash log (``.bin``), written on the vehicle: photos from CAM (or TRIG,
  where the camera gave no feedback), the track from POS, the mission from CMD, the firmware
  from its first MSG.

What is refused, in one line naming the log and the fix: a file that is no log of these kinds,
a log without any position, a log of several vehicles, a log with no photo message at all.
A log that ends while the vehicle is still armed is read as far as it goes, with a warning:
photos after the end are not in it.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pymavlink import DFReader, mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import SettingsError
from urpt_gcs.replay.record import PhotoFix, TrackPoint

__all__ = ["LOG_SUFFIXES", "FlightLog", "LoggedWaypoint", "read_flight_log"]

LogKind = Literal["tlog", "dataflash"]
# File name endings of the logs read, and what each is.
LOG_SUFFIXES: dict[str, LogKind] = {".tlog": "tlog", ".bin": "dataflash"}
# Fixes of the track kept per second of the log: enough for the clearance check between
# fixes, few enough that a long DataFlash log (POS at up to 50 Hz) stays small.
TRACK_RATE_HZ = 10.0
# A log larger than this is refused before it is read (a day of DataFlash at full rate is
# a few GB; a flight is well under this).
LOG_MAX_BYTES = 4 * 1024**3
# The messages read, by kind of log (a reader skips the others without decoding them).
_TYPES: dict[LogKind, list[str]] = {
    "tlog": [
        "HEARTBEAT",
        "GLOBAL_POSITION_INT",
        "CAMERA_FEEDBACK",
        "CAMERA_IMAGE_CAPTURED",
        "MISSION_COUNT",
        "MISSION_ITEM_INT",
        "BAD_DATA",
    ],
    "dataflash": ["POS", "CAM", "TRIG", "CMD", "ARM", "MSG", "PARM"],
}
# A DataFlash log begins with the FMT record that describes FMT: its two header bytes and
# FMT's type number.
_DATAFLASH_START = bytes([0xA3, 0x95, 0x80])
# MAV_CMD_NAV_* are numbered below this; other items' x and y are parameters, not a place.
_NAV_COMMANDS_END = 100
# HEARTBEAT's autopilot field: what ran on the vehicle.
_AUTOPILOTS = {
    mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot",
    mavlink.MAV_AUTOPILOT_PX4: "px4",
}
_HOW = (
    "give the .tlog your ground station recorded (QGroundControl: Application Settings > "
    "Telemetry, save log after each flight; MAVProxy: the .tlog of its session) or the "
    "vehicle's DataFlash .bin"
)


@dataclass(frozen=True, slots=True)
class LoggedWaypoint:
    """A located mission item as the log holds it (degrees; the command's number)."""

    seq: int
    command: int
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True, slots=True)
class FlightLog:
    """What one log says of one flight.

    ``autopilot`` is ``ardupilot``, ``px4`` or ``unknown``; ``mission`` the located items of
    the last mission it holds (empty if none was logged); ``armed_at_end`` says the log ends
    with the vehicle armed, so it may be cut short.
    """

    path: Path
    kind: LogKind
    autopilot: str
    system_id: int
    firmware: str
    photos: tuple[PhotoFix, ...]
    track: tuple[TrackPoint, ...]
    mission: tuple[LoggedWaypoint, ...]
    armed_at_end: bool
    damaged: int
    duration_s: float
    warnings: tuple[str, ...] = field(default=())


def _refuse(path: Path, problem: str, fix: str = _HOW) -> SettingsError:
    return SettingsError(f"--log '{path}': {problem}: {fix}")


def _kind(path: Path) -> LogKind:
    suffix = path.suffix.lower()
    if suffix == ".ulg":
        raise _refuse(
            path,
            "PX4's own .ulg logs are not read",
            "give the .tlog QGroundControl recorded of the flight (its camera messages are "
            "CAMERA_IMAGE_CAPTURED)",
        )
    if suffix not in LOG_SUFFIXES:
        raise _refuse(path, f"the name ends in {suffix or 'nothing'!r}, not .tlog or .bin")
    return LOG_SUFFIXES[suffix]


def _check_file(path: Path) -> None:
    try:
        info = path.stat()
    except OSError as exc:
        raise _refuse(path, f"cannot be read ({exc.strerror or exc})", "check the path") from None
    if not path.is_file():
        raise _refuse(path, "is not a regular file", "give the log file itself")
    if info.st_size == 0:
        raise _refuse(path, "is empty")
    if info.st_size > LOG_MAX_BYTES:
        raise _refuse(
            path,
            f"is {info.st_size / 1024**3:.1f} GB, over the {LOG_MAX_BYTES / 1024**3:.0f} GB a "
            "flight's log may have",
            "give the log of one flight",
        )
    if not os.access(path, os.R_OK):
        raise _refuse(path, "cannot be read (permission denied)", "check its permissions")


@contextlib.contextmanager
def _silenced() -> Iterator[None]:
    """Nothing written to stdout or stderr gets out, from Python or from compiled code
    (pymavlink's DataFlash indexer reports every damaged byte it skips)."""
    quiet = io.StringIO()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
            yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def _messages(path: Path, kind: LogKind) -> Iterator[Any]:
    """Every message of the log, in order (pymavlink's reader for its kind)."""
    if kind == "dataflash":
        with path.open("rb") as file:
            start = file.read(3)
        if start != _DATAFLASH_START:
            raise _refuse(path, "holds no DataFlash log (it does not start with a FMT record)")
    with _silenced():
        if kind == "tlog":
            reader: Any = mavutil.mavlogfile(str(path), robust_parsing=True)
        else:
            reader = DFReader.DFReader_binary(str(path), zero_time_base=True)
    try:
        while True:
            with _silenced():
                message = reader.recv_match(type=_TYPES[kind])
            if message is None:
                return
            yield message
    finally:
        with contextlib.suppress(Exception):
            reader.close()


@dataclass
class _Gathered:
    """What the reader has gathered so far."""

    photos: dict[tuple[str, int], PhotoFix] = field(default_factory=dict)
    triggers: dict[int, PhotoFix] = field(default_factory=dict)
    track: list[TrackPoint] = field(default_factory=list)
    mission: dict[int, LoggedWaypoint] = field(default_factory=dict)
    mission_count: int | None = None
    autopilots: dict[int, str] = field(default_factory=dict)
    armed: bool = False
    firmware: str = ""
    damaged: int = 0
    first_s: float = math.nan
    last_s: float = math.nan
    last_track_s: float = -math.inf

    def position(self, time_s: float, lat: float, lon: float, alt_rel: float) -> None:
        if lat == 0.0 and lon == 0.0:
            return  # no position yet
        if time_s - self.last_track_s < 1.0 / TRACK_RATE_HZ:
            return
        self.last_track_s = time_s
        self.track.append(TrackPoint(time_s, lat, lon, alt_rel))

    def waypoint(self, seq: int, command: int, count: int | None, lat: float, lon: float) -> None:
        if seq == 0 or (count is not None and count != self.mission_count):
            # A new mission starts at item 0: forget the one before.
            self.mission = {}
            self.mission_count = count
        if command < _NAV_COMMANDS_END and not (lat == 0.0 and lon == 0.0):
            self.mission[seq] = LoggedWaypoint(seq, command, lat, lon)


def _yaw_from_quaternion(q: Any) -> float:
    w, x, y, z = (float(v) for v in q)
    if not all(math.isfinite(v) for v in (w, x, y, z)) or (w, x, y, z) == (0, 0, 0, 0):
        return math.nan
    return math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))) % 360.0


def _from_tlog(message: Any, got: _Gathered) -> None:
    kind = message.get_type()
    source = message.get_srcSystem()
    if kind == "HEARTBEAT":
        if message.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
            got.autopilots[source] = _AUTOPILOTS.get(message.autopilot, "unknown")
            got.armed = bool(message.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        return
    if kind == "GLOBAL_POSITION_INT":
        got.position(
            message.time_boot_ms / 1000.0,
            message.lat * 1e-7,
            message.lon * 1e-7,
            message.relative_alt / 1000.0,
        )
    elif kind == "CAMERA_FEEDBACK":
        got.photos[("feedback", int(message.img_idx))] = PhotoFix(
            int(message.img_idx),
            message.lat * 1e-7,
            message.lng * 1e-7,
            float(message.alt_rel),
            message.time_usec / 1e6,
            float(message.yaw) % 360.0,
        )
    elif kind == "CAMERA_IMAGE_CAPTURED":
        if message.capture_result == 1:
            got.photos[("captured", int(message.image_index))] = PhotoFix(
                int(message.image_index),
                message.lat * 1e-7,
                message.lon * 1e-7,
                message.relative_alt / 1000.0,
                message.time_boot_ms / 1000.0,
                _yaw_from_quaternion(message.q),
            )
    elif kind == "MISSION_COUNT" and getattr(message, "mission_type", 0) == 0:
        got.mission, got.mission_count = {}, int(message.count)
    elif kind == "MISSION_ITEM_INT" and getattr(message, "mission_type", 0) == 0:
        got.waypoint(
            int(message.seq), int(message.command), None, message.x * 1e-7, message.y * 1e-7
        )
    elif kind == "BAD_DATA":
        got.damaged += 1


def _from_dataflash(message: Any, got: _Gathered) -> None:
    kind = message.get_type()
    if kind == "POS":
        got.position(message.TimeUS / 1e6, message.Lat, message.Lng, message.RelHomeAlt)
    elif kind in ("CAM", "TRIG"):
        photo = PhotoFix(
            int(message.Img),
            float(message.Lat),
            float(message.Lng),
            float(message.RelAlt),
            message.TimeUS / 1e6,
            float(message.Y) % 360.0,
        )
        if kind == "CAM":
            got.photos[("cam", photo.index)] = photo
        else:
            got.triggers[photo.index] = photo
    elif kind == "CMD":
        got.waypoint(
            int(message.CNum), int(message.CId), int(message.CTot), message.Lat, message.Lng
        )
    elif kind == "ARM":
        got.armed = bool(message.ArmState)
    elif kind == "MSG" and not got.firmware:
        text = str(message.Message)
        if text.startswith(("ArduCopter", "ArduPlane", "ArduRover", "ArduSub", "Blimp")):
            got.firmware = text
            got.autopilots[0] = "ardupilot"
    elif kind == "PARM" and not got.autopilots:
        got.autopilots[0] = "ardupilot"


def read_flight_log(path: Path) -> FlightLog:
    """Read a ``.tlog`` or DataFlash ``.bin`` log of one flight; see the module docstring.

    Raises
    ------
    SettingsError
        One line naming the log: not a log of these kinds, no position, several vehicles,
        no photo message.
    """
    kind = _kind(path)
    _check_file(path)
    got = _Gathered()
    read = _from_tlog if kind == "tlog" else _from_dataflash
    count = 0
    try:
        for message in _messages(path, kind):
            count += 1
            stamp = getattr(message, "_timestamp", math.nan)
            if math.isfinite(stamp):
                if not math.isfinite(got.first_s):
                    got.first_s = stamp
                got.last_s = stamp
            read(message, got)
    except SettingsError:
        raise
    except (struct.error, ValueError, IndexError, KeyError, TypeError, AttributeError) as exc:
        if count == 0:
            raise _refuse(path, f"is not a {kind} log ({type(exc).__name__})") from None
        got.damaged += 1
    except OSError as exc:
        raise _refuse(path, f"cannot be read ({exc.strerror or exc})", "check the file") from None
    vehicles = got.autopilots
    if count == 0 or (not got.track and not vehicles):
        raise _refuse(path, f"holds no MAVLink {'telemetry' if kind == 'tlog' else 'DataFlash'}")
    if len(vehicles) > 1:
        listed = ", ".join(f"{s} ({a})" for s, a in sorted(vehicles.items()))
        raise _refuse(
            path,
            f"holds several vehicles (MAVLink systems {listed})",
            "give a log of the one vehicle that flew this plan",
        )
    if not got.track:
        raise _refuse(path, "holds no position of the vehicle", "give the log of the flight")
    photos = list(got.photos.values())
    if not photos and got.triggers:
        photos = list(got.triggers.values())
    if not photos:
        names = "CAMERA_FEEDBACK or CAMERA_IMAGE_CAPTURED" if kind == "tlog" else "CAM or TRIG"
        raise _refuse(
            path,
            f"holds no photo message ({names})",
            "check that the camera reports its photos (ArduPilot: a camera set up with "
            "CAM1_TYPE; PX4: TRIG_MODE 1) and that the log covers the flight",
        )
    photos.sort(key=lambda p: (p.time_s, p.index))
    system, autopilot = next(iter(vehicles.items()), (0, "unknown"))
    warnings = []
    if got.armed:
        warnings.append(
            f"the log ends with the vehicle still armed, {got.track[-1].alt_rel_m:.0f} m above "
            "home: it may be cut short, and photos after its end are not in it"
        )
    if got.damaged:
        warnings.append(f"{got.damaged} damaged message(s) were skipped")
    mission = tuple(got.mission[k] for k in sorted(got.mission))
    return FlightLog(
        path,
        kind,
        autopilot,
        system,
        got.firmware,
        tuple(photos),
        tuple(got.track),
        mission,
        got.armed,
        got.damaged,
        got.last_s - got.first_s if math.isfinite(got.first_s) else 0.0,
        tuple(warnings),
    )
