"""plan_fleet(): K vehicles photograph the site at once; the job ends when the last one lands.

The stages are the single-vehicle plan's, once per vehicle where they depend on it: each
vehicle flies its own altitude layer from its own home (``--separation altitude``: layer k is
the first layer plus ``(k - 1) * --layer-spacing``), so its DEM window, visibility regions
and viewpoints are its own (the camera cone's footprint grows with altitude). The targets are
shared out by :func:`urpt_gcs.solvers.fleet.solve_fleet`; each vehicle's share then goes
through the rest of the single-vehicle chain (margins, sorties, missions checked as written),
so every vehicle's plan is an ordinary :class:`~urpt_gcs.pipeline.result.Plan`.

Separation (:mod:`~urpt_gcs.pipeline.separation`): in altitude mode the layers keep the
vehicles apart once at altitude; in time mode (``--separation time``) all fly one layer. Either
way the planned tracks are checked at every instant while both are in the air, and a vehicle
whose track comes too close to an earlier one's starts later; the summary states each start
delay and the planned closest approach.

A vehicle whose every share would only land the fleet later (far slower than the others, or
unable to reach any target within its endurance) is left idle: it has no plan, no mission and
no start delay, and the summary says why. The fleet is refused only when some target is out
of every vehicle's reach.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.certificate import bound_time_s
from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.pipeline.area import (
    PlanArea,
    SiteInputs,
    altitude_rel,
    latlon_to_xy,
    read_area,
    read_site,
)
from urpt_gcs.pipeline.improve import certify_flight, prepare_bound
from urpt_gcs.pipeline.missions import flight_model
from urpt_gcs.pipeline.planner import finish_plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.separation import Separation, separate
from urpt_gcs.pipeline.settings import FleetSettings, PlanSettings, VehicleSpec
from urpt_gcs.pipeline.stages import Stages
from urpt_gcs.problem.instance import Instance
from urpt_gcs.progress import Progress
from urpt_gcs.site.targets import TargetSet
from urpt_gcs.solvers import choose, prepare, solve
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour
from urpt_gcs.solvers.fleet import (
    SINGLE_SHARE,
    FleetTours,
    Vehicle,
    naive_tours,
    reachable,
    refuse_unreachable,
    restrict,
    solve_fleet,
    with_home,
)
from urpt_gcs.solvers.fleet_bound import MakespanBound, fleet_budget, makespan_bound
from urpt_gcs.visibility.cover import build_instance
from urpt_gcs.visibility.regions import Region, visibility_regions


@dataclass(frozen=True, slots=True)
class IdleVehicle:
    """A vehicle of the fleet given nothing to fly, and why.

    Attributes
    ----------
    number
        Its number in the fleet (1, 2, ...).
    settings
        Its own settings (home, speed, endurance).
    altitude_m, altitude_rel_m
        The layer it would have flown, and its height above its home.
    home_lat_lon
        Its home, WGS84 degrees.
    reason
        Why it flies nothing, for the operator.
    """

    number: int
    settings: PlanSettings
    altitude_m: float
    altitude_rel_m: float
    home_lat_lon: tuple[float, float]
    reason: str


@dataclass(frozen=True, slots=True)
class FleetPlan:
    """Every vehicle's plan (or, for a vehicle left idle, why it has none) and what the
    fleet as a whole achieved."""

    settings: PlanSettings
    fleet: FleetSettings
    plans: tuple[Plan | IdleVehicle, ...]
    tours: FleetTours
    bound: MakespanBound
    separation: Separation
    single_length_m: float
    single_flight_time_s: float
    timings_s: dict[str, float]
    # The naive split (the single tour cut into contiguous pieces, nothing searched) finished
    # and separated as the plans are: when its last vehicle lands (inf: no cut of the tour
    # fits, or no delay keeps its vehicles apart). The plans land no later.
    naive_flown_s: float = math.inf

    @property
    def flying(self) -> tuple[Plan | None, ...]:
        """Each vehicle's plan, None for a vehicle left idle."""
        return tuple(p if isinstance(p, Plan) else None for p in self.plans)

    @property
    def idle(self) -> tuple[IdleVehicle, ...]:
        """The vehicles left idle."""
        return tuple(p for p in self.plans if isinstance(p, IdleVehicle))

    @property
    def finish_s(self) -> tuple[float, ...]:
        """When each vehicle has landed for the last time, from the first take-off (0 for a
        vehicle left idle)."""
        return _finish_s(self.plans, self.separation)

    @property
    def makespan_s(self) -> float:
        """When the last vehicle has landed, from the first take-off."""
        return max(self.finish_s)

    @property
    def gap(self) -> float:
        """(makespan - bound) / bound."""
        b = self.bound.bound_s
        return math.inf if b <= 0.0 else max(self.makespan_s - b, 0.0) / b


@dataclass(frozen=True, slots=True)
class VehicleLayer:
    """One vehicle's settings, site, area, regions and instance.

    Attributes
    ----------
    settings
        The plan's settings with this vehicle's home, altitude, endurance and speed.
    site
        The site with this vehicle's home.
    area
        The DEM window and the flight plane of its layer.
    regions
        Each target's visibility region from its layer.
    instance
        Its viewpoints and what each sees, from its home.
    """

    settings: PlanSettings
    site: SiteInputs
    area: PlanArea
    regions: tuple[Region, ...]
    instance: Instance


@dataclass(frozen=True, slots=True)
class FleetProblem:
    """What the fleet's solver works on: every vehicle's layer and instance, the reference
    instance the single-vehicle tour is solved on (the lowest layer's viewpoints, from the
    first vehicle's home: what a lower eye sees, the eye above it sees too, so its stops
    serve every layer) and the widest (the highest layer's), whose bound holds for all."""

    site: SiteInputs
    layers: tuple[VehicleLayer, ...]
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
    stages: Stages | None = None,
) -> FleetProblem:
    """Read the site and build every vehicle's layer, regions and viewpoints.

    Parameters
    ----------
    dem_path, targets_path, settings
        As for :func:`urpt_gcs.pipeline.planner.plan`; ``settings`` gives every vehicle's
        defaults.
    fleet
        The vehicles and their separation.
    stages
        Announces each stage and keeps its time (None: silently).

    Returns
    -------
    FleetProblem
        Every vehicle's layer, the vehicles as the fleet's search sees them, and the reference
        and widest instances.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        More vehicles than targets, or a layer over ``--max-agl`` or under ``--clearance``.
    """
    stages = stages or Stages(None)
    stages.say("reading targets")
    site = read_site(dem_path, targets_path, settings)
    stages.lap("targets")
    if len(fleet.vehicles) > len(site.names):
        raise SettingsError.about(
            "{count} vehicles for {targets} targets leaves a vehicle nothing to photograph: "
            "use fewer vehicles ({vehicles} or {fleet_file})",
            count=len(fleet.vehicles),
            targets=len(site.names),
        )
    layers = _layers(site, settings, fleet, stages)
    top = max(range(len(layers)), key=lambda k: layers[k].area.camera.altitude_m)
    low = min(range(len(layers)), key=lambda k: layers[k].area.camera.altitude_m)
    vehicles = tuple(
        Vehicle(
            layer.instance,
            flight_model(layer.settings),
            altitude_rel(layer.area),
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

    Returns
    -------
    FleetPlan
        Every vehicle's plan, the fleet's makespan bound and the vehicles' separation.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        A solver that places its own stops, a target no vehicle can reach within its
        endurance, or vehicles that no start delay keeps apart.
    """
    if settings.agl_band_m is not None:
        raise SettingsError.about(
            "{agl_band_m} (a flight that follows the terrain) is planned for one vehicle only: "
            "drop {vehicles}/{fleet_file}, or split the targets and plan each vehicle's part "
            "on its own"
        )
    stages = Stages(progress)
    problem = fleet_problem(dem_path, targets_path, settings, fleet, stages)
    refuse_unreachable(problem.vehicles, problem.site.names)
    vehicles, reference = list(problem.vehicles), problem.reference
    solver = choose(reference, settings.solver)
    stages.say(f"preparing the {solver} solver (compiled on first use)")
    prepare(solver)
    stages.lap("compile")
    single_s = SINGLE_SHARE * settings.solve.time_limit_s
    stages.say(f"solving the single-vehicle tour ({reference.n_viewpoints} viewpoints)")
    stop_cost = settings.solve.stop_cost or flight_model(settings).stop_cost_m
    single = solve(
        reference, solver, SolveSettings(single_s, settings.solve.seed, stop_cost=stop_cost)
    )
    if any(v < 0 for v in single.order):
        raise SettingsError.about(
            "{solver} {value} places its own stops, which a fleet cannot share out: use "
            "{solver} auto, exact, heuristic or ortools",
            value=solver,
        )
    stages.lap("single")
    budget = settings.solve.time_limit_s - single_s
    stages.say(f"sharing the targets among {len(vehicles)} vehicles (up to {budget:.1f} s)")
    search = SolveSettings(budget, settings.solve.seed, stop_cost=stop_cost)
    solvers = (settings.solver, solver)
    tours, plans, separation = _shared(problem, fleet, single.order, solvers, search, None, stages)
    delays = separation.start_delays_s
    if max(delays) > 0.0:
        # The start delays come from the tracks: shared out again with them counted, a
        # vehicle held back gets less to fly. Kept if the last landing is earlier.
        stages.say("sharing the targets again with the start delays counted")
        try:
            again = _shared(problem, fleet, single.order, solvers, search, delays, stages)
        except SettingsError:
            # Shared out again, no delays kept the vehicles apart: the first sharing stands.
            again = None
        if again is not None and max(_finish_s(again[1], again[2])) < max(
            _finish_s(plans, separation)
        ):
            tours, plans, separation = again
    # The search compares the flight model's estimates, and margins and refinement then
    # change every flight a little: the naive split is finished the same way and kept if
    # it lands sooner, so the plan never lands after the naive split as flown.
    stages.say("finishing the naive split, to keep the plan no later than it")
    delays = separation.start_delays_s
    try:
        naive = _shared(
            problem, fleet, single.order, solvers, search, delays if max(delays) > 0.0 else None,
            stages, naive=True,
        )  # fmt: skip
        naive_flown = max(_finish_s(naive[1], naive[2]))
    except SettingsError:
        naive, naive_flown = None, math.inf
    if naive is not None and naive_flown < max(_finish_s(plans, separation)):
        tours, plans, separation = naive
    bound = _makespan_bound(problem, single.length, settings, stages)
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
        naive_flown_s=naive_flown,
    )
    if result.makespan_s < bound.bound_s * (1.0 - 1e-9):
        raise PlanError(
            f"internal check failed: makespan {result.makespan_s:.1f} s is under its lower "
            f"bound {bound.bound_s:.1f} s; report this"
        )
    return result


def _shared(
    problem: FleetProblem,
    fleet: FleetSettings,
    single_order: tuple[int, ...],
    solvers: tuple[str, str],
    search: SolveSettings,
    offsets_s: tuple[float, ...] | None,
    stages: Stages,
    naive: bool = False,
) -> tuple[FleetTours, tuple[Plan | IdleVehicle, ...], Separation]:
    """The targets shared out (each vehicle's start delay counted), every vehicle's plan
    (or why it is left idle) and the start delays that keep them apart. ``solvers``: the
    setting the search re-solves with, and the solver the single tour came from; ``naive``:
    the naive split as it is cut, not searched."""
    if naive:
        tours = naive_tours(problem.vehicles, single_order, problem.reference, offsets_s)
    else:
        tours = solve_fleet(
            problem.vehicles, single_order, problem.reference, solvers[0], search, offsets_s
        )
    stages.lap("fleet")
    flown = [
        _vehicle_plan(k, layer, tours, solvers[1], stages) if tours.targets[k] else None
        for k, layer in enumerate(problem.layers)
    ]
    stages.say("checking separation along the planned tracks")
    separation = separate(flown, fleet, problem.site.crs, offsets_s)
    stages.lap("separation")
    landing = max(
        d + p.flight_time_s
        for d, p in zip(separation.start_delays_s, flown, strict=True)
        if p is not None
    )
    plans = tuple(p if p is not None else _idle(k, problem, landing) for k, p in enumerate(flown))
    return tours, plans, separation


def _finish_s(plans: tuple[Plan | IdleVehicle, ...], separation: Separation) -> tuple[float, ...]:
    return tuple(
        d + p.flight_time_s if isinstance(p, Plan) else 0.0
        for d, p in zip(separation.start_delays_s, plans, strict=True)
    )


def _idle(k: int, problem: FleetProblem, landing_s: float) -> IdleVehicle:
    """Vehicle ``k`` left idle, and why: it reaches no target within its endurance, or its
    quickest flight to any one target lands after the others have flown every target."""
    layer, vehicle = problem.layers[k], problem.vehicles[k]
    reach = reachable([vehicle])[0]
    others = f"the others fly all {len(problem.site.names)} targets in {_minutes(landing_s)}"
    if not reach.any():
        endurance = layer.settings.endurance_min
        reason = (
            f"it cannot fly to any target and back within its {endurance:g} min endurance; "
            + others
        )
    else:
        quickest = float(vehicle.alone_s()[vehicle.flyable()].min())
        speed = layer.settings.mission.cruise_speed_m_s
        reason = (
            f"at {speed:g} m/s its quickest flight to any one target takes "
            f"{_minutes(quickest)}; {others}"
            if quickest >= landing_s
            else f"{others}; no share for it landed the fleet sooner"
        )
    home = layer.site.home_lat_lon
    return IdleVehicle(
        k + 1,
        layer.settings,
        layer.area.camera.altitude_m,
        altitude_rel(layer.area),
        (float(home[0]), float(home[1])),
        reason,
    )


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s:02d} s"


def _makespan_bound(
    problem: FleetProblem, single_m: float, settings: PlanSettings, stages: Stages
) -> MakespanBound:
    """The fleet's makespan bound, with the certified bound of one flight over the highest
    layer's outer stars (it holds for every layer when they nest) and, when every vehicle
    flies from one home, the bound of sorties within the fleet's weakest budget."""
    vehicles = problem.vehicles
    if not (settings.certify and problem.monotone):
        return makespan_bound(vehicles, problem.single_bound_m)
    top = max(problem.layers, key=lambda layer: layer.area.camera.altitude_m)
    home = vehicles[0].home_xy
    site = dataclasses.replace(top.site, home_xy=home)
    prepare_bound(site, top.area)
    stages.lap("compile")
    bound_s = settings.bound_time_s or bound_time_s(settings.solve.time_limit_s)
    stages.say(f"bounding the fleet's flights (up to {bound_s:.1f} s)")
    one_home = all(v.home_xy == home for v in vehicles)
    certificate = certify_flight(
        site, top.area, problem.widest, single_m, single_m, bound_s, top.settings,
        fleet_budget(vehicles),
    )  # fmt: skip
    stages.lap("bound")
    single = max(certificate.single_flight_m, problem.single_bound_m or 0.0)
    return makespan_bound(vehicles, single, certificate.sorties if one_home else None)


@contextlib.contextmanager
def _own_altitude_named(fleet: FleetSettings, k: int) -> Iterator[None]:
    """Name a vehicle's own ``altitude_m`` in its fleet file where an error about vehicle
    ``k`` (from 0) names the plan's altitude: the operator set it there, not by the flag."""
    try:
        yield
    except SettingsError as exc:
        if fleet.vehicles[k].altitude_m is None or exc.template is None:
            raise
        source = fleet.source.replace("{", "{{").replace("}", "}}")
        own = f"[[vehicle]] {k + 1} altitude_m ({source})"
        raise SettingsError.about(exc.template.replace("{altitude_m}", own), **exc.values) from None


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


def _vehicle_site(
    site: SiteInputs, settings: PlanSettings, number: int, fleet: FleetSettings
) -> SiteInputs:
    if settings.home is None:
        return site
    lat, lon = settings.home
    xy = latlon_to_xy(site.crs, [(lat, lon)])[0]
    return dataclasses.replace(
        site,
        home_lat_lon=(lat, lon),
        home_xy=(float(xy[0]), float(xy[1])),
        home_source=f"vehicle {number} of {fleet.source}"
        if fleet.vehicles[number - 1].home is not None
        else site.home_source,
    )


def _layers(
    site: SiteInputs, settings: PlanSettings, fleet: FleetSettings, stages: Stages
) -> list[VehicleLayer]:
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
    with _own_altitude_named(fleet, 0):
        base = read_area(_vehicle_site(site, first, 1, fleet), first).camera.altitude_m

    def wanted(k: int, base_m: float) -> float:
        given = specs[k].altitude_m
        return given if given is not None else base_m + k * spacing

    for _ in range(3):
        areas = []
        for k, spec in enumerate(specs):
            s = _vehicle_settings(settings, spec, wanted(k, base))
            areas.append((s, _vehicle_site(site, s, k + 1, fleet)))
        read = []
        for k, (s, v) in enumerate(areas):
            with _own_altitude_named(fleet, k):
                read.append((s, v, read_area(v, s)))
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
        with _own_altitude_named(fleet, k):
            _check_layer(k + 1, s, a, settings, fleet)
    out: list[VehicleLayer] = []
    for k, (s, v, a) in enumerate(read):
        stages.say(f"visibility of {len(site.names)} targets for vehicle {k + 1}")
        same = next(
            (layer for layer in out if layer.area.camera.altitude_m == a.camera.altitude_m),
            None,
        )
        if same is not None:
            out.append(VehicleLayer(s, v, a, same.regions, with_home(same.instance, v.home_xy)))
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
        out.append(VehicleLayer(s, v, a, regions, instance))
    stages.lap("viewpoints")
    return out


def _check_layer(
    number: int, s: PlanSettings, area: PlanArea, settings: PlanSettings, fleet: FleetSettings
) -> None:
    """Refuse a layer over ``--max-agl`` above its home, or (planned from ``--clearance``)
    under the clearance over the terrain its cones reach."""
    altitude = area.camera.altitude_m
    above_home = altitude - area.home_ground_m
    if above_home > settings.max_agl_m:
        fix = (
            "lower {layer_spacing_m} or {altitude_m}/{clearance_m}, use fewer vehicles or "
            "{separation} time, or raise {max_agl_m}"
            if fleet.separation == "altitude"
            else "lower {altitude_m}/{clearance_m} or raise {max_agl_m}"
        )
        raise SettingsError.about(
            "layer {number} (vehicle {number}) at {altitude:.1f} m is {above:.1f} m above its "
            "home, over {max_agl_m} {max_agl:g} m: " + fix,
            number=number,
            altitude=altitude,
            above=above_home,
            max_agl=settings.max_agl_m,
        )
    if settings.altitude_m is None and fleet.vehicles[number - 1].altitude_m is None:
        over = altitude - area.terrain_max_m
        if over < settings.clearance_m - 1e-6:
            raise SettingsError.about(
                "layer {number} (vehicle {number}) at {altitude:.1f} m is only {over:.1f} m "
                "over the highest terrain its cones reach, under {clearance_m} {clearance:g} m: "
                "give {altitude_m}, or lower {layer_spacing_m}",
                number=number,
                altitude=altitude,
                over=over,
                clearance=settings.clearance_m,
            )


def _vehicle_plan(
    k: int, layer: VehicleLayer, tours: FleetTours, solver: str, stages: Stages
) -> Plan:
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
    return finish_plan(sub_site, sub_area, regions, sub, tour, layer.settings, Stages(None))


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


__all__ = [
    "FleetPlan",
    "FleetProblem",
    "IdleVehicle",
    "VehicleLayer",
    "fleet_problem",
    "plan_fleet",
]
