"""plan(): from a DEM and a target file to a checked tour and its mission.

Each stage is a function of the previous stage's value (see the package modules); this module
only chains them, decides the flight plane and the window of the DEM to read, and checks the
result against the terrain before anyone flies it.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyproj

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.bound.certificate import Certificate, bound_time_s, certify
from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import PlanError, SettingsError, TargetsError
from urpt_gcs.flight.margin import robust_tour
from urpt_gcs.flight.mission import (
    GeoPoint,
    Mission,
    build_mission,
    waypoint_positions,
)
from urpt_gcs.flight.refinement import Refinement, Site, refine_along, refine_tour, written_grid
from urpt_gcs.flight.safety import (
    FlightModel,
    Leg,
    Sortie,
    check_height_above_ground,
    check_legs,
    geofence_polygon,
    leg_clearances,
    split_sorties,
)
from urpt_gcs.flight.sorties import SEARCH_SHARE, SortieOrder, order_sorties
from urpt_gcs.memory import require_memory
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.instance import Instance, instance_bytes
from urpt_gcs.progress import Progress
from urpt_gcs.site.camera import true_bearing_deg
from urpt_gcs.site.dem import WGS84, DemInfo, check_elevations, open_dem, planning_crs
from urpt_gcs.site.reading import BlockCache, area_max, fill_along, read_mosaic, sample_points
from urpt_gcs.site.targets import SWAP_FIX, Target, TargetSet, read_targets
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour, choose, prepare, solve
from urpt_gcs.visibility.cover import build_instance, cover_sets
from urpt_gcs.visibility.outer import finer_stars, outer_regions
from urpt_gcs.visibility.regions import Camera, Region, visibility_regions

if TYPE_CHECKING:
    from urpt_gcs.pipeline.altitude import AltitudeSweep

# Extra DEM read around the operating area, in cells, so bilinear samples at its edge exist.
_WINDOW_MARGIN_CELLS = 4
# The narrowest camera cone a plan accepts, as a radius on the flight plane: ten times the
# 1e-7 degree grid waypoints are stored on, so a rounded waypoint stays well inside it.
MIN_CONE_RADIUS_M = 0.1


@dataclass(frozen=True, slots=True)
class Plan:
    """Everything a plan produced, stage by stage."""

    settings: PlanSettings
    dem: DemInfo
    terrain: Terrain
    targets: TargetSet
    crs: pyproj.CRS
    targets_xy: FloatArray
    ground_m: FloatArray
    home_xy: tuple[float, float]
    home_ground_m: float
    home_source: str
    camera: Camera
    terrain_max_m: float
    regions: tuple[Region, ...]
    instance: Instance
    tour: Tour
    legs: tuple[Leg, ...]
    sorties: tuple[Sortie, ...]
    missions: tuple[Mission, ...]
    geofence_latlon: tuple[tuple[float, float], ...]
    flight_time_s: float
    timings_s: dict[str, float]
    warnings: tuple[str, ...]
    sortie_order: SortieOrder | None = None
    # With --altitude auto: every altitude planned and the one kept.
    altitude_sweep: AltitudeSweep | None = None
    # The solver's tour before and after its stops were moved within their regions.
    refinement: Refinement | None = None
    # The certified lower bound of every flight that photographs every target.
    certificate: Certificate | None = None
    # The solver's claim for its tour (before any stop moved): no tour over the candidate
    # viewpoints is shorter.
    optimal_over_candidates: bool = False

    @property
    def lower_bound_m(self) -> float:
        """A lower bound of every flight from home that photographs every target, from
        anywhere on the plane (not only the candidate viewpoints)."""
        if self.certificate is not None:
            return self.certificate.lower_bound_m
        return min(geometric_lower_bound(self.instance), self.flown_length_m)

    @property
    def flown_length_m(self) -> float:
        """Length of every sortie as flown, each from home and back, added up."""
        return math.fsum(s.length_m for s in self.sorties)

    @property
    def flown_gap(self) -> float:
        """How much longer the flight may be than the shortest that sees every target:
        (flown - LB) / LB, with LB :attr:`lower_bound_m`.

        The bound holds for any closed flight from home that sees every target, and sorties
        from home joined at home are one such flight, no longer than their total: so it
        bounds the total of any set of sorties too.
        """
        bound = self.lower_bound_m
        if bound <= 0.0:
            return 0.0 if self.flown_length_m <= 0.0 else math.inf
        return max(self.flown_length_m - bound, 0.0) / bound

    @property
    def proven_optimal(self) -> bool:
        """Whether the flight is certified within the tolerance of the shortest possible."""
        return self.certificate is not None and self.certificate.proven(self.flown_length_m)

    @property
    def flight_model(self) -> FlightModel:
        return flight_model(self.settings)

    @property
    def mission(self) -> Mission:
        """The mission of the first (or only) sortie."""
        return self.missions[0]

    @property
    def altitude_rel_m(self) -> float:
        return self.mission.altitude_rel_m


def _pick_home(targets: TargetSet, settings: PlanSettings) -> tuple[float, float, str]:
    if settings.home is not None:
        return settings.home[0], settings.home[1], "--home"
    if targets.home is not None:
        return targets.home.lat_deg, targets.home.lon_deg, f"placemark '{targets.home.name}'"
    lat = float(np.mean([t.lat_deg for t in targets.targets]))
    lon = float(np.mean([t.lon_deg for t in targets.targets]))
    return lat, lon, "centroid of the targets (no Home placemark and no --home given)"


def _bbox(xy: FloatArray, pad: float) -> tuple[float, float, float, float]:
    lo = xy.min(axis=0) - pad
    hi = xy.max(axis=0) + pad
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _contains(
    outer: tuple[float, float, float, float], inner: tuple[float, float, float, float]
) -> bool:
    return (
        outer[0] <= inner[0]
        and outer[1] <= inner[1]
        and outer[2] >= inner[2]
        and outer[3] >= inner[3]
    )


def _check_swapped(
    info: DemInfo, site: TargetSet, home: tuple[float, float], home_source: str
) -> None:
    """Refuse, with a hint, a point off the DEM that swapped lat and lon would put on it.

    Checked before anything else uses the points: a point far off the site otherwise fails
    later and less clearly (no DEM window, a UTM zone edge, a distorted projection).
    """
    points = [(f"target '{t.name}'", t.lat_deg, t.lon_deg) for t in site.targets]
    points.append((f"home ({home_source})", *home))
    lat = np.array([p[1] for p in points])
    lon = np.array([p[2] for p in points])
    off = ~_on_dem(info, lat, lon)
    swapped = off & _on_dem(info, lon, lat)
    if not swapped.any():
        return
    i = int(np.flatnonzero(swapped)[0])
    where, a, b = points[i]
    problem = (
        f"lies outside DEM '{info.path}', and ({b:.7f}, {a:.7f}) would lie on it: "
        "did you swap lat and lon?"
    )
    if i == len(points) - 1 and home_source == "--home":
        raise SettingsError(f"--home {a},{b} {problem} Give --home LAT,LON: --home {b},{a}")
    fix = SWAP_FIX.get(Path(site.source).suffix.lower(), "swap the two numbers")
    raise TargetsError(
        f"{where} ({a:.7f}, {b:.7f}) in targets file '{site.source}' {problem} "
        f"{fix[0].upper()}{fix[1:]}"
    )


def _on_dem(info: DemInfo, lat: FloatArray, lon: FloatArray) -> BoolArray:
    """Which WGS84 points fall inside the DEM's extent (any point off the globe does not)."""
    ok = (np.abs(lat) <= 90.0) & (np.abs(lon) <= 180.0)
    to_src = pyproj.Transformer.from_crs(WGS84, info.horizontal_crs, always_xy=True)
    sx, sy = to_src.transform(np.where(ok, lon, 0.0), np.where(ok, lat, 0.0), errcheck=False)
    col, row = ~info.transform @ (np.asarray(sx), np.asarray(sy))
    with np.errstate(invalid="ignore"):
        inside = (col >= 0) & (col <= info.width_px) & (row >= 0) & (row <= info.height_px)
    return np.asarray(ok & np.isfinite(col) & np.isfinite(row) & inside, dtype=np.bool_)


def _check_ground(
    info: DemInfo,
    ground: FloatArray,
    names: list[str],
    lat_lon: list[tuple[float, float]],
    xy: FloatArray,
) -> FloatArray:
    """The ground elevation at each point, or an error naming the first point without one."""
    bad = np.flatnonzero(~np.isfinite(ground))
    if bad.size == 0:
        return ground
    check_elevations(info)
    i = int(bad[0])
    lat, lon = lat_lon[i]
    to_src = pyproj.Transformer.from_crs(WGS84, info.horizontal_crs, always_xy=True)
    sx, sy = to_src.transform(lon, lat)
    col, row = ~info.transform @ (sx, sy)
    where = f"{names[i]} ({lat:.7f}, {lon:.7f})"
    if not (0 <= col <= info.width_px and 0 <= row <= info.height_px):
        raise TargetsError(
            f"{where} lies outside DEM '{info.path}': remove it from the target file or use a "
            "DEM that covers it"
        )
    raise TargetsError(
        f"{where} is on a nodata cell of DEM '{info.path}': move it onto surveyed ground"
    )


def _require_window(
    info: DemInfo,
    cell_m: float,
    need: tuple[float, float, float, float],
    altitude_m: float,
    settings: PlanSettings,
) -> None:
    """Refuse a camera cone whose DEM window would not fit the memory budget.

    The window is counted in full even where it runs past the DEM: every ray of the
    visibility sweep and every line of sight is sampled that far, cell by cell.
    """
    width = math.ceil((need[2] - need[0]) / cell_m)
    height = math.ceil((need[3] - need[1]) / cell_m)
    # The grid spanning the cones holds float64 elevations at most.
    per_cell = 8
    if settings.altitude_m is not None:
        cause = f"--altitude {altitude_m:g} m"
    else:
        cause = f"--clearance {settings.clearance_m:g} m (camera at {altitude_m:.0f} m)"
    require_memory(
        float(width) * float(height) * per_cell,
        f"{cause} with --fov {settings.fov_deg:g}: the camera cone needs a DEM window of "
        f"{width} x {height} cells, which",
        "lower --altitude/--clearance or narrow the camera (--fov)",
    )


@dataclass(frozen=True, slots=True)
class _Site:
    """The targets and home, placed in the planning CRS."""

    targets: TargetSet
    dem: DemInfo
    crs: pyproj.CRS
    names: list[str]
    targets_xy: FloatArray
    home_lat_lon: tuple[float, float]
    home_xy: tuple[float, float]
    home_source: str


@dataclass(frozen=True, slots=True)
class _Area:
    """The DEM window planned on, the ground under the points and the flight plane."""

    terrain: Terrain
    ground_m: FloatArray
    home_ground_m: float
    terrain_max_m: float
    camera: Camera


@dataclass(frozen=True, slots=True)
class _Flight:
    """The tour cut into sorties and written as missions, checked as written."""

    stop_names: list[str]
    sorties: tuple[Sortie, ...]
    missions: tuple[Mission, ...]
    legs: tuple[Leg, ...]
    geofence_latlon: tuple[tuple[float, float], ...]
    warnings: list[str]


class _Stages:
    """Announces each stage and keeps how long it took."""

    def __init__(self, progress: Progress | None) -> None:
        self.say = progress or (lambda _msg: None)
        self.timings_s: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timings_s[name] = now - self._clock
        self._clock = now


def plan(
    dem_path: Path,
    targets_path: Path,
    settings: PlanSettings | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Plan a mission that photographs every target from the flight plane.

    Parameters
    ----------
    dem_path
        GeoTIFF DSM/DEM of the site.
    targets_path
        KML/KMZ, GeoJSON or CSV of the targets (a point named Home or Launch is the take-off).
    settings
        Camera, flight plane, solver and mission choices; defaults if omitted.
    progress
        Called with a short message as each stage starts.

    Returns
    -------
    Plan
        The checked tour, its mission and everything computed on the way.
    """
    settings = settings or PlanSettings()
    stages = _Stages(progress)
    stages.say("reading targets")
    site = _read_site(dem_path, targets_path, settings)
    stages.lap("targets")
    stages.say("reading terrain")
    area = _read_area(site, settings)
    stages.lap("terrain")
    stages.say(f"visibility of {len(site.names)} targets")
    regions = visibility_regions(
        area.terrain,
        site.targets_xy,
        area.ground_m,
        area.camera,
        settings.samples,
        settings.workers,
    )
    stages.lap("visibility")
    stages.say("checking viewpoints")
    instance = build_instance(
        area.terrain,
        regions,
        site.targets_xy,
        area.ground_m,
        area.camera,
        site.home_xy,
        area.terrain_max_m,
        settings.workers,
    )
    stages.lap("viewpoints")
    solver = choose(instance, settings.solver)
    stages.say(f"preparing the {solver} solver (compiled on first use)")
    prepare(solver)
    stages.lap("compile")
    stages.say(f"solving ({instance.n_viewpoints} viewpoints)")
    tour = solve(instance, solver, settings.solve)
    stages.lap("solve")
    return finish_plan(site, area, regions, instance, tour, settings, stages)


def finish_plan(
    site: _Site,
    area: _Area,
    regions: tuple[Region, ...],
    instance: Instance,
    tour: Tour,
    settings: PlanSettings,
    stages: _Stages,
) -> Plan:
    """From the solver's tour to the checked plan: stops given their margin, ordered and cut
    into sorties, written as missions and checked as written."""
    over_candidates = tour.proven_optimal
    stages.say(f"stops seeing from anywhere within {settings.position_tolerance_m:g} m")
    tour, margin_warnings = robust_tour(
        area.terrain,
        site.targets_xy,
        area.ground_m,
        area.camera,
        tour,
        site.home_xy,
        settings.position_tolerance_m,
        site.names,
    )
    stages.lap("margin")
    refinement = None
    if settings.refine:
        stages.say("moving the stops within what they see")
        tour, refinement = _refine(site, area, tour, settings)
        stages.lap("refine")
    planned = tour
    tour, sortie_order, flight = _sorties_and_checks(site, area, planned, settings, stages)
    certificate = None
    if settings.certify:
        bound_s = settings.bound_time_s or bound_time_s(settings.solve.time_limit_s)
        stages.say(f"bounding the shortest possible flight (up to {bound_s:.1f} s)")
        flown_m = math.fsum(s.length_m for s in flight.sorties)
        certificate = _certify(
            site, area, instance, flown_m, bound_s, settings.workers, settings.position_tolerance_m
        )
        stages.lap("bound")
        if refinement is not None:
            stages.say("reading a tour off the bound")
            better = _bounds_tour(site, area, planned, certificate, settings, flown_m)
            stages.lap("bound's tour")
            if better is not None:
                # Shorter as flown too: it is the plan.
                (tour, sortie_order, flight), other_m, refined_m = better
                refinement = dataclasses.replace(refinement, after_m=refined_m)
                certificate = dataclasses.replace(
                    certificate, lower_bound_m=min(certificate.lower_bound_m, other_m)
                )
    return Plan(
        settings=settings,
        dem=site.dem,
        terrain=area.terrain,
        targets=site.targets,
        crs=site.crs,
        targets_xy=site.targets_xy,
        ground_m=area.ground_m,
        home_xy=site.home_xy,
        home_ground_m=area.home_ground_m,
        home_source=site.home_source,
        camera=area.camera,
        terrain_max_m=area.terrain_max_m,
        regions=regions,
        instance=instance,
        tour=tour,
        legs=flight.legs,
        sorties=flight.sorties,
        missions=flight.missions,
        geofence_latlon=flight.geofence_latlon,
        flight_time_s=sum(s.flight_time_s for s in flight.sorties),
        timings_s=stages.timings_s,
        warnings=(*margin_warnings, *flight.warnings),
        sortie_order=sortie_order,
        refinement=refinement,
        certificate=certificate,
        optimal_over_candidates=over_candidates,
    )


def _sorties_and_checks(
    site: _Site, area: _Area, tour: Tour, settings: PlanSettings, stages: _Stages
) -> tuple[Tour, SortieOrder | None, _Flight]:
    """The tour ordered and cut into sorties, and its missions written and checked."""
    endurance = None if settings.endurance_min is None else settings.endurance_min * 60.0
    budget = SEARCH_SHARE * settings.solve.time_limit_s
    stages.say(f"ordering the stops for sorties (up to {budget:.1f} s)")
    tour, sortie_order = order_sorties(
        tour,
        site.home_xy,
        _altitude_rel(area),
        flight_model(settings),
        endurance,
        [f"stop {k}" for k in range(1, len(tour.sees) + 1)],
        budget,
        settings.solve.seed,
    )
    stages.lap("sorties")
    stages.say("checking the missions")
    flight = _fly(site, area, tour, settings)
    stages.lap("checks")
    return tour, sortie_order, flight


def _bounds_tour(
    site: _Site,
    area: _Area,
    tour: Tour,
    certificate: Certificate,
    settings: PlanSettings,
    flown_m: float,
) -> tuple[tuple[Tour, SortieOrder | None, _Flight], float, float] | None:
    """The tour read off the certified bound's relaxed tour and refined, checked as the
    mission will be, cut into sorties and checked, with its flown and refined lengths: when
    it is shorter than ``tour`` (the refined tour) and than ``flown_m`` as flown; else None."""
    if certificate.relaxed_tour_xy is None:
        return None
    check = _check_site(site, area, settings)
    read = refine_along(check, certificate.relaxed_tour_xy, site.home_xy, tour, _REFINE_MAX_S)
    if read is None:
        return None
    found = read[0]
    if found.length >= tour.length * (1.0 - _BETTER):
        return None
    flown = _sorties_and_checks(site, area, found, settings, _Stages(None))
    other_m = math.fsum(s.length_m for s in flown[2].sorties)
    return (flown, other_m, found.length) if other_m < flown_m else None


# How much shorter a tour read off the bound must be to replace the refined one.
_BETTER = 1e-6

# Seconds refinement may take at most: it ends when its steps are down to a centimetre (so
# that a plan does not depend on the machine's load), this only guards against a runaway.
_REFINE_MAX_S = 60.0


def _refine(
    site: _Site, area: _Area, tour: Tour, settings: PlanSettings
) -> tuple[Tour, Refinement]:
    """Move the stops within what they see, checked as the mission will be (the position
    margin, the written grid and the legs' clearance)."""
    return refine_tour(_check_site(site, area, settings), tour, site.home_xy, _REFINE_MAX_S)


def _check_site(site: _Site, area: _Area, settings: PlanSettings) -> Site:
    """What a stop is checked against: the position margin, the written grid and the legs'
    clearance, on the terrain read so far (filled along new legs)."""
    to_geo = pyproj.Transformer.from_crs(site.crs, WGS84, always_xy=True)
    to_grid = pyproj.Transformer.from_crs(WGS84, site.crs, always_xy=True)

    def to_latlon(xy: FloatArray) -> FloatArray:
        lon, lat = to_geo.transform(xy[:, 0], xy[:, 1])
        return np.column_stack([lat, lon]).astype(np.float64)

    def to_xy(lat_lon: FloatArray) -> FloatArray:
        x, y = to_grid.transform(lat_lon[:, 1], lat_lon[:, 0])
        return np.column_stack([x, y]).astype(np.float64)

    def fill(a: FloatArray, b: FloatArray) -> None:
        fill_along(site.dem, area.terrain, a, b)

    return Site(
        terrain=area.terrain,
        targets_xy=site.targets_xy,
        ground_m=area.ground_m,
        camera=area.camera,
        tolerance_m=settings.position_tolerance_m,
        min_clearance_m=settings.min_clearance_m,
        written=written_grid(to_latlon, to_xy),
        fill=fill,
        workers=settings.workers,
    )


def _certify(
    site: _Site,
    area: _Area,
    instance: Instance,
    flown_m: float,
    time_limit_s: float,
    workers: int | None,
    hold_m: float,
) -> Certificate:
    """The certified lower bound of every flight from home whose stops see every target from
    anywhere within ``hold_m`` of them."""
    regions, ratio = outer_regions(
        area.terrain,
        site.targets_xy,
        area.ground_m,
        area.camera,
        site.home_xy,
        workers=workers,
        hold_m=hold_m,
    )
    also = geometric_lower_bound(instance)
    tighten = finer_stars(area.terrain, area.camera, workers, hold_m)
    return certify(regions, flown_m, time_limit_s, also, ratio, tighten)


def _read_site(dem_path: Path, targets_path: Path, settings: PlanSettings) -> _Site:
    """Read the targets and the DEM's description; place them in the planning CRS."""
    targets = read_targets(targets_path)
    # Every target offers its nadir and a viewpoint per azimuth, each seeing at least its own
    # target, and the tour records which targets each stop sees (a stop per target at most):
    # refuse, before any work, a target count whose instance and tour could not fit.
    m = len(targets.targets)
    n = m * (settings.samples + 1)
    require_memory(
        instance_bytes(n, n) + float(m) * float(m),
        f"{m} targets in {targets.source!r} at --samples {settings.samples}: "
        f"{n} viewpoints, their cover sets and the tour's stop-by-target table",
        "plan fewer targets at a time (split the file) or use fewer --samples",
    )
    info = open_dem(dem_path, settings.band)
    home_lat, home_lon, home_source = _pick_home(targets, settings)
    _check_swapped(info, targets, (home_lat, home_lon), home_source)
    lat_lon = [(t.lat_deg, t.lon_deg) for t in targets.targets]
    lats = [p[0] for p in lat_lon] + [home_lat]
    lons = [p[1] for p in lat_lon] + [home_lon]
    crs = planning_crs(info, (min(lons), min(lats), max(lons), max(lats)))
    home_xy = _xy(crs, [(home_lat, home_lon)])[0]
    return _Site(
        targets=targets,
        dem=info,
        crs=crs,
        names=[t.name for t in targets.targets],
        targets_xy=_xy(crs, lat_lon),
        home_lat_lon=(home_lat, home_lon),
        home_xy=(float(home_xy[0]), float(home_xy[1])),
        home_source=home_source,
    )


def _read_area(site: _Site, settings: PlanSettings) -> _Area:
    """Read the DEM where the camera cones need it and fix the flight plane.

    Without ``--altitude`` the plane sits ``--clearance`` above the highest terrain of the
    operating area (the box of the points widened by the widest cone), found one block at a
    time; a higher plane widens the cones, which may widen the area: repeat until it holds
    them. Then only the source blocks the cone of some target (or home) touches are read.
    """
    info, crs = site.dem, site.crs
    points_xy = np.vstack([site.targets_xy, np.array([site.home_xy])])
    tan = settings.camera_at(0.0).tan_fov
    cell_m = _cell_m(info, crs, points_xy)
    margin = _WINDOW_MARGIN_CELLS * cell_m
    # The ground under the points first, from the few cells around each.
    ground = _check_ground(
        info,
        sample_points(info, crs, points_xy),
        [*(f"target '{n}'" for n in site.names), f"home ({site.home_source})"],
        [*((t.lat_deg, t.lon_deg) for t in site.targets.targets), site.home_lat_lon],
        points_xy,
    )[:-1]

    def cone_boxes(altitude_m: float) -> FloatArray:
        cones = np.maximum(altitude_m - ground, 0.0) * tan
        return _boxes(points_xy, np.append(cones, 0.0) + margin)

    # The plane only rises from pass to pass, and the cones widen with it: blocks inside the
    # cones of the lowest plane possible so far are kept as read, for the mosaic.
    altitude = (
        settings.altitude_m
        if settings.altitude_m is not None
        else float(ground.max()) + settings.clearance_m
    )
    cache = BlockCache(info)
    area = _bbox(points_xy, 0.0)
    top = area_max(info, crs, area, cache, cone_boxes(altitude))
    for _ in range(12):
        altitude = (
            settings.altitude_m if settings.altitude_m is not None else (top + settings.clearance_m)
        )
        reach = max(altitude - float(ground.min()), 0.0) * tan
        need = _bbox(points_xy, reach + margin)
        if _contains(area, need):
            break
        _require_window(info, cell_m, need, altitude, settings)
        area = need
        top = area_max(info, crs, area, cache, cone_boxes(altitude))
    terrain = read_mosaic(info, crs, cone_boxes(altitude), cache)
    # Heights from the grid planned on: a geographic DEM's fitted georeferencing differs
    # slightly from one grid to the next, and every line of sight ends on the target.
    all_ground = terrain.sample(points_xy[:, 0], points_xy[:, 1])
    ground, home_ground = all_ground[:-1], float(all_ground[-1])
    low = np.flatnonzero(ground >= altitude)
    if low.size:
        i = int(low[0])
        raise SettingsError(
            f"--altitude {altitude:g} m is at or below the terrain at target '{site.names[i]}' "
            f"({ground[i]:.1f} m): raise it above {float(ground.max()):.1f} m or use --clearance"
        )
    if home_ground >= altitude:
        raise SettingsError(
            f"--altitude {altitude:g} m is at or below the ground at home ({home_ground:.1f} m): "
            "raise it or use --clearance"
        )
    camera = settings.camera_at(altitude)
    _check_gsd(camera, ground, site.names)
    _check_cone_width(camera, ground, site.names, settings.position_tolerance_m)
    return _Area(terrain, ground, home_ground, top, camera)


def _boxes(xy: FloatArray, radius_m: FloatArray) -> FloatArray:
    """Boxes (xmin, ymin, xmax, ymax) around points, ``radius_m`` out on every side."""
    r = np.asarray(radius_m, dtype=np.float64)
    return np.column_stack([xy[:, 0] - r, xy[:, 1] - r, xy[:, 0] + r, xy[:, 1] + r])


def _cell_m(info: DemInfo, crs: pyproj.CRS, points_xy: FloatArray) -> float:
    """The DEM's cell size in metres in the planning CRS near the points."""
    t = info.transform
    if not (info.needs_warp or crs != info.horizontal_crs):
        return float(min(abs(t.a), abs(t.e)))
    to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
    to_crs = pyproj.Transformer.from_crs(info.horizontal_crs, crs, always_xy=True)
    sx, sy = to_src.transform(float(points_xy[0, 0]), float(points_xy[0, 1]))
    x0, y0 = to_crs.transform(sx, sy)
    x1, y1 = to_crs.transform(sx + t.a, sy)
    x2, y2 = to_crs.transform(sx, sy + t.e)
    return float(min(math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x0, y2 - y0)))


def _fly(site: _Site, area: _Area, tour: Tour, settings: PlanSettings) -> _Flight:
    """Cut the tour into sorties, write their missions and check them before anyone flies."""
    if tour.points_xy is None:
        raise PlanError(f"internal check failed: solver {tour.solver} returned no positions")
    names = site.names
    altitude_rel = _altitude_rel(area)
    stop_names = [
        f"stop {k} ({_stop_name(row, names)})" for k, row in enumerate(tour.sees, start=1)
    ]
    endurance = None if settings.endurance_min is None else settings.endurance_min * 60.0
    sorties = split_sorties(
        tour.points_xy, site.home_xy, altitude_rel, flight_model(settings), endurance, stop_names
    )
    # Home written a little low (whole centimetres, down): every check of the mission as
    # written then measures from a height the vehicle is at or above.
    home = GeoPoint(*site.home_lat_lon, math.floor(area.home_ground_m * 100.0) / 100.0)
    stops_latlon = _latlon(site.crs, tour.points_xy)
    true_headings, written_grid = _headings(site.crs, tour, sorties)
    missions = tuple(
        build_mission(
            home,
            stops_latlon[s.first : s.stop],
            altitude_rel,
            settings.mission,
            None if true_headings is None else true_headings[s.first : s.stop].tolist(),
        )
        for s in sorties
    )
    legs = _check_as_written(
        site, area, missions, sorties, tour.sees, stop_names, settings.workers, written_grid
    )
    warnings = check_legs(legs, settings.min_clearance_m)
    stop_ground = area.terrain.sample(tour.points_xy[:, 0], tour.points_xy[:, 1])
    warnings += check_height_above_ground(
        area.camera.altitude_m,
        stop_ground,
        stop_names,
        area.home_ground_m,
        settings.max_agl_m,
        settings.strict,
    )
    if len(sorties) > 1:
        warnings.append(
            f"the tour needs {len(sorties)} sorties to fit --endurance "
            f"{settings.endurance_min:g} min; each returns home"
        )
    fence_xy = geofence_polygon(
        np.vstack([[site.home_xy], tour.points_xy, site.targets_xy]), settings.geofence_margin_m
    )
    return _Flight(
        stop_names, sorties, missions, legs, tuple(_latlon(site.crs, fence_xy)), warnings
    )


# Headings are written to the mission in hundredths of a degree.
_HEADING_STEP_DEG = 0.01


def _headings(
    crs: pyproj.CRS, tour: Tour, sorties: tuple[Sortie, ...]
) -> tuple[FloatArray | None, FloatArray | None]:
    """Each stop's heading as the mission gives it (true north, degrees in [0, 360)) and that
    written heading back in the planning grid, for the checks; None for the cone.

    A frame looks the same turned half a turn, so each stop takes whichever of its two
    headings is nearer the stop before it in its sortie: the vehicle never turns more than
    90 degrees between photos.
    """
    if tour.headings_deg is None or tour.points_xy is None:
        return None, None
    grid = np.asarray(tour.headings_deg, dtype=np.float64) % 180.0
    for sortie in sorties:
        for k in range(sortie.first + 1, sortie.stop):
            turn = (grid[k] - grid[k - 1] + 180.0) % 360.0 - 180.0
            if abs(turn) > 90.0:
                grid[k] = (grid[k] + 180.0) % 360.0
    true = true_bearing_deg(crs, tour.points_xy, grid)
    written = np.round(true / _HEADING_STEP_DEG) * _HEADING_STEP_DEG % 360.0
    back: FloatArray = grid + (written - true)
    return written, back


def _altitude_rel(area: _Area) -> float:
    """The plane's height above home as written: centimetres, rounded up, since a higher eye
    only widens the cone and lifts every line of sight, so nothing checked is lost."""
    return math.ceil((area.camera.altitude_m - area.home_ground_m) * 100.0) / 100.0


def _check_gsd(camera: Camera, ground_m: FloatArray, names: list[str]) -> None:
    """Refuse a plane too high for ``--gsd`` over some target: no photo from it resolves it."""
    far = camera.max_distance_m
    height = camera.altitude_m - ground_m
    i = int(np.argmax(height))
    if height[i] < far:
        return
    assert camera.gsd_cm is not None
    raise SettingsError(
        f"--gsd {camera.gsd_cm:g} cm needs the camera within {far:.1f} m of target "
        f"'{names[i]}', but the plane is {height[i]:.1f} m above it: lower --altitude or "
        "--clearance, or ask for a coarser --gsd"
    )


def _check_cone_width(
    camera: Camera, ground_m: FloatArray, names: list[str], tolerance_m: float
) -> None:
    """Refuse a camera cone too narrow for a waypoint to be placed inside it, or for the
    vehicle to photograph from within ``tolerance_m`` of it."""
    cone = camera.least_half_width_m(ground_m)
    i = int(np.argmin(cone))
    least = max(MIN_CONE_RADIUS_M, 2.0 * tolerance_m)
    if cone[i] >= least:
        return
    if camera.frame is not None:
        raise SettingsError(
            f"the frame camera sees only {cone[i] * 100:.2g} cm around target '{names[i]}' "
            f"(its short side, within any --gsd distance), under the {least:g} m a stop needs "
            "(twice --position-tolerance): raise --altitude or --clearance, ask for a coarser "
            "--gsd, or lower --position-tolerance"
        )
    height = camera.altitude_m - float(ground_m[i])
    need = math.ceil(math.degrees(math.atan(least / height)) * 1000) / 1000
    seen = f"--fov {camera.fov_deg:g} sees only {cone[i] * 100:.2g} cm around target '{names[i]}'"
    if least > MIN_CONE_RADIUS_M:
        raise SettingsError(
            f"{seen}, under twice the {tolerance_m:g} m the vehicle may stop off its waypoint "
            f"(--position-tolerance): use --fov {need:g} or more, or lower --position-tolerance"
        )
    raise SettingsError(
        f"{seen}, finer than a waypoint can be placed (1e-7 degree, about 1 cm): "
        f"use --fov {need:g} or more"
    )


def _check_as_written(
    site: _Site,
    area: _Area,
    missions: tuple[Mission, ...],
    sorties: tuple[Sortie, ...],
    sees: BoolArray,
    stop_names: list[str],
    workers: int | None,
    headings_deg: FloatArray | None = None,
) -> tuple[Leg, ...]:
    """Check the missions as the vehicle will store them, and return their legs.

    Positions are the written ones (on the 1e-7 degree grid) and the altitude the written one
    (whole centimetres above home): every stop must still see every target the plan says it
    sees, and the legs' clearance is measured between those positions.
    """
    eye_m = missions[0].home.amsl_m + missions[0].altitude_rel_m
    written_camera = dataclasses.replace(area.camera, altitude_m=eye_m)
    legs: tuple[Leg, ...] = ()
    stops = []
    for sortie, mission in zip(sorties, missions, strict=True):
        home_xy = _xy(site.crs, [(mission.home.lat_deg, mission.home.lon_deg)])
        at = _xy(site.crs, waypoint_positions(mission))
        stops.append(at)
        path = np.vstack([home_xy, at, home_xy])
        # The mosaic holds the cones; a leg between them crosses blocks read only now.
        fill_along(site.dem, area.terrain, path[:-1], path[1:])
        legs += leg_clearances(
            area.terrain, path, ["home", *stop_names[sortie.first : sortie.stop], "home"], eye_m
        )
    written = np.vstack(stops)
    seen = cover_sets(
        area.terrain, written, site.targets_xy, area.ground_m, written_camera, workers, headings_deg
    )
    lost = np.argwhere(sees & ~seen)
    if lost.size:
        k, t = (int(v) for v in lost[0])
        raise PlanError(
            f"{stop_names[k]} no longer sees target '{site.names[t]}' once its position is "
            "written to the mission's 1e-7 degree grid: it sits on the edge of what the camera "
            "sees; widen --fov, raise --samples or change --altitude"
        )
    return legs


def flight_model(settings: PlanSettings) -> FlightModel:
    """How the flight-time estimate sees the vehicle: its firmware's model at the settings'
    speeds."""
    make = FlightModel.arducopter if settings.mission.firmware == "ardupilot" else FlightModel.px4
    return make(
        cruise_m_s=settings.mission.cruise_speed_m_s,
        hold_s=settings.mission.hold_s,
        climb_m_s=settings.climb_m_s,
        descent_m_s=settings.descent_m_s,
        accel_m_s2=settings.accel_m_s2,
    )


def _stop_name(sees: BoolArray, names: list[str]) -> str:
    return "viewpoint for " + "+".join(names[t] for t in np.flatnonzero(sees).tolist())


def _xy(crs: pyproj.CRS, lat_lon: list[tuple[float, float]]) -> FloatArray:
    to_xy = pyproj.Transformer.from_crs(WGS84, crs, always_xy=True)
    x, y = to_xy.transform([p[1] for p in lat_lon], [p[0] for p in lat_lon])
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y)]).astype(np.float64)


def _latlon(crs: pyproj.CRS, xy: FloatArray) -> list[tuple[float, float]]:
    to_geo = pyproj.Transformer.from_crs(crs, WGS84, always_xy=True)
    lon, lat = to_geo.transform(xy[:, 0], xy[:, 1])
    return list(zip(np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist(), strict=True))


__all__ = ["Leg", "Plan", "Target", "plan"]
