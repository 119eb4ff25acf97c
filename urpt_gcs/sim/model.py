"""The simulated copter: arming, ArduCopter modes and a kinematic flight model.

No sockets here: :meth:`Vehicle.step` advances simulated time, the ``command``/``set_mode``
methods are what COMMAND_LONG and SET_MODE do, and what the vehicle has to say (status text,
mission progress, photos) collects in :attr:`Vehicle.events` for the server to send.

The copter flies straight lines from rest to rest, a leg that changes height on the 3-D line
between its ends as ArduCopter's waypoint controller does (its horizontal speed held down so
that the climb or descent keeps within its limits): horizontally on an S-curve of speed, as
ArduCopter 4.x does, its acceleration built up at ``WPNAV_JERK`` and held within
``WPNAV_ACCEL``, with the mission's DO_CHANGE_SPEED (else ``WPNAV_SPEED``) between, and it
returns home at ``RTL_SPEED`` (else ``WPNAV_SPEED``: ArduCopter's RTL starts its waypoint
controller afresh, whatever the mission set); vertically it climbs at ``WPNAV_SPEED_UP``
and descends at ``WPNAV_SPEED_DN`` and, below ``LAND_ALT_LOW``, at ``LAND_SPEED``, changing
its climb rate at ``WPNAV_ACCEL_Z``. It reaches each waypoint exactly, and disarms
:data:`LAND_DETECT_S` after touching down. Positions are metres east/north of home on a
sphere of the WGS84 equatorial radius, as ArduPilot's Location does.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.sim.autopilot import Plan, SCurve, Step, mission_steps, rtl_steps
from urpt_gcs.sim.events import Current, Event, Photo, PhotoTaken, Reached, Text
from urpt_gcs.sim.params import (
    AUTO_OPTION_ALLOW_ARMING,
    AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE,
    Params,
)
from urpt_gcs.sim.settings import VehicleSettings
from urpt_gcs.sim.store import Home, MissionStore

__all__ = [
    "EARTH_RADIUS_M",
    "FORCE_DISARM",
    "HOVER_MODES",
    "LAND_DETECT_S",
    "NOT_ARMABLE",
    "USER_TAKEOFF_MODES",
    "Vehicle",
    "mode_name",
]

EARTH_RADIUS_M = 6_378_137.0
# ArduCopter's land detector: on ArduCopter 4.7 SITL the disarm after an RTL came 2.5-3.1 s
# after the copter reached the ground.
LAND_DETECT_S = 3.0
# COMPONENT_ARM_DISARM param2 that forces a disarm in flight.
FORCE_DISARM = 21196.0
HOVER_MODES = frozenset(
    {
        mavlink.COPTER_MODE_STABILIZE,
        mavlink.COPTER_MODE_ALT_HOLD,
        mavlink.COPTER_MODE_LOITER,
        mavlink.COPTER_MODE_POSHOLD,
        mavlink.COPTER_MODE_BRAKE,
        mavlink.COPTER_MODE_GUIDED,
    }
)
# ArduCopter's modes whose allows_arming() is false (BRAKE: MAVSDK's "Hold" on a copter).
NOT_ARMABLE = frozenset(
    {mavlink.COPTER_MODE_RTL, mavlink.COPTER_MODE_LAND, mavlink.COPTER_MODE_BRAKE}
)
USER_TAKEOFF_MODES = frozenset(
    {mavlink.COPTER_MODE_GUIDED, mavlink.COPTER_MODE_LOITER, mavlink.COPTER_MODE_POSHOLD}
)


def mode_name(mode: int) -> str:
    """ArduCopter's name for a custom mode, as its messages say it ("BRAKE")."""
    entry = mavlink.enums["COPTER_MODE"].get(mode)
    return entry.name.removeprefix("COPTER_MODE_") if entry is not None else str(mode)


class Vehicle:
    """State and behaviour of the simulated copter.

    Parameters
    ----------
    settings
        Home, capacity, firmware flavour and the mission fault flag.
    """

    def __init__(self, settings: VehicleSettings) -> None:
        self.settings = settings
        home = settings.home
        self.params = Params(px4=settings.px4)
        self.store = MissionStore(
            Home(round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), home.amsl_m),
            settings.capacity,
            px4=settings.px4,
        )
        self.store.corrupt_seq = settings.corrupt_seq
        self.arm_refusals_left = settings.arm_refusals
        self.time_s = 0.0
        self.armed = False
        self.mode = int(mavlink.COPTER_MODE_STABILIZE)
        self.east_m = self.north_m = self.alt_m = 0.0
        self.velocity = (0.0, 0.0, 0.0)  # east, north, up; m/s
        self.ground_speed_m_s = 0.0
        self.climb_rate_m_s = 0.0
        self.auto_armed = False
        self.landed_for_s = 0.0
        self.speed_m_s: float | None = None
        self.photos: list[Photo] = []
        # Heading, degrees clockwise from north; turned by CONDITION_YAW (at once: the turn
        # itself is not simulated).
        self.heading_deg = 0.0
        self.events: list[Event] = []
        self.current_seq = 0
        self._resume_seq: int | None = None
        self._plan: Plan | None = None
        self._guided: Step | None = None

    # --- where the vehicle is ----------------------------------------------------------

    @property
    def landed(self) -> bool:
        """On the ground (at home's altitude: the simulator has no terrain)."""
        return self.alt_m <= 1e-6

    def to_latlon_e7(self, east_m: float, north_m: float) -> tuple[int, int]:
        """Degrees * 1e7 of a point east/north of home."""
        home = self.settings.home
        lat = home.lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
        scale = EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg))
        lon = home.lon_deg + math.degrees(east_m / scale)
        return round(lat * 1e7), round(lon * 1e7)

    def to_east_north(self, lat_e7: int, lon_e7: int) -> tuple[float, float]:
        """Metres east and north of home of a point in degrees * 1e7."""
        home = self.settings.home
        north = math.radians(lat_e7 * 1e-7 - home.lat_deg) * EARTH_RADIUS_M
        scale = EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg))
        east = math.radians(lon_e7 * 1e-7 - home.lon_deg) * scale
        return east, north

    @property
    def position_e7(self) -> tuple[int, int]:
        """Where the copter is, degrees * 1e7."""
        return self.to_latlon_e7(self.east_m, self.north_m)

    @property
    def amsl_m(self) -> float:
        """Altitude above mean sea level."""
        return self.settings.home.amsl_m + self.alt_m

    # --- speeds from parameters --------------------------------------------------------

    def cruise_m_s(self) -> float:
        """Horizontal speed: DO_CHANGE_SPEED's, else WPNAV_SPEED."""
        return self.speed_m_s or self.params["WPNAV_SPEED"] / 100.0

    def accel_m_s2(self) -> float:
        """WPNAV_ACCEL in m/s/s."""
        return self.params["WPNAV_ACCEL"] / 100.0

    def jerk_m_s3(self) -> float:
        """WPNAV_JERK in m/s/s/s."""
        return self.params["WPNAV_JERK"]

    def climb_accel_m_s2(self) -> float:
        """WPNAV_ACCEL_Z in m/s/s."""
        return self.params["WPNAV_ACCEL_Z"] / 100.0

    def climb_m_s(self) -> float:
        """WPNAV_SPEED_UP in m/s."""
        return self.params["WPNAV_SPEED_UP"] / 100.0

    def descent_m_s(self, landing: bool) -> float:
        """WPNAV_SPEED_DN, or LAND_SPEED on the last LAND_ALT_LOW of a landing."""
        if landing and self.alt_m <= self.params["LAND_ALT_LOW"] / 100.0:
            return self.params["LAND_SPEED"] / 100.0
        return self.params["WPNAV_SPEED_DN"] / 100.0

    # --- commands ------------------------------------------------------------------------

    def say(self, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        """Queue a STATUSTEXT."""
        self.events.append(Text(severity, text))

    def booting(self, now_wall_s: float) -> bool:
        """Still in the start-up window (``boot_s``, wall seconds since start)."""
        return now_wall_s < self.settings.boot_s

    def arm(self, now_wall_s: float) -> int:
        """COMPONENT_ARM_DISARM with param1 = 1."""
        if self.armed:
            return int(mavlink.MAV_RESULT_ACCEPTED)
        auto_ok = int(self.params["AUTO_OPTIONS"]) & AUTO_OPTION_ALLOW_ARMING
        if self.booting(now_wall_s):
            self.say("PreArm: waiting for position estimate", mavlink.MAV_SEVERITY_CRITICAL)
            return int(mavlink.MAV_RESULT_FAILED)
        if self.arm_refusals_left > 0:
            self.arm_refusals_left -= 1
            self.say("PreArm: gyros still settling", mavlink.MAV_SEVERITY_CRITICAL)
            return int(mavlink.MAV_RESULT_FAILED)
        if self.mode in NOT_ARMABLE or (self.mode == mavlink.COPTER_MODE_AUTO and not auto_ok):
            self.say(f"Arm: {mode_name(self.mode)} mode not armable", mavlink.MAV_SEVERITY_CRITICAL)
            return int(mavlink.MAV_RESULT_FAILED)
        self.armed = True
        self.auto_armed = False
        self.landed_for_s = 0.0
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def disarm(self, force: bool = False, why: str = "") -> int:
        """COMPONENT_ARM_DISARM with param1 = 0; refused in flight unless forced."""
        if not self.armed:
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if not self.landed and not force:
            self.say("Disarm: vehicle is flying", mavlink.MAV_SEVERITY_CRITICAL)
            return int(mavlink.MAV_RESULT_FAILED)
        self.armed = False
        self.auto_armed = False
        self.alt_m = max(self.alt_m, 0.0)
        self.velocity = (0.0, 0.0, 0.0)
        self.say(f"Disarming motors{': ' + why if why else ''}")
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def set_mode(self, mode: int) -> bool:
        """Switch to an ArduCopter custom mode; False if the mode refuses (PX4: always)."""
        if self.settings.px4:
            return False
        if mode == mavlink.COPTER_MODE_AUTO:
            if len(self.store) <= self.store.first_seq:
                self.say("Auto: Missing mission", mavlink.MAV_SEVERITY_CRITICAL)
                return False
            first = self.store.read(self.store.first_seq)
            if self.armed and self.landed and first.command != mavlink.MAV_CMD_NAV_TAKEOFF:
                self.say("Auto: Missing Takeoff Cmd", mavlink.MAV_SEVERITY_CRITICAL)
                return False
            self.mode = mode
            # ModeAuto::init forgets an earlier DO_CHANGE_SPEED (desired_speed_override).
            self.speed_m_s = None
            self._start_mission()
            return True
        if mode in HOVER_MODES | {mavlink.COPTER_MODE_RTL, mavlink.COPTER_MODE_LAND}:
            self.mode = mode
            self._plan = None
            self._guided = Step(self.east_m, self.north_m, self.alt_m)
            if mode == mavlink.COPTER_MODE_RTL and not self.landed:
                self._plan = Plan(seq=None, steps=rtl_steps(self))
            elif mode in (mavlink.COPTER_MODE_RTL, mavlink.COPTER_MODE_LAND):
                # On the ground both only land, which disarms an armed copter.
                self._plan = Plan(seq=None, steps=[Step(None, None, 0.0, land=True)])
            return True
        return False

    def takeoff(self, alt_m: float) -> int:
        """NAV_TAKEOFF as a command (GUIDED take-off)."""
        if not (self.armed and self.landed and self.mode in USER_TAKEOFF_MODES):
            return int(mavlink.MAV_RESULT_FAILED)
        if not (math.isfinite(alt_m) and alt_m > 0.0):
            return int(mavlink.MAV_RESULT_FAILED)
        self._guided = Step(self.east_m, self.north_m, alt_m)
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def mission_start(self, first: float, last: float) -> int:
        """MAV_CMD_MISSION_START: ArduCopter switches to AUTO and allows the take-off."""
        if first != 0.0 or last != 0.0:
            return int(mavlink.MAV_RESULT_DENIED)
        if not self.armed or not self.set_mode(mavlink.COPTER_MODE_AUTO):
            return int(mavlink.MAV_RESULT_FAILED)
        self.auto_armed = True
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT: fly ``seq`` next (now, if in AUTO)."""
        if not self.store.first_seq <= seq < len(self.store):
            return False
        self._resume_seq = seq
        self.current_seq = seq
        if self.mode == mavlink.COPTER_MODE_AUTO:
            self._start_mission()
        else:
            self.events.append(Current(seq))
        return True

    def take_photo(self) -> None:
        """Record a photo here and queue its CAMERA_FEEDBACK."""
        lat, lon = self.position_e7
        photo = Photo(
            len(self.photos) + 1, self.time_s, lat, lon, self.amsl_m, self.alt_m, self.heading_deg
        )
        self.photos.append(photo)
        self.events.append(PhotoTaken(photo))

    # --- flying ---------------------------------------------------------------------------

    def _start_mission(self) -> None:
        start = self._resume_seq if self._resume_seq is not None else self.store.first_seq
        self._resume_seq = None
        self._plan = mission_steps(self, start)

    def _mission_complete(self) -> None:
        self._plan = None
        self.say("Mission complete")
        if self.landed:
            self.disarm(why="mission complete")
        else:
            self._guided = Step(self.east_m, self.north_m, self.alt_m)

    def step(self, dt_s: float) -> None:
        """Advance simulated time by ``dt_s`` seconds."""
        self.time_s += dt_s
        if not self.armed:
            self.velocity = (0.0, 0.0, 0.0)
            return
        if self._plan is not None:
            self._fly_plan(dt_s)
        elif self._guided is not None:
            self._move(self._guided, dt_s)
        else:
            self.velocity = (0.0, 0.0, 0.0)
        if self.armed and self.landed and self.velocity[2] <= 0.0:
            self.landed_for_s += dt_s
            if self.landed_for_s >= self.params["DISARM_DELAY"] > 0:
                self.disarm(why="auto-disarm")
        else:
            self.landed_for_s = 0.0

    def _fly_plan(self, dt_s: float) -> None:
        plan = self._plan
        assert plan is not None
        if not plan.steps:
            finished = plan.seq
            if finished is not None:
                self.events.append(Reached(finished))
                self._plan = mission_steps(self, finished + 1)
                if self._plan is None:
                    self._mission_complete()
            else:
                self._plan = None
                self._guided = Step(self.east_m, self.north_m, self.alt_m)
            return
        step = plan.steps[0]
        may_take_off = self.auto_armed or self.takeoff_allowed_in_auto()
        if step.takeoff and self.landed and not may_take_off:
            # ArduCopter waits for the pilot's throttle (or AUTO_OPTIONS bit 1).
            self.velocity = (0.0, 0.0, 0.0)
            return
        if step.takeoff:
            self.auto_armed = True
        if step.hold_s > 0.0 and step.arrived:
            step.hold_s -= dt_s
            self.velocity = (0.0, 0.0, 0.0)
            if step.hold_s <= 0.0:
                plan.steps.pop(0)
            return
        if step.land and step.arrived:
            # On the ground: ArduCopter disarms once its land detector agrees, in LAND/RTL.
            step.landed_s += dt_s
            self.velocity = (0.0, 0.0, 0.0)
            if step.landed_s >= LAND_DETECT_S:
                if plan.seq is not None:
                    self.events.append(Reached(plan.seq))
                self._plan = None
                self.disarm(why="landed")
            return
        if self._move(step, dt_s):
            step.arrived = True
            if not step.land and step.hold_s <= 0.0:
                plan.steps.pop(0)

    def _move(self, step: Step, dt_s: float) -> bool:
        """Move toward a step's target; True once there."""
        east = self.east_m if step.east_m is None else step.east_m
        north = self.north_m if step.north_m is None else step.north_m
        de, dn = east - self.east_m, north - self.north_m
        distance = math.hypot(de, dn)
        if step.profile is None and distance > 0.0:
            speed, accel = step.speed_m_s or self.cruise_m_s(), self.accel_m_s2()
            rise = step.alt_m - self.alt_m
            if rise != 0.0 and not step.land:
                # Along the 3-D line: the horizontal speed and acceleration held down so
                # that the climb or descent keeps within its own limits.
                rate = self.climb_m_s() if rise > 0 else self.descent_m_s(False)
                ratio = distance / abs(rise)
                speed = min(speed, rate * ratio)
                accel = min(accel, self.climb_accel_m_s2() * ratio)
                step.start_alt_m, step.start_distance_m = self.alt_m, distance
            step.profile = SCurve.for_leg(distance, speed, accel, self.jerk_m_s3())
        if step.profile is None or distance == 0.0:
            ve = vn = 0.0
            self.ground_speed_m_s = 0.0
        else:
            profile = step.profile
            before = profile.speed_at(step.leg_s)
            step.leg_s += dt_s
            speed = profile.speed_at(step.leg_s)
            step.along_m += 0.5 * (before + speed) * dt_s
            left = profile.length_m - step.along_m
            if step.leg_s >= profile.duration_s or left <= 0.0:
                ve, vn = de / dt_s, dn / dt_s
                self.east_m, self.north_m = east, north
                self.ground_speed_m_s = 0.0
                distance = 0.0
            else:
                # Along the line from here to the target, so the target is met exactly.
                step_m = max(distance - left, 0.0)
                ve, vn = de / distance * speed, dn / distance * speed
                self.east_m += de / distance * step_m
                self.north_m += dn / distance * step_m
                self.ground_speed_m_s = speed
                distance = left
        dz = step.alt_m - self.alt_m
        if step.land:
            vz = self._descend(dt_s) if distance == 0.0 else 0.0  # over the point first
        elif step.start_alt_m is not None:
            # On the line: the height in proportion to the horizontal way flown.
            done = 1.0 - distance / step.start_distance_m
            alt = step.start_alt_m + (step.alt_m - step.start_alt_m) * done
            vz = (alt - self.alt_m) / dt_s
            self.alt_m = step.alt_m if distance == 0.0 else alt
            self.climb_rate_m_s = 0.0 if distance == 0.0 else vz
        elif dz == 0.0:
            vz = self.climb_rate_m_s = 0.0
        else:
            if step.climb is None:
                rate = self.climb_m_s() if dz > 0 else self.descent_m_s(False)
                step.climb = SCurve.for_leg(abs(dz), rate, self.climb_accel_m_s2(), math.inf)
            before = step.climb.speed_at(step.climb_s)
            step.climb_s += dt_s
            now = step.climb.speed_at(step.climb_s)
            step.climbed_m += 0.5 * (before + now) * dt_s
            if step.climb_s >= step.climb.duration_s or step.climbed_m >= step.climb.length_m:
                vz, self.alt_m = dz / dt_s, step.alt_m
            else:
                vz = math.copysign(now, dz)
                self.alt_m = step.alt_m - math.copysign(step.climb.length_m - step.climbed_m, dz)
            self.climb_rate_m_s = 0.0 if self.alt_m == step.alt_m else vz
        self.velocity = (ve, vn, vz)
        return distance == 0.0 and abs(step.alt_m - self.alt_m) <= 1e-6

    def _descend(self, dt_s: float) -> float:
        """A landing's descent: from rest down at WPNAV_SPEED_DN, then LAND_SPEED, reaching
        the ground at that speed; the rate changes within WPNAV_ACCEL_Z. The vertical speed."""
        change = self.climb_accel_m_s2() * dt_s
        before = self.climb_rate_m_s
        vz = max(-self.descent_m_s(True), before - change)
        vz = min(vz, before + change)
        self.alt_m = max(self.alt_m + 0.5 * (before + vz) * dt_s, 0.0)
        self.climb_rate_m_s = 0.0 if self.alt_m == 0.0 else vz
        return vz

    def mission_item_alt(self, frame: int, z: float) -> float:
        """An item's altitude as metres above home."""
        if frame in (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT):
            return z - self.settings.home.amsl_m
        return z

    def auto_options(self) -> int:
        """The AUTO_OPTIONS bit mask."""
        return int(self.params["AUTO_OPTIONS"])

    def takeoff_allowed_in_auto(self) -> bool:
        """AUTO_OPTIONS bit 1: AUTO may take off without the pilot's throttle."""
        return bool(self.auto_options() & AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE)
