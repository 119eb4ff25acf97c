"""Replay a fleet: K vehicles flown at once, each judged, together judged, kept apart.

:func:`fly_fleet` starts one vehicle per mission, each at its own home and on its own
loopback port: simulated copters in threads, or ArduCopter SITL processes
(:func:`urpt_gcs.replay.ardupilot.launch`, each its own instance, ports and scratch
folder). Each is flown through the same code as a single replay; they wait for each other
once every one is ready to arm (SYS_STATUS's pre-arm bit), then arm and start together. Every
simulator is stopped by its pid when the flight ends, fails or is interrupted.

:func:`replay_fleet` judges each flight on its own targets and clearance, all photos together
on every target (:func:`urpt_gcs.replay.judge.judge_set`), and measures the closest approach of
any two vehicles at equal times (:func:`closest_approach`). Equal times are the ground
station's clock: each position is timed by when it arrived, corrected for the delay of its
delivery (the lower envelope of arrival minus the vehicle's own clock), so vehicles whose
clocks started apart, or run at slightly different speeds, are compared at the same instant.
A vehicle the plan leaves idle is not flown; the report names it.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
from scipy.ndimage import minimum_filter1d

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import LinkError, MissionFileError, SettingsError
from urpt_gcs.files.fleet_folder import FleetFolder, FleetVehicle, Separation
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.flight.mission import Mission
from urpt_gcs.progress import Progress
from urpt_gcs.replay.ardupilot import launch
from urpt_gcs.replay.fly import (
    CONNECT_TIMEOUT_S,
    ReplaySettings,
    estimate_wall_timeout_s,
    fly_connected,
    free_udp_port,
)
from urpt_gcs.replay.judge import (
    ReplayReport,
    SetReport,
    expected_checks,
    judge,
    judge_set,
    set_report_text,
)
from urpt_gcs.replay.record import SIMULATED, Flight
from urpt_gcs.sim.server import SitlServer
from urpt_gcs.sim.settings import VehicleSettings
from urpt_gcs.site.dem import open_dem
from urpt_gcs.site.targets import read_targets
from urpt_gcs.vehicle.mavsdk_link import connect

__all__ = [
    "ALTITUDE_TOLERANCE_M",
    "DELAY_WINDOW",
    "ON_GROUND_M",
    "SAME_PAD_M",
    "Approach",
    "FleetReport",
    "closest_approach",
    "fleet_report_text",
    "fly_fleet",
    "replay_fleet",
    "required_separation_m",
]

# Altitude layers: a vehicle holds its altitude to well under a metre (ArduCopter SITL: 0.01 m
# at its photos); this much below the spacing is still separation.
ALTITUDE_TOLERANCE_M = 2.0
# Both vehicles this close to their homes' altitude are parked, not flying.
# Homes closer than this are one launch pad, used in turn.
SAME_PAD_M = 1.0
ON_GROUND_M = 1.0
# Positions whose delivery delay is estimated together (about half a second at 20x).
DELAY_WINDOW = 101
_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


@dataclass(frozen=True, slots=True)
class Approach:
    """The closest two vehicles came at equal times.

    ``time_s`` is on the first vehicle of ``pair``'s own clock, seconds after its take-off;
    ``lat_deg``, ``lon_deg`` the midpoint between them.
    """

    pair: tuple[int, int]
    distance_m: float
    horizontal_m: float
    vertical_m: float
    time_s: float
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True, slots=True)
class FleetReport:
    """The verdict on a fleet's replay."""

    vehicles: tuple[FleetVehicle, ...]
    together: SetReport
    separation: Separation
    required_m: float
    approach: Approach | None
    takeoff_wall_s: tuple[float, ...]
    wall_time_s: float
    problems: tuple[str, ...]
    idle: tuple[FleetVehicle, ...] = ()

    @property
    def ok(self) -> bool:
        """Every flight passed, every target was seen, and the vehicles kept apart."""
        return self.together.ok and not self.problems


def required_separation_m(separation: Separation) -> float:
    """The least closest approach that passes: the layer spacing less
    :data:`ALTITUDE_TOLERANCE_M`, or the horizontal minimum of a time-separated plan."""
    if separation.mode == "altitude":
        return separation.min_m - ALTITUDE_TOLERANCE_M
    return separation.min_m


def fly_fleet(
    missions: Sequence[Mission],
    settings: ReplaySettings,
    progress: Progress | None = None,
    start_delays_s: Sequence[float] | None = None,
) -> list[Flight]:
    """Fly every mission at once, one vehicle each, in mission order; vehicle ``k`` arms
    ``start_delays_s[k]`` simulated seconds after the common start (all at once if None),
    counted from when the vehicle planned just before it really armed.

    Raises
    ------
    SettingsError
        For a PX4 mission, or settings that name one vehicle (``--connect``, ``--px4``).
    LinkError
        Naming the vehicle, if any upload is not verified or any flight is not completed;
        the other vehicles are then stopped too.
    """
    if settings.connect is not None or settings.px4 is not None:
        raise SettingsError(
            "a fleet replay starts its own vehicles: give --ardupilot PATH or nothing (the "
            "simulated copters), not --connect or --px4"
        )
    for number, mission in enumerate(missions, start=1):
        if mission.firmware != "ardupilot":
            raise SettingsError(
                f"vehicle {number}'s mission is for PX4: a fleet replay flies ArduCopters; "
                "plan the fleet with --firmware ardupilot"
            )
    say = progress or (lambda _msg: None)
    timeout_s = settings.timeout_s or max(estimate_wall_timeout_s(m, settings) for m in missions)
    with contextlib.ExitStack() as running:
        places: list[tuple[str, str]] = []
        for number, mission in enumerate(missions, start=1):
            places.append(_start_vehicle(running, number, mission, settings, say))
        delays = list(start_delays_s) if start_delays_s is not None else [0.0] * len(missions)
        return asyncio.run(_fly_all(places, missions, settings, timeout_s, say, delays))


def _start_vehicle(
    running: contextlib.ExitStack,
    number: int,
    mission: Mission,
    settings: ReplaySettings,
    say: Progress,
) -> tuple[str, str]:
    """Start vehicle ``number`` at its home; (MAVSDK url, what it is)."""
    if settings.ardupilot is not None:
        sitl = running.enter_context(launch(settings.ardupilot, mission.home, settings.speedup))
        say(f"vehicle {number}: ArduCopter SITL instance {sitl.instance} (pid {sitl.pid})")
        return sitl.url, f"ArduCopter SITL, pid {sitl.pid}, instance {sitl.instance}"
    port = free_udp_port()
    vehicle = VehicleSettings(home=mission.home, speedup=settings.speedup, system_id=number)
    running.enter_context(SitlServer(vehicle, f"udpout://127.0.0.1:{port}"))
    say(f"vehicle {number}: simulated ArduCopter on udp 127.0.0.1:{port}")
    return f"udpin://127.0.0.1:{port}", SIMULATED


class _TogetherGate:
    """Lets every vehicle through once all of them have arrived."""

    def __init__(self, count: int) -> None:
        self.count = count
        self.arrived = 0
        self.open = asyncio.Event()

    async def wait(self) -> None:
        self.arrived += 1
        if self.arrived >= self.count:
            self.open.set()
        await self.open.wait()


async def _fly_all(
    places: Sequence[tuple[str, str]],
    missions: Sequence[Mission],
    settings: ReplaySettings,
    timeout_s: float,
    say: Progress,
    delays_s: Sequence[float],
) -> list[Flight]:
    gate = _TogetherGate(len(missions))
    armed = [asyncio.Event() for _ in missions]

    async def one(number: int, url: str, where: str, mission: Mission) -> Flight:
        prefix = f"vehicle {number}: "
        delay_s = delays_s[number - 1]
        # The stagger is kept from the take-off before it as it really happened: a vehicle
        # waits for those planned before it to be armed (one that was slow to arm would
        # otherwise fly in the gap the plan left), then its own difference.
        earlier = [k for k, d in enumerate(delays_s) if d < delay_s]
        after = max(earlier, key=lambda k: delays_s[k], default=None)

        async def ready() -> None:
            await gate.wait()
            if after is not None:
                await armed[after].wait()

        try:
            async with connect(url, CONNECT_TIMEOUT_S) as link:
                return await fly_connected(
                    link,
                    mission,
                    settings,
                    timeout_s + delay_s / settings.speedup,
                    lambda m: say(prefix + m),
                    where,
                    ready,
                    delay_s if after is None else delay_s - delays_s[after],
                    armed[number - 1].set,
                )
        except LinkError as exc:
            raise LinkError(f"vehicle {number}: {exc}") from None

    tasks = [
        asyncio.create_task(one(n, url, where, m))
        for n, ((url, where), m) in enumerate(zip(places, missions, strict=True), start=1)
    ]
    try:
        done, _pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
        for task in done:
            if task.exception() is not None:
                raise task.exception()  # type: ignore[misc]
        return [task.result() for task in tasks]
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


@dataclass(frozen=True, slots=True)
class _Track:
    """One vehicle's positions on the common clock, in time order."""

    time_s: FloatArray  # ground station's clock (wall seconds)
    ecef: FloatArray  # (n, 3) metres
    rel_m: FloatArray  # above home
    lat_deg: FloatArray
    lon_deg: FloatArray
    amsl_m: FloatArray
    own_s: FloatArray  # the vehicle's own clock

    def at(self, field: FloatArray, t: FloatArray | float) -> FloatArray:
        return np.asarray(np.interp(t, self.time_s, field), dtype=np.float64)

    def position(self, t: FloatArray) -> FloatArray:
        return np.column_stack([self.at(self.ecef[:, k], t) for k in range(3)])


def _send_times(flight: Flight) -> FloatArray:
    """Each position's time on the ground station's clock, its delivery delay taken off.

    Locally the vehicle's clock runs at a steady rate against the ground station's (a SITL
    that cannot keep its speed-up runs slower, not unevenly), so within a window of
    :data:`DELAY_WINDOW` positions arrival is fitted as a line of the vehicle's clock, and
    the line is lowered onto the earliest arrivals: delivery only ever adds delay.
    """
    wall = np.array([p.wall_s for p in flight.track], dtype=np.float64)
    own = np.array([p.time_s for p in flight.track], dtype=np.float64)
    # Centred, so the window sums below lose no precision.
    x, y = own - own.mean(), wall - wall.mean()
    half = DELAY_WINDOW // 2
    lo = np.clip(np.arange(len(x)) - half, 0, len(x))
    hi = np.clip(np.arange(len(x)) + half + 1, 0, len(x))

    def window_sum(values: FloatArray) -> FloatArray:
        total = np.concatenate([[0.0], np.cumsum(values)])
        return np.asarray(total[hi] - total[lo], dtype=np.float64)

    count = (hi - lo).astype(np.float64)
    mean_x, mean_y = window_sum(x) / count, window_sum(y) / count
    spread = window_sum(x * x) / count - mean_x**2
    cross = window_sum(x * y) / count - mean_x * mean_y
    rate = np.where(spread > 1e-12, cross / np.maximum(spread, 1e-12), 0.0)
    line = mean_y + rate * (x - mean_x)
    lowered = minimum_filter1d(y - line, size=2 * half + 1, mode="nearest")
    return np.asarray(line + lowered + wall.mean(), dtype=np.float64)


def _track(flight: Flight, ground_m: float) -> _Track | None:
    if len(flight.track) < 2:
        return None
    t = _send_times(flight)
    order = np.argsort(t, kind="stable")
    lat = np.array([p.lat_deg for p in flight.track], dtype=np.float64)[order]
    lon = np.array([p.lon_deg for p in flight.track], dtype=np.float64)[order]
    rel = np.array([p.alt_rel_m for p in flight.track], dtype=np.float64)[order]
    own = np.array([p.time_s for p in flight.track], dtype=np.float64)[order]
    x, y, z = _ECEF.transform(lon, lat, ground_m + rel)
    ecef = np.column_stack([x, y, z]).astype(np.float64)
    return _Track(t[order], ecef, rel, lat, lon, ground_m + rel, own)


def _takeoff(track: _Track | None) -> int | None:
    """The index of the first position in the air."""
    if track is None or not (track.rel_m > ON_GROUND_M).any():
        return None
    return int(np.argmax(track.rel_m > ON_GROUND_M))


def _same_pad(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether two planned homes (lat, lon) are one pad (within :data:`SAME_PAD_M`): the
    missions' homes, not the first fixes, which a simulator's GPS places a little apart."""
    north = (a[0] - b[0]) * 111_132.0
    east = (a[1] - b[1]) * 111_320.0 * math.cos(math.radians(a[0]))
    return math.hypot(north, east) <= SAME_PAD_M


def closest_approach(
    flights: Sequence[Flight],
    homes_amsl_m: Sequence[float],
    pads: Sequence[tuple[float, float]] | None = None,
) -> tuple[Approach | None, tuple[float, ...]]:
    """The closest 3-D approach of any two vehicles at equal times, while at least one of
    them flies (both, for two from one home: they use its pad in turn); and each vehicle's
    take-off, in wall seconds after the first (NaN for one that never took off).

    Positions are compared on one clock (see the module docstring), each track linearly
    interpolated at the other's sample times.
    """
    tracks = [_track(f, ground) for f, ground in zip(flights, homes_amsl_m, strict=True)]
    lifts = [_takeoff(t) for t in tracks]
    airborne = np.array(
        [
            t.time_s[k] if t is not None and k is not None else math.nan
            for t, k in zip(tracks, lifts, strict=True)
        ],
        dtype=np.float64,
    )
    first = float(np.nanmin(airborne)) if np.isfinite(airborne).any() else math.nan
    takeoff = tuple(float(a - first) for a in airborne)
    best: Approach | None = None
    for i, a in enumerate(tracks):
        for j in range(i + 1, len(tracks)):
            b = tracks[j]
            if a is None or b is None:
                continue
            lo, hi = max(a.time_s[0], b.time_s[0]), min(a.time_s[-1], b.time_s[-1])
            times = np.union1d(a.time_s, b.time_s)
            times = times[(times >= lo) & (times <= hi)]
            up_a, up_b = a.at(a.rel_m, times) > ON_GROUND_M, b.at(b.rel_m, times) > ON_GROUND_M
            # Vehicles sharing a home share its pad and take off and land there in turn (as
            # planned, by their start delays): the one waiting is not on the pad.
            one_pad = pads is not None and _same_pad(pads[i], pads[j])
            flying = (up_a & up_b) if one_pad else (up_a | up_b)
            if not flying.any():
                continue
            gap = np.linalg.norm(a.position(times) - b.position(times), axis=1)
            gap[~flying] = np.inf
            k = int(np.argmin(gap))
            if best is not None and gap[k] >= best.distance_m:
                continue
            t = float(times[k])
            lift = lifts[i]
            start = a.own_s[lift] if lift is not None else a.own_s[0]
            since = float(a.at(a.own_s, t)) - float(start)
            vertical = abs(float(a.at(a.amsl_m, t)) - float(b.at(b.amsl_m, t)))
            best = Approach(
                (i + 1, j + 1),
                float(gap[k]),
                math.sqrt(max(float(gap[k]) ** 2 - vertical**2, 0.0)),
                vertical,
                since,
                (float(a.at(a.lat_deg, t)) + float(b.at(b.lat_deg, t))) / 2.0,
                (float(a.at(a.lon_deg, t)) + float(b.at(b.lon_deg, t))) / 2.0,
            )
    return best, takeoff


def replay_fleet(
    dem_path: Path,
    targets_path: Path,
    fleet: FleetFolder,
    settings: ReplaySettings | None = None,
    progress: Progress | None = None,
) -> FleetReport:
    """Fly every vehicle of ``fleet`` at once and judge them (see the module docstring).

    Raises
    ------
    MissionFileError
        If a vehicle has several sorties (a fleet replay flies one mission per vehicle).
    LinkError
        If a vehicle's upload or flight fails.
    """
    settings = settings or ReplaySettings()
    # A vehicle left idle has no mission: it stays on the ground.
    flying = tuple(v for v in fleet.vehicles if not v.idle)
    for vehicle in flying:
        if len(vehicle.missions) > 1:
            raise MissionFileError(
                f"{vehicle.name} has {len(vehicle.missions)} sorties: a fleet replay flies one "
                f"mission per vehicle; replay its sorties with --plan {vehicle.folder}"
            )
    missions = [read_mission(v.missions[0]) for v in flying]
    open_dem(dem_path)
    read_targets(targets_path)
    expected = [
        expected_checks(v.missions[0], m, settings.fov_deg, settings.min_clearance_m)
        for v, m in zip(flying, missions, strict=True)
    ]
    started = time.monotonic()
    delays = [v.start_delay_s for v in flying]
    flights = fly_fleet(missions, settings, progress, delays)
    wall_s = time.monotonic() - started
    reports: list[ReplayReport] = [
        judge(flight, mission, dem_path, targets_path, exp, f"{v.name} ({v.missions[0]})")
        for flight, mission, exp, v in zip(flights, missions, expected, flying, strict=True)
    ]
    together = judge_set(reports, dem_path, targets_path)
    approach, takeoff = closest_approach(
        flights,
        [m.home.amsl_m for m in missions],
        [(m.home.lat_deg, m.home.lon_deg) for m in missions],
    )
    if approach is not None:
        numbers = (flying[approach.pair[0] - 1].number, flying[approach.pair[1] - 1].number)
        approach = dataclasses.replace(approach, pair=numbers)
    required = required_separation_m(fleet.separation)
    problems = []
    if approach is None:
        # One vehicle flying alone has no one to keep apart from.
        if len(flying) > 1:
            problems.append("no two vehicles were in the air at once: the separation is unchecked")
    elif approach.distance_m < required:
        problems.append(
            f"vehicles {approach.pair[0]} and {approach.pair[1]} came within "
            f"{approach.distance_m:.1f} m of each other, under the required {required:g} m"
        )
    return FleetReport(
        flying,
        together,
        fleet.separation,
        required,
        approach,
        takeoff,
        wall_s,
        tuple(problems),
        tuple(v for v in fleet.vehicles if v.idle),
    )


def fleet_report_text(report: FleetReport) -> str:
    """Each vehicle's replay report, all photos together, then the fleet's verdict."""
    sep = report.separation
    rule = (
        f"by altitude, layers {sep.min_m:g} m apart: required {report.required_m:g} m "
        f"({sep.min_m:g} m less {ALTITUDE_TOLERANCE_M:g} m tolerance)"
        if sep.mode == "altitude"
        else f"by timing in one layer: required {report.required_m:g} m"
    )
    lines = [f"fleet: {len(report.vehicles)} vehicles flown at once, separation {rule}"]
    lines += [f"  {v.name:<10} idle in the plan: not flown" for v in report.idle]
    for vehicle, flight_report, takeoff in zip(
        report.vehicles, report.together.reports, report.takeoff_wall_s, strict=True
    ):
        flight = flight_report.flight
        seen = sum(r.photo is not None for r in flight_report.targets)
        lines.append(
            f"  {vehicle.name:<10} {vehicle.altitude_m:g} m, flight {flight.sim_time_s:.1f} s"
            + (f" (planned {vehicle.flight_time_s:.1f} s)" if vehicle.flight_time_s else "")
            + ", "
            f"took off {takeoff:+.2f} s (wall), {len(flight.photos)} photos, {seen} of "
            f"{len(flight_report.targets)} own targets, "
            f"{'PASS' if flight_report.ok else 'FAIL'}"
        )
    approach = report.approach
    if approach is not None:
        planned = (
            f"; planned {sep.planned_closest_m:.1f} m" if sep.planned_closest_m is not None else ""
        )
        lines.append(
            f"  closest   {approach.distance_m:.1f} m between vehicles {approach.pair[0]} and "
            f"{approach.pair[1]}, {approach.time_s:.1f} s into vehicle {approach.pair[0]}'s "
            "flight, at "
            f"{approach.lat_deg:.6f},{approach.lon_deg:.6f} (horizontal "
            f"{approach.horizontal_m:.1f} m, vertical {approach.vertical_m:.1f} m){planned}"
        )
    lines.append(f"  wall time {report.wall_time_s:.1f} s")
    lines.append(f"  result    {'PASS' if report.ok else 'FAIL'}")
    lines.extend(f"  problem   {p}" for p in report.problems)
    return "\n\n".join([set_report_text(report.together), "\n".join(lines)])
