"""The tour flown: cut into sorties, written as missions, and checked as written.

The checks run on the missions as the vehicle will store them (positions on the 1e-7 degree
grid, altitude in whole centimetres): every stop still sees its targets (and, short of a
warning, keeps them in the picture from the whole disc of ``--position-tolerance`` around
it), every leg keeps its clearance over the terrain, and the height above ground stays within
``--max-agl``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import pyproj
from scipy import sparse

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.errors import PlanError
from urpt_gcs.flight.mission import (
    GeoPoint,
    Mission,
    build_mission,
    waypoint_positions,
)
from urpt_gcs.flight.refinement import Site, flies_from, written_grid
from urpt_gcs.flight.safety import (
    Leg,
    check_height_above_ground,
    check_legs,
    geofence_polygon,
    leg_clearances,
)
from urpt_gcs.flight.sorties import SEARCH_SHARE, SortieOrder, order_sorties
from urpt_gcs.pipeline.area import PlanArea, SiteInputs, altitude_rel, latlon_to_xy, xy_to_latlon
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.pipeline.stages import Stages
from urpt_gcs.problem.flight_time import FlightModel, Sortie, split_sorties
from urpt_gcs.problem.instance import Instance
from urpt_gcs.site.camera import true_bearing_deg
from urpt_gcs.site.dem import WGS84
from urpt_gcs.site.reading import fill_along
from urpt_gcs.solvers import Tour
from urpt_gcs.solvers.sortie_routes import viewpoints_seeing
from urpt_gcs.visibility.cover import cover_sets

# Other positions offered to the sortie search for each stop: its nearest candidates that see
# what it must (each checked on the terrain before the search).
ALTERNATIVES = 4
# Halvings of the way from a candidate that fails the checks to its stop.
_TOWARDS_STOP_STEPS = 6


@dataclass(frozen=True, slots=True)
class CheckedFlight:
    """The tour cut into sorties and written as missions, checked as written.

    Attributes
    ----------
    stop_names
        Each stop as messages name it (``stop 3 (viewpoint for T4+T7)``).
    sorties
        The tour's sorties, each from home and back.
    missions
        Each sortie's mission as written.
    legs
        Every leg of every mission, with its clearance over the terrain.
    geofence_latlon
        The geofence polygon, (lat, lon) degrees.
    warnings
        What the checks found that does not refuse the plan.
    """

    stop_names: list[str]
    sorties: tuple[Sortie, ...]
    missions: tuple[Mission, ...]
    legs: tuple[Leg, ...]
    geofence_latlon: tuple[tuple[float, float], ...]
    warnings: list[str]


def sorties_and_missions(
    site: SiteInputs,
    area: PlanArea,
    tour: Tour,
    settings: PlanSettings,
    stages: Stages,
    instance: Instance | None = None,
) -> tuple[Tour, SortieOrder | None, CheckedFlight]:
    """The tour ordered and cut into sorties, and its missions written and checked.

    Parameters
    ----------
    site, area
        The site and the area planned on (:func:`~urpt_gcs.pipeline.area.read_site`,
        :func:`~urpt_gcs.pipeline.area.read_area`).
    tour
        The tour to fly, its stops in the planning CRS.
    settings
        The plan's settings: endurance, speeds, mission and check options.
    stages
        Announces the ordering and the checks and keeps their times.
    instance
        The candidate viewpoints the tour was solved over: the sortie search may fly a stop
        from another of them that sees what it must (None: from where it is).

    Returns
    -------
    tuple of (Tour, SortieOrder or None, CheckedFlight)
        The tour in the order flown, how its sorties were ordered, and the flight written
        and checked.
    """
    endurance = None if settings.endurance_min is None else settings.endurance_min * 60.0
    budget = SEARCH_SHARE * settings.solve.time_limit_s
    model = flight_model(settings)
    stages.say(f"ordering the stops for sorties (up to {budget:.1f} s)")
    # Checked on the terrain only if the flight needs several sorties.
    alternatives = (
        None
        if instance is None
        else functools.partial(_alternatives, site, area, instance, tour, settings)
    )
    searched, sortie_order = order_sorties(
        tour,
        site.home_xy,
        altitude_rel(area),
        model,
        endurance,
        [f"stop {k}" for k in range(1, len(tour.sees) + 1)],
        budget,
        settings.solve.seed,
        alternatives,
    )
    stages.lap("sorties")
    stages.say("checking the missions")
    try:
        flight = _write_missions(site, area, searched, settings)
    except PlanError as exc:
        if sortie_order is None:
            raise
        # The search joins stops that the solver's tour never joined, and only the checks
        # read the terrain under those legs: when one fails, the solver's order is flown.
        flight = _write_missions(site, area, tour, settings)
        flight.warnings.append(
            f"the sorties searched failed a check ({exc}); the tour's own order is flown"
        )
        searched, sortie_order = tour, None
    stages.lap("checks")
    return searched, sortie_order, flight


def check_site(site: SiteInputs, area: PlanArea, settings: PlanSettings) -> Site:
    """What a stop is checked against: the position margin, the position, heading and height
    the mission writes, and the legs' clearance, on the terrain read so far (filled along new
    legs)."""
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

    def heading(xy: FloatArray, grid_deg: FloatArray) -> FloatArray:
        # As _headings writes it: the true bearing to a hundredth of a degree.
        true = true_bearing_deg(site.crs, xy, grid_deg)
        step = _HEADING_STEP_DEG
        out: FloatArray = grid_deg + (np.round(true / step) * step - true)
        return out

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
        written_eye_m=_home_amsl_m(area) + altitude_rel(area),
        written_heading=heading,
    )


def _home_amsl_m(area: PlanArea) -> float:
    """Home's height as the mission writes it: whole centimetres, rounded down, so that every
    check of the mission as written measures from a height the vehicle is at or above."""
    return math.floor(area.home_ground_m * 100.0) / 100.0


def _alternatives(
    site: SiteInputs, area: PlanArea, instance: Instance, tour: Tour, settings: PlanSettings
) -> tuple[FloatArray, IntArray] | None:
    """Other positions each stop may be flown from in the sortie search: its nearest
    candidate viewpoints that see every target it is counted for, checked as refinement checks
    a stop (from anywhere within the tolerance and as written, and the leg straight home). None
    for a frame camera (its stops carry headings) or a tour not over the plane's points."""
    if tour.headings_deg is not None or tour.points_xy is None or instance.points_xy is None:
        return None
    xy, own = viewpoints_seeing(instance, tour.points_xy, tour.sees, ALTERNATIVES)
    if own.size == 0:
        return None
    check = check_site(site, area, settings)
    home = np.asarray(site.home_xy, dtype=np.float64)
    # Candidates lie on the edge of what they see, where the tolerance disc leaves it: each
    # is drawn towards its stop (which passes) by halving, and the passing point nearest it
    # kept.
    stop_xy = tour.points_xy[own]
    # Each candidate takes its stop's row, many times over: sparse rows cost what they hold.
    rows = sparse.csr_array(tour.sees)
    ok = flies_from(check, xy, rows[own], home)
    lo = np.zeros(len(xy))  # share of the way to the stop known to fail (0: the candidate)
    hi = np.where(ok, 0.0, 1.0)  # share known to pass (1: the stop itself)
    for _ in range(_TOWARDS_STOP_STEPS):
        todo = np.flatnonzero(hi > lo)
        if todo.size == 0:
            break
        mid = 0.5 * (lo[todo] + hi[todo])
        at = xy[todo] + mid[:, None] * (stop_xy[todo] - xy[todo])
        passed = flies_from(check, at, rows[own[todo]], home)
        hi[todo] = np.where(passed, mid, hi[todo])
        lo[todo] = np.where(passed, lo[todo], mid)
    keep = hi < 1.0
    moved = xy + hi[:, None] * (stop_xy - xy)
    xy, own = moved[keep], own[keep]
    return xy, np.searchsorted(own, np.arange(len(tour.sees) + 1)).astype(np.int64)


def _write_missions(
    site: SiteInputs, area: PlanArea, tour: Tour, settings: PlanSettings
) -> CheckedFlight:
    """Cut the tour into sorties, write their missions and check them before anyone flies."""
    if tour.points_xy is None:
        raise PlanError(f"internal check failed: solver {tour.solver} returned no positions")
    names = site.names
    rel_m = altitude_rel(area)
    stop_names = [
        f"stop {k} ({_stop_name(row, names)})" for k, row in enumerate(tour.sees, start=1)
    ]
    endurance = None if settings.endurance_min is None else settings.endurance_min * 60.0
    sorties = split_sorties(
        tour.points_xy, site.home_xy, rel_m, flight_model(settings), endurance, stop_names
    )
    home = GeoPoint(*site.home_lat_lon, _home_amsl_m(area))
    stops_latlon = xy_to_latlon(site.crs, tour.points_xy)
    true_headings, written_grid = _headings(site.crs, tour, sorties)
    missions = tuple(
        build_mission(
            home,
            stops_latlon[s.first : s.stop],
            rel_m,
            settings.mission,
            None if true_headings is None else true_headings[s.first : s.stop].tolist(),
        )
        for s in sorties
    )
    legs, warnings = _check_as_written(
        site, area, missions, sorties, tour.sees, stop_names, settings, written_grid
    )
    warnings += check_legs(legs, settings.min_clearance_m)
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
    return CheckedFlight(
        stop_names, sorties, missions, legs, tuple(xy_to_latlon(site.crs, fence_xy)), warnings
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


def _check_as_written(
    site: SiteInputs,
    area: PlanArea,
    missions: tuple[Mission, ...],
    sorties: tuple[Sortie, ...],
    sees: BoolArray,
    stop_names: list[str],
    settings: PlanSettings,
    headings_deg: FloatArray | None = None,
) -> tuple[tuple[Leg, ...], list[str]]:
    """Check the missions as the vehicle will store them; return their legs and a warning
    for every target that leaves the picture from part of the tolerance disc of its stop.

    Positions are the written ones (on the 1e-7 degree grid), the altitude the written one
    (whole centimetres above home) and headings the written ones: every stop must still see
    every target the plan says it sees, and the legs' clearance is measured between those
    positions. The margin stage and refinement keep each target in the picture from the
    whole disc of ``--position-tolerance`` around its stop as written, short of a stop the
    margin stage could not place (it warned then); measured here again, exactly.
    """
    workers = settings.workers
    eye_m = missions[0].home.amsl_m + missions[0].altitude_rel_m
    written_camera = dataclasses.replace(area.camera, altitude_m=eye_m)
    legs: tuple[Leg, ...] = ()
    stops = []
    for sortie, mission in zip(sorties, missions, strict=True):
        home_xy = latlon_to_xy(site.crs, [(mission.home.lat_deg, mission.home.lon_deg)])
        at = latlon_to_xy(site.crs, waypoint_positions(mission))
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
    stop, target = np.nonzero(sees)
    margin = written_camera.view_margin_m(
        written[stop],
        site.targets_xy[target],
        area.ground_m[target],
        None if headings_deg is None else headings_deg[stop],
    )
    tolerance = settings.position_tolerance_m
    warnings = [
        f"{stop_names[k]} keeps target '{site.names[t]}' in the picture only within "
        f"{max(m, 0.0):.2f} m of its waypoint, not {tolerance:g} m: a vehicle that stops "
        "farther off may miss it"
        for k, t, m in zip(stop.tolist(), target.tolist(), margin.tolist(), strict=True)
        if m < tolerance
    ]
    return legs, warnings


def flight_model(settings: PlanSettings) -> FlightModel:
    """How the flight-time estimate sees the vehicle: its firmware's model at the settings'
    speeds.

    Parameters
    ----------
    settings
        The plan's settings (firmware, cruise speed, hold, climb, descent, acceleration).

    Returns
    -------
    FlightModel
        The model that times every leg, hold, take-off and landing of the plan.
    """
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


__all__ = ["ALTERNATIVES", "CheckedFlight", "check_site", "flight_model", "sorties_and_missions"]
