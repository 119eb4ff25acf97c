"""plan_fleet(): K vehicles photograph the site at once; the job ends when the last one lands.

The stages are the single-vehicle plan's, once per vehicle where they depend on it: each
vehicle flies its own altitude layer from its own home (``--separation altitude``: layer k is
the first layer plus ``(k - 1) * --layer-spacing``), so its DEM window, visibility regions
and viewpoints are its own (the camera cone's footprint grows with altitude). The targets are
shared out by :func:`urpt_gcs.solvers.fleet.solve_fleet`; each vehicle's share then goes
through the rest of the single-vehicle chain (margins, sorties, missions checked as written),
so every vehicle's plan is an ordinary :class:`~urpt_gcs.pipeline.planner.Plan`.

Separation: in altitude mode the layers keep the vehicles apart once at altitude; in time mode
(``--separation time``) all fly one layer. Either way the planned tracks (every vehicle takes
off at its start time, flies at its planned speeds and holds at its stops) are checked at every
instant while both are in the air, and a vehicle whose track comes too close to an earlier
one's starts later (whole steps of :data:`DELAY_STEP_S`); the summary states each start delay
and the planned closest approach.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.pipeline.planner import (
    Plan,
    _altitude_rel,
    _Area,
    _latlon,
    _read_area,
    _read_site,
    _Site,
    _Stages,
    _xy,
    finish_plan,
    flight_model,
)
from urpt_gcs.pipeline.settings import FleetSettings, PlanSettings, SeparationMode, VehicleSpec
from urpt_gcs.problem.instance import Instance
from urpt_gcs.progress import Progress
from urpt_gcs.site.targets import TargetSet
from urpt_gcs.solvers import choose, prepare, solve
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour
from urpt_gcs.solvers.fleet import (
    SINGLE_SHARE,
    FleetTours,
    Vehicle,
    restrict,
    solve_fleet,
    with_home,
)
from urpt_gcs.solvers.fleet_bound import MakespanBound, makespan_bound
from urpt_gcs.visibility.cover import build_instance
from urpt_gcs.visibility.regions import Region, visibility_regions

# Start delays are searched in whole steps of this, up to the undelayed makespan.
DELAY_STEP_S = 5.0
# A vehicle keeps its planned timing only so well (a real copter flew the demo 3 % faster
# than the flight-time model): separation must hold with either vehicle of a pair up to
# this much early or late against the other -- the larger of a fixed time and a share of
# the longer flight -- tried in steps of TIMING_STEP_S.
TIMING_SLACK_S = 10.0
TIMING_SLACK_SHARE = 0.05
TIMING_STEP_S = 1.0
# The longest start delay, as a share of the longest flight; beyond it the plan is refused.
MAX_DELAY_SHARE = 0.5
# Each vehicle's written altitude is rounded to whole centimetres (home down, height up): the
# layers as written may come this much closer than the spacing asked for.
_WRITTEN_ROUNDING_M = 0.05


@dataclass(frozen=True, slots=True)
class Closest:
    """The closest two vehicles come while both are in the air."""

    distance_m: float
    horizontal_m: float
    vehicles: tuple[int, int]
    at_s: float
    where_xy: tuple[float, float]


@dataclass(frozen=True, slots=True)
class Separation:
    """How the vehicles are kept apart, and how close they come as planned."""

    mode: SeparationMode
    layer_spacing_m: float
    min_m: float
    start_delays_s: tuple[float, ...]
    closest: Closest | None
    closest_latlon: tuple[float, float] | None
    closest_horizontal_m: float | None
    timing_slack_s: float = 0.0


@dataclass(frozen=True, slots=True)
class FleetPlan:
    """Every vehicle's plan and what the fleet as a whole achieved."""

    settings: PlanSettings
    fleet: FleetSettings
    plans: tuple[Plan, ...]
    tours: FleetTours
    bound: MakespanBound
    separation: Separation
    single_length_m: float
    single_flight_time_s: float
    timings_s: dict[str, float]

    @property
    def finish_s(self) -> tuple[float, ...]:
        """When each vehicle has landed for the last time, from the first take-off."""
        return tuple(
            d + p.flight_time_s
            for d, p in zip(self.separation.start_delays_s, self.plans, strict=True)
        )

    @property
    def makespan_s(self) -> float:
        return max(self.finish_s)

    @property
    def gap(self) -> float:
        """(makespan - bound) / bound."""
        b = self.bound.bound_s
        return math.inf if b <= 0.0 else max(self.makespan_s - b, 0.0) / b


@dataclass(frozen=True, slots=True)
class _Layer:
    """One vehicle's settings, site, area, regions and instance."""

    settings: PlanSettings
    site: _Site
    area: _Area
    regions: tuple[Region, ...]
    instance: Instance


@dataclass(frozen=True, slots=True)
class FleetProblem:
    """What the fleet's solver works on: every vehicle's layer and instance, the reference
    instance the single-vehicle tour is solved on (the lowest layer's viewpoints, from the
    first vehicle's home: what a lower eye sees, the eye above it sees too, so its stops
    serve every layer) and the widest (the highest layer's), whose bound holds for all."""

    site: _Site
    layers: tuple[_Layer, ...]
    vehicles: tuple[Vehicle, ...]
    reference: Instance
    widest: Instance
    gsd_cm: float | None

    @property
    def single_bound_m(self) -> float | None:
        """A bound on any single closed tour from the first home that sees every target from
        any layer flown, or None when the layers' regions are not nested."""
        return geometric_lower_bound(self.widest) if self.monotone else None

    @property
    def monotone(self) -> bool:
        """Whether the reference's single-vehicle bound holds for every layer.

        A higher plane sees every target from wherever a lower one does (its lines of sight
        lie above the lower ones, its cone is wider), so the highest layer's bound holds for
        all of them; a GSD cap breaks that (a higher eye is farther away).
        """
        altitudes = {round(layer.area.camera.altitude_m, 6) for layer in self.layers}
        return len(altitudes) == 1 or self.gsd_cm is None


def fleet_problem(
    dem_path: Path,
    targets_path: Path,
    settings: PlanSettings,
    fleet: FleetSettings,
    stages: _Stages | None = None,
) -> FleetProblem:
    """Read the site and build every vehicle's layer, regions and viewpoints."""
    stages = stages or _Stages(None)
    stages.say("reading targets")
    site = _read_site(dem_path, targets_path, settings)
    stages.lap("targets")
    if len(fleet.vehicles) > len(site.names):
        raise SettingsError(
            f"{len(fleet.vehicles)} vehicles for {len(site.names)} targets leaves a vehicle "
            "nothing to photograph: use fewer vehicles (--vehicles or --fleet)"
        )
    layers = _layers(site, settings, fleet, stages)
    top = max(range(len(layers)), key=lambda k: layers[k].area.camera.altitude_m)
    low = min(range(len(layers)), key=lambda k: layers[k].area.camera.altitude_m)
    vehicles = tuple(
        Vehicle(
            layer.instance,
            flight_model(layer.settings),
            _altitude_rel(layer.area),
            None if layer.settings.endurance_min is None else layer.settings.endurance_min * 60.0,
        )
        for layer in layers
    )
    home = vehicles[0].home_xy
    reference = with_home(layers[low].instance, home)
    widest = with_home(layers[top].instance, home)
    return FleetProblem(site, tuple(layers), vehicles, reference, widest, settings.gsd_cm)


def plan_fleet(
    dem_path: Path,
    targets_path: Path,
    settings: PlanSettings,
    fleet: FleetSettings,
    progress: Progress | None = None,
) -> FleetPlan:
    """Plan the fleet: every target seen by some vehicle, the last landing as early as found.

    Parameters
    ----------
    dem_path, targets_path, settings
        As for :func:`urpt_gcs.pipeline.planner.plan`; ``settings`` gives every vehicle's defaults.
    fleet
        The vehicles and their separation.
    progress
        Called with a short message as each stage starts.
    """
    stages = _Stages(progress)
    problem = fleet_problem(dem_path, targets_path, settings, fleet, stages)
    layers, vehicles, reference = problem.layers, list(problem.vehicles), problem.reference
    solver = choose(reference, settings.solver)
    stages.say(f"preparing the {solver} solver (compiled on first use)")
    prepare(solver)
    stages.lap("compile")
    single_s = SINGLE_SHARE * settings.solve.time_limit_s
    stages.say(f"solving the single-vehicle tour ({reference.n_viewpoints} viewpoints)")
    single = solve(reference, solver, SolveSettings(single_s, settings.solve.seed))
    if any(v < 0 for v in single.order):
        raise SettingsError(
            f"--solver {solver} places its own stops, which a fleet cannot share out: use "
            "--solver auto, exact, heuristic or ortools"
        )
    stages.lap("single")
    budget = settings.solve.time_limit_s - single_s
    stages.say(f"sharing the targets among {len(vehicles)} vehicles (up to {budget:.1f} s)")
    tours = solve_fleet(
        vehicles,
        single.order,
        reference,
        settings.solver,
        SolveSettings(budget, settings.solve.seed),
    )
    stages.lap("fleet")
    idle = [k + 1 for k, share in enumerate(tours.targets) if not share]
    if idle:
        raise SettingsError(
            f"vehicle {idle[0]} has nothing left to photograph (the others' stops see all its "
            "targets): use fewer vehicles (--vehicles or --fleet)"
        )
    bound = makespan_bound(vehicles, problem.single_bound_m)
    plans = tuple(_vehicle_plan(k, layer, tours, solver, stages) for k, layer in enumerate(layers))
    stages.say("checking separation along the planned tracks")
    separation = _separate(plans, fleet, problem.site)
    stages.lap("separation")
    result = FleetPlan(
        settings=settings,
        fleet=fleet,
        plans=plans,
        tours=tours,
        bound=bound,
        separation=separation,
        single_length_m=single.length,
        single_flight_time_s=vehicles[0].time_s(
            reference.points_xy[list(single.order)]  # type: ignore[index]
        ),
        timings_s=stages.timings_s,
    )
    if result.makespan_s < bound.bound_s * (1.0 - 1e-9):
        raise PlanError(
            f"internal check failed: makespan {result.makespan_s:.1f} s is under its lower "
            f"bound {bound.bound_s:.1f} s; report this"
        )
    return result


def _vehicle_settings(
    settings: PlanSettings, spec: VehicleSpec, altitude_m: float | None
) -> PlanSettings:
    mission = settings.mission
    if spec.speed_m_s is not None:
        mission = dataclasses.replace(
            mission, cruise_speed_m_s=spec.speed_m_s, hover_speed_m_s=spec.speed_m_s
        )
    return dataclasses.replace(
        settings,
        home=spec.home if spec.home is not None else settings.home,
        altitude_m=altitude_m,
        endurance_min=spec.endurance_min
        if spec.endurance_min is not None
        else settings.endurance_min,
        mission=mission,
    )


def _vehicle_site(site: _Site, settings: PlanSettings, number: int, fleet: FleetSettings) -> _Site:
    if settings.home is None:
        return site
    lat, lon = settings.home
    xy = _xy(site.crs, [(lat, lon)])[0]
    return dataclasses.replace(
        site,
        home_lat_lon=(lat, lon),
        home_xy=(float(xy[0]), float(xy[1])),
        home_source=f"vehicle {number} of {fleet.source}"
        if fleet.vehicles[number - 1].home is not None
        else site.home_source,
    )


def _layers(
    site: _Site, settings: PlanSettings, fleet: FleetSettings, stages: _Stages
) -> list[_Layer]:
    """Every vehicle's flight plane, DEM window, regions and viewpoints.

    Without ``--altitude`` the first layer is the single plan's (``--clearance`` over the
    highest terrain its cones reach); the layers above it reach wider, so the first layer is
    raised until every layer keeps ``--clearance`` over the terrain of its own window.
    """
    spacing = fleet.layer_spacing_m if fleet.separation == "altitude" else 0.0
    specs = fleet.vehicles
    stages.say("reading terrain")
    given = specs[0].altitude_m if specs[0].altitude_m is not None else settings.altitude_m
    first = _vehicle_settings(settings, specs[0], given)
    base = _read_area(_vehicle_site(site, first, 1, fleet), first).camera.altitude_m

    def wanted(k: int, base_m: float) -> float:
        given = specs[k].altitude_m
        return given if given is not None else base_m + k * spacing

    for _ in range(3):
        areas = []
        for k, spec in enumerate(specs):
            s = _vehicle_settings(settings, spec, wanted(k, base))
            areas.append((s, _vehicle_site(site, s, k + 1, fleet)))
        read = [(s, v, _read_area(v, s)) for s, v in areas]
        if settings.altitude_m is not None:
            break
        # The first layer each layer planned from --clearance asks for over its own window.
        need = [
            a.terrain_max_m + settings.clearance_m - k * spacing
            for k, (_, _, a) in enumerate(read)
            if specs[k].altitude_m is None
        ]
        if not need or max(need) <= base + 1e-6:
            break
        base = max(need)
    stages.lap("terrain")
    for k, (s, _, a) in enumerate(read):
        _check_layer(k + 1, s, a, settings, fleet)
    out: list[_Layer] = []
    for k, (s, v, a) in enumerate(read):
        stages.say(f"visibility of {len(site.names)} targets for vehicle {k + 1}")
        same = next(
            (layer for layer in out if layer.area.camera.altitude_m == a.camera.altitude_m),
            None,
        )
        if same is not None:
            out.append(_Layer(s, v, a, same.regions, with_home(same.instance, v.home_xy)))
            continue
        regions = visibility_regions(
            a.terrain, v.targets_xy, a.ground_m, a.camera, s.samples, s.workers
        )
        instance = build_instance(
            a.terrain,
            regions,
            v.targets_xy,
            a.ground_m,
            a.camera,
            v.home_xy,
            a.terrain_max_m,
            s.workers,
        )
        out.append(_Layer(s, v, a, regions, instance))
    stages.lap("viewpoints")
    return out


def _check_layer(
    number: int, s: PlanSettings, area: _Area, settings: PlanSettings, fleet: FleetSettings
) -> None:
    """Refuse a layer over ``--max-agl`` above its home, or (planned from ``--clearance``)
    under the clearance over the terrain its cones reach."""
    altitude = area.camera.altitude_m
    above_home = altitude - area.home_ground_m
    if above_home > settings.max_agl_m:
        fix = (
            "lower --layer-spacing or --altitude/--clearance, use fewer vehicles or "
            "--separation time, or raise --max-agl"
            if fleet.separation == "altitude"
            else "lower --altitude/--clearance or raise --max-agl"
        )
        raise SettingsError(
            f"layer {number} (vehicle {number}) at {altitude:.1f} m is {above_home:.1f} m above "
            f"its home, over --max-agl {settings.max_agl_m:g} m: {fix}"
        )
    if settings.altitude_m is None and fleet.vehicles[number - 1].altitude_m is None:
        over = altitude - area.terrain_max_m
        if over < settings.clearance_m - 1e-6:
            raise SettingsError(
                f"layer {number} (vehicle {number}) at {altitude:.1f} m is only {over:.1f} m "
                f"over the highest terrain its cones reach, under --clearance "
                f"{settings.clearance_m:g} m: give --altitude, or lower --layer-spacing"
            )


def _vehicle_plan(k: int, layer: _Layer, tours: FleetTours, solver: str, stages: _Stages) -> Plan:
    """Vehicle ``k``'s share as an ordinary plan over its own targets."""
    targets = list(tours.targets[k])
    sub, kept = restrict(layer.instance, targets)
    index = {int(v): i for i, v in enumerate(kept.tolist())}
    order = [index[v] for v in tours.orders[k] if v in index]
    tour = finish_tour(
        sub, order, geometric_lower_bound(sub), solver, tours.search_s, notes=("fleet share",)
    )
    tour = _counted_once(tour, layer.site.targets_xy[np.asarray(targets, dtype=np.int64)])
    idx = np.asarray(targets, dtype=np.int64)
    site = layer.site
    shared = TargetSet(
        tuple(site.targets.targets[i] for i in targets), site.targets.home, site.targets.source
    )
    sub_site = dataclasses.replace(
        site,
        targets=shared,
        names=[site.names[i] for i in targets],
        targets_xy=site.targets_xy[idx],
    )
    sub_area = dataclasses.replace(layer.area, ground_m=layer.area.ground_m[idx])
    regions = tuple(dataclasses.replace(layer.regions[i], target=j) for j, i in enumerate(targets))
    stages.say(f"checking vehicle {k + 1}'s missions")
    return finish_plan(sub_site, sub_area, regions, sub, tour, layer.settings, _Stages(None))


def _counted_once(tour: Tour, targets_xy: FloatArray) -> Tour:
    """The tour with each target counted for one stop only, the nearest that sees it: only
    a counted target must be seen with the position margin and as written, and the mission
    still flies every stop."""
    assert tour.points_xy is not None
    d = np.hypot(
        tour.points_xy[:, None, 0] - targets_xy[None, :, 0],
        tour.points_xy[:, None, 1] - targets_xy[None, :, 1],
    )
    d = np.where(tour.sees, d, np.inf)
    nearest = np.argmin(d, axis=0)
    sees = np.zeros_like(tour.sees)
    sees[nearest, np.arange(len(targets_xy))] = True
    return dataclasses.replace(tour, sees=sees)


# ---- tracks and separation -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Track:
    """A vehicle's planned position against time: breakpoints ``t_s`` (from its take-off
    command), positions ``xyz`` between which it moves at constant velocity, and whether it
    is in the air on each interval."""

    t_s: FloatArray
    xyz: FloatArray
    airborne: npt.NDArray[np.bool_]

    def shifted(self, delay_s: float) -> Track:
        return Track(self.t_s + delay_s, self.xyz, self.airborne)


def track(plan: Plan) -> Track:
    """The plan's tracks as the flight-time model flies them: on the ground until the
    take-off starts, straight up to the plane, each leg at the time the model gives it, a
    hold at each stop, home, down, and on the ground until the disarm; sorties back to back."""
    model = plan.flight_model
    ground = plan.mission.home.amsl_m
    eye = ground + plan.altitude_rel_m
    hx, hy = plan.home_xy
    assert plan.tour.points_xy is not None
    times = [0.0]
    points = [(hx, hy, ground)]
    air: list[bool] = []

    def go(duration_s: float, to: tuple[float, float, float], flying: bool) -> None:
        times.append(times[-1] + max(duration_s, 0.0))
        points.append(to)
        air.append(flying)

    climb = model.takeoff_s(plan.altitude_rel_m) - model.start_s
    down = model.landing_s(plan.altitude_rel_m) - model.touchdown_s
    for sortie in plan.sorties:
        go(model.start_s, (hx, hy, ground), False)
        go(climb, (hx, hy, eye), True)
        here = (hx, hy)
        for x, y in plan.tour.points_xy[sortie.first : sortie.stop].tolist():
            go(float(model.leg_s(math.hypot(x - here[0], y - here[1]))), (x, y, eye), True)
            go(model.stop_s, (x, y, eye), True)
            here = (x, y)
        go(float(model.return_s(math.hypot(hx - here[0], hy - here[1]))), (hx, hy, eye), True)
        go(down, (hx, hy, ground), True)
        go(model.touchdown_s, (hx, hy, ground), False)
    return Track(np.asarray(times), np.asarray(points, dtype=np.float64), np.asarray(air))


def _at(tr: Track, t: FloatArray) -> FloatArray:
    return np.column_stack([np.interp(t, tr.t_s, tr.xyz[:, i]) for i in range(3)])


def _flying(tr: Track, t: FloatArray) -> npt.NDArray[np.bool_]:
    i = np.searchsorted(tr.t_s, t, side="right") - 1
    inside = (i >= 0) & (i < len(tr.airborne))
    out: npt.NDArray[np.bool_] = inside & tr.airborne[np.clip(i, 0, len(tr.airborne) - 1)]
    return out


def closest(a: Track, b: Track, horizontal: bool) -> tuple[float, float, FloatArray] | None:
    """The least distance (3-D, or horizontal) between two tracks while both fly, exact for
    their piecewise-constant velocities: (distance, time, midpoint xyz), or None if they are
    never in the air together."""
    t = np.union1d(a.t_s, b.t_s)
    t = t[(t >= max(a.t_s[0], b.t_s[0])) & (t <= min(a.t_s[-1], b.t_s[-1]))]
    if len(t) < 2:
        return None
    mid = 0.5 * (t[:-1] + t[1:])
    both = _flying(a, mid) & _flying(b, mid)
    if not both.any():
        return None
    pa, pb = _at(a, t), _at(b, t)
    r = pa - pb
    if horizontal:
        r[:, 2] = 0.0
    r0, r1 = r[:-1][both], r[1:][both]
    dr = r1 - r0
    den = np.einsum("ij,ij->i", dr, dr)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(den > 0.0, np.clip(-np.einsum("ij,ij->i", r0, dr) / den, 0.0, 1.0), 0.0)
    gap = np.linalg.norm(r0 + s[:, None] * dr, axis=1)
    i = int(np.argmin(gap))
    t0, t1 = t[:-1][both][i], t[1:][both][i]
    when = float(t0 + s[i] * (t1 - t0))
    where = 0.5 * (_at(a, np.array([when]))[0] + _at(b, np.array([when]))[0])
    return float(gap[i]), when, where


def timing_slack_s(a: Track, b: Track) -> float:
    """How far early or late one vehicle of a pair may run against the other."""
    longest = max(a.t_s[-1] - a.t_s[0], b.t_s[-1] - b.t_s[0])
    return max(TIMING_SLACK_S, TIMING_SLACK_SHARE * float(longest))


def _pair_closest(tracks: Sequence[Track], i: int, j: int) -> Closest | None:
    """The pair's closest approach, the least over ``j`` running early or late against ``i``
    by up to :func:`timing_slack_s` (each shift's approach exact, the shifts in steps of
    :data:`TIMING_STEP_S`); its time is on ``i``'s clock."""
    a, b = tracks[i], tracks[j]
    slack = timing_slack_s(a, b)
    steps = math.ceil(slack / TIMING_STEP_S)
    best: Closest | None = None
    for shift in np.linspace(-slack, slack, 2 * steps + 1):
        moved = b.shifted(float(shift))
        full = closest(a, moved, horizontal=False)
        if full is None:
            continue
        flat = closest(a, moved, horizontal=True)
        assert flat is not None
        if best is not None and full[0] >= best.distance_m and flat[0] >= best.horizontal_m:
            continue
        found = Closest(
            full[0], flat[0], (i + 1, j + 1), full[1], (float(full[2][0]), float(full[2][1]))
        )
        if best is None:
            best = found
        else:
            # The least of each measure over the shifts (3-D and horizontal apart).
            best = Closest(
                min(best.distance_m, found.distance_m),
                min(best.horizontal_m, found.horizontal_m),
                best.vehicles,
                found.at_s if found.distance_m < best.distance_m else best.at_s,
                found.where_xy if found.distance_m < best.distance_m else best.where_xy,
            )
    return best


def _separate(plans: Sequence[Plan], fleet: FleetSettings, site: _Site) -> Separation:
    """Start delays that keep every pair apart, and the closest approach they leave.

    Vehicles are taken in turn (:func:`_delays`, for a few orders of take-off); each starts
    at the first step of :data:`DELAY_STEP_S` at which its track stays ``min_m`` from every
    earlier one's while both fly (3-D in altitude mode, less the written altitudes'
    rounding; horizontal in time mode), with either running early or late by up to
    :func:`timing_slack_s`. None up to :data:`MAX_DELAY_SHARE` of the longest
    flight in any order: refused, naming the pair, where and when.
    """
    base = [track(p) for p in plans]
    horizontal = fleet.separation == "time"
    need = fleet.min_m - (0.0 if horizontal else _WRITTEN_ROUNDING_M)
    # A vehicle held back longer than half the longest flight is all but flying in turn.
    cap = MAX_DELAY_SHARE * max(p.flight_time_s for p in plans)
    # Who takes off first changes the delays: the vehicles in turn as numbered (lowest layer
    # first), the longest flight first, and the highest layer first; the earliest last
    # landing is kept, the first refusal raised if every order is refused.
    count = len(plans)
    turns = [
        list(range(count)),
        sorted(range(count), key=lambda k: -plans[k].flight_time_s),
        list(range(count - 1, -1, -1)),
    ]
    best: list[float] | None = None
    refused: SettingsError | None = None
    for turn in turns:
        try:
            delays = _delays(base, turn, need, cap, horizontal, fleet, site)
        except SettingsError as exc:
            refused = refused or exc
            continue
        finish = max(d + p.flight_time_s for d, p in zip(delays, plans, strict=True))
        if best is None or finish < max(
            d + p.flight_time_s for d, p in zip(best, plans, strict=True)
        ):
            best = delays
    if best is None:
        assert refused is not None
        raise refused
    delays = best
    tracks = [b.shifted(d) for b, d in zip(base, delays, strict=True)]
    found = [
        c
        for i in range(len(tracks))
        for j in range(i + 1, len(tracks))
        if (c := _pair_closest(tracks, i, j)) is not None
    ]
    least = min(found, key=lambda c: c.distance_m, default=None)
    flat = min((c.horizontal_m for c in found), default=None)
    where = None if least is None else _latlon(site.crs, np.array([least.where_xy]))[0]
    return Separation(
        mode=fleet.separation,
        layer_spacing_m=fleet.layer_spacing_m,
        min_m=fleet.min_m,
        start_delays_s=tuple(delays),
        closest=least,
        closest_latlon=where,
        closest_horizontal_m=flat,
        timing_slack_s=max(
            (
                timing_slack_s(tracks[i], tracks[j])
                for i in range(len(tracks))
                for j in range(i + 1, len(tracks))
            ),
            default=0.0,
        ),
    )


def _delays(
    base: list[Track],
    turn: list[int],
    need: float,
    cap: float,
    horizontal: bool,
    fleet: FleetSettings,
    site: _Site,
) -> list[float]:
    """Start delays with the vehicles taking off in the order ``turn``: each at the first
    step of :data:`DELAY_STEP_S` that keeps it ``need`` from every vehicle before it."""
    delays = [0.0] * len(base)

    def apart(k: int, delay: float, earlier: list[int]) -> Closest | None:
        moved = base[k].shifted(delay)
        worst: Closest | None = None
        for j in earlier:
            c = _pair_closest([base[j].shifted(delays[j]), moved], 0, 1)
            if c is None:
                continue
            c = dataclasses.replace(c, vehicles=(min(j, k) + 1, max(j, k) + 1))
            value = c.horizontal_m if horizontal else c.distance_m
            if value < need and (worst is None or value < _value(worst, horizontal)):
                worst = c
        return worst

    for n, k in enumerate(turn[1:], start=1):
        first = apart(k, 0.0, turn[:n])
        delay = 0.0
        clash = first
        while clash is not None:
            delay += DELAY_STEP_S
            if delay > cap:
                assert first is not None
                lat, lon = _latlon(site.crs, np.array([first.where_xy]))[0]
                what = " horizontally" if horizontal else ""
                raise SettingsError(
                    f"vehicles {first.vehicles[0]} and {first.vehicles[1]} come within "
                    f"{_value(first, horizontal):.1f} m{what} of each other at "
                    f"{first.at_s:.0f} s after take-off near {lat:.6f}, {lon:.6f}, under the "
                    f"{fleet.min_m:g} m required, and no start delay up to {cap:.0f} s avoids "
                    "it: give the vehicles homes further apart in --fleet, or use "
                    "--separation altitude"
                )
            clash = apart(k, delay, turn[:n])
        delays[k] = delay
    return delays


def _value(c: Closest, horizontal: bool) -> float:
    return c.horizontal_m if horizontal else c.distance_m


__all__ = [
    "FleetPlan",
    "Separation",
    "closest",
    "fleet_problem",
    "plan_fleet",
    "track",
]
