"""Telemetry of the simulated vehicle: message builders and the streams a GCS asks for.

Like ArduPilot, nothing but HEARTBEAT (and STATUSTEXT) is sent until a ground station asks
for rates with REQUEST_DATA_STREAM or MAV_CMD_SET_MESSAGE_INTERVAL; a single message can be
asked for with MAV_CMD_REQUEST_MESSAGE. Stream periods are in simulated seconds, as in
ArduPilot's SITL, so a speed-up sends proportionally more messages per wall second.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.sim.model import Vehicle

__all__ = [
    "BUILDERS",
    "CAPABILITIES",
    "DEFAULT_PERIOD_S",
    "FLIGHT_SW_VERSION",
    "HEARTBEAT_PERIOD_S",
    "PX4_AUTO_LOITER",
    "SENSORS",
    "STREAM_GROUPS",
    "Builder",
    "Message",
    "Streams",
    "attitude",
    "autopilot_version",
    "extended_sys_state",
    "global_position_int",
    "gps_raw_int",
    "heartbeat",
    "home_position",
    "mission_current",
    "sys_status",
    "system_time",
    "vfr_hud",
]

Message = Any
Builder = Callable[[mavlink.MAVLink, Vehicle], Message]

# ArduPilot 4.6.0, official release: major << 24 | minor << 16 | patch << 8 | type.
FLIGHT_SW_VERSION = (4 << 24) | (6 << 16) | (0 << 8) | mavlink.FIRMWARE_VERSION_TYPE_OFFICIAL
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    # As ArduPilot reports its pre-arm checks passing (AP_Notify's pre_arm_check).
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
# PX4 custom mode: main mode in bits 16-23, sub mode in bits 24-31 (AUTO.LOITER).
PX4_AUTO_LOITER = (4 << 16) | (3 << 24)


def _ms(vehicle: Vehicle) -> int:
    return int(vehicle.time_s * 1000.0) & 0xFFFFFFFF


def heartbeat(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """HEARTBEAT: quadrotor, ArduPilot (or PX4), custom mode, armed flag."""
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    if vehicle.armed:
        base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    if vehicle.mode in (mavlink.COPTER_MODE_AUTO, mavlink.COPTER_MODE_GUIDED):
        base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    if vehicle.settings.px4:
        autopilot, custom = mavlink.MAV_AUTOPILOT_PX4, PX4_AUTO_LOITER
    else:
        autopilot, custom = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, vehicle.mode
    state = mavlink.MAV_STATE_ACTIVE if vehicle.armed else mavlink.MAV_STATE_STANDBY
    return mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, autopilot, base, custom, state)


def sys_status(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """SYS_STATUS: healthy sensors, a full battery."""
    return mav.sys_status_encode(
        SENSORS, SENSORS, SENSORS, 250, 12_600, 1_000 if vehicle.armed else 0, 100, 0, 0, 0, 0, 0, 0
    )


def gps_raw_int(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """GPS_RAW_INT: a 3D fix at the vehicle's position."""
    lat, lon = vehicle.position_e7
    ve, vn, _ = vehicle.velocity
    speed = math.hypot(ve, vn)
    cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) if speed > 0.1 else 0
    return mav.gps_raw_int_encode(
        int(vehicle.time_s * 1e6),
        mavlink.GPS_FIX_TYPE_3D_FIX,
        lat,
        lon,
        round(vehicle.amsl_m * 1000.0),
        70,
        90,
        round(speed * 100.0),
        cog,
        14,
    )


def global_position_int(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """GLOBAL_POSITION_INT: position, AMSL and relative altitude, velocity."""
    lat, lon = vehicle.position_e7
    ve, vn, vu = vehicle.velocity
    return mav.global_position_int_encode(
        _ms(vehicle),
        lat,
        lon,
        round(vehicle.amsl_m * 1000.0),
        round(vehicle.alt_m * 1000.0),
        round(vn * 100.0),
        round(ve * 100.0),
        round(-vu * 100.0),
        65535,
    )


def home_position(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """HOME_POSITION."""
    home = vehicle.store.home
    return mav.home_position_encode(
        home.lat_e7,
        home.lon_e7,
        round(home.amsl_m * 1000.0),
        0.0,
        0.0,
        0.0,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        int(vehicle.time_s * 1e6),
    )


def extended_sys_state(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """EXTENDED_SYS_STATE: the landed state MAVSDK's Action plugin asks for."""
    if vehicle.landed:
        landed = mavlink.MAV_LANDED_STATE_ON_GROUND
    elif vehicle.velocity[2] > 0.1:
        landed = (
            mavlink.MAV_LANDED_STATE_TAKEOFF
            if vehicle.alt_m < 2.0
            else mavlink.MAV_LANDED_STATE_IN_AIR
        )
    elif vehicle.velocity[2] < -0.1 and vehicle.alt_m < 2.0:
        landed = mavlink.MAV_LANDED_STATE_LANDING
    else:
        landed = mavlink.MAV_LANDED_STATE_IN_AIR
    return mav.extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)


def mission_current(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """MISSION_CURRENT: the mission item being flown."""
    return mav.mission_current_encode(vehicle.current_seq, max(len(vehicle.store) - 1, 0))


def attitude(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """ATTITUDE: level."""
    return mav.attitude_encode(_ms(vehicle), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def vfr_hud(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """VFR_HUD."""
    ve, vn, vu = vehicle.velocity
    speed = math.hypot(ve, vn)
    return mav.vfr_hud_encode(speed, speed, 0, 50 if vehicle.armed else 0, vehicle.amsl_m, vu)


def system_time(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """SYSTEM_TIME: wall-clock UTC, simulated time since boot."""
    return mav.system_time_encode(int(time.time() * 1e6), _ms(vehicle))


def autopilot_version(mav: mavlink.MAVLink, vehicle: Vehicle) -> Message:
    """AUTOPILOT_VERSION: MISSION_INT, COMMAND_INT, MAVLink 2 capabilities."""
    return mav.autopilot_version_encode(
        CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0
    )


BUILDERS: dict[int, Builder] = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: system_time,
    mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
}
# Messages in each REQUEST_DATA_STREAM group (the ones simulated).
STREAM_GROUPS: dict[int, tuple[int, ...]] = {
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mavlink.MAVLINK_MSG_ID_SYS_STATUS,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
        mavlink.MAVLINK_MSG_ID_MISSION_CURRENT,
    ),
    mavlink.MAV_DATA_STREAM_POSITION: (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,),
    mavlink.MAV_DATA_STREAM_EXTRA1: (mavlink.MAVLINK_MSG_ID_ATTITUDE,),
    mavlink.MAV_DATA_STREAM_EXTRA2: (mavlink.MAVLINK_MSG_ID_VFR_HUD,),
    mavlink.MAV_DATA_STREAM_EXTRA3: (
        mavlink.MAVLINK_MSG_ID_SYSTEM_TIME,
        mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    ),
}
STREAM_GROUPS[mavlink.MAV_DATA_STREAM_ALL] = tuple(
    msg_id for group in list(STREAM_GROUPS.values()) for msg_id in group
)
HEARTBEAT_PERIOD_S = 1.0
DEFAULT_PERIOD_S = 1.0


class Streams:
    """Which messages are streamed, at what period (simulated seconds), and when next."""

    def __init__(self) -> None:
        self._period: dict[int, float] = {mavlink.MAVLINK_MSG_ID_HEARTBEAT: HEARTBEAT_PERIOD_S}
        self._due: dict[int, float] = {mavlink.MAVLINK_MSG_ID_HEARTBEAT: 0.0}

    def set_interval(self, msg_id: int, interval_us: float, now_s: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 stops, 0 is the default rate. False if unknown."""
        if msg_id not in BUILDERS or msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return False
        if interval_us < 0:
            self._period.pop(msg_id, None)
            self._due.pop(msg_id, None)
            return True
        period = DEFAULT_PERIOD_S if interval_us == 0 else interval_us / 1e6
        self._period[msg_id] = period
        self._due[msg_id] = now_s
        return True

    def request_stream(self, stream_id: int, rate_hz: int, start: bool, now_s: float) -> None:
        """REQUEST_DATA_STREAM for one group; rate 0 or start 0 stops it."""
        for msg_id in STREAM_GROUPS.get(stream_id, ()):
            if start and rate_hz > 0:
                self.set_interval(msg_id, 1e6 / rate_hz, now_s)
            else:
                self.set_interval(msg_id, -1, now_s)

    def due(self, now_s: float) -> list[int]:
        """Messages to send now; each at most once per call."""
        out = []
        for msg_id, next_s in self._due.items():
            if next_s <= now_s:
                out.append(msg_id)
                period = self._period[msg_id]
                self._due[msg_id] = max(next_s + period, now_s + period / 2.0)
        return out
