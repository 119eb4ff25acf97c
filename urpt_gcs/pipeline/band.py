"""The plan inside a height band (``--agl FLOOR:CEILING``): a flight that follows the terrain.

The stage chain of :func:`~urpt_gcs.pipeline.planner.plan` with the flight plane replaced
by the band:

1. viewpoints in three dimensions inside the band, with what each sees from anywhere within
   the position tolerance (:mod:`urpt_gcs.visibility.band`);
2. the tour over them, its legs costed in flight time (horizontal, climb and descent limits
   of the flight model) between straight legs -- the solver core sees points, cover sets
   and a table of times;
3. every leg made to follow the terrain inside the band, waypoints without a photo inserted
   where a straight leg would leave it (:mod:`urpt_gcs.flight.band`); the sorties searched
   over those legs' times (:func:`urpt_gcs.solvers.sortie_routes.search_routes`), written as
   missions whose waypoints each carry their own height above home, and checked as written;
4. the certificate: a lower bound of the horizontal length of any flight in the band that
   sees every target, and from it a lower bound of the flight time.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.bound.certificate import Certificate, bound_time_s
from urpt_gcs.bound.geometric import greedy_disjoint
from urpt_gcs.bound.lower_bound import lower_bound, sorties_through
from urpt_gcs.bound.order_bound import prepare as prepare_bound
from urpt_gcs.bound.sorties import SORTIES_SHARE, SortieBudget, sortie_bound
from urpt_gcs.errors import PlanError
from urpt_gcs.flight.band import FlightBand, band_profile
from urpt_gcs.flight.band_refine import BandStops, refine_band_stops
from urpt_gcs.flight.follow import path_in_band
from urpt_gcs.flight.mission import GeoPoint, Mission, build_mission
from urpt_gcs.flight.safety import Leg, geofence_polygon
from urpt_gcs.flight.sorties import SEARCH_SHARE
from urpt_gcs.memory import require_memory
from urpt_gcs.pipeline.area import PlanArea, SiteInputs, latlon_to_xy, site_fields, xy_to_latlon
from urpt_gcs.pipeline.missions import flight_model
from urpt_gcs.pipeline.result import BandFlight, Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.pipeline.stages import Stages, solve_stage
from urpt_gcs.problem.flight_time import FlightModel, Sortie, SortieLegs, cut_sorties
from urpt_gcs.problem.instance import Covers, Instance
from urpt_gcs.site.camera import true_bearing_deg
from urpt_gcs.site.reading import fill_along
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour
from urpt_gcs.solvers.sortie_routes import NEIGHBOURS, search_routes
from urpt_gcs.visibility.band import BandViewpoints, band_levels, band_viewpoints, sees_from
from urpt_gcs.visibility.band_outer import BandOuter, band_outer

__all__ = ["MAX_BAND_VIEWPOINTS", "plan_in_band"]

# Candidates the band offers the solver at most: its table of leg times is dense.
MAX_BAND_VIEWPOINTS = 4000
# Candidates around each one whose legs to it are costed with the ground under them (a
# tour's legs join near neighbours; a candidate's copies at three heights count thrice).
_NEAR_COUNT = 300
# Heights are written in whole centimetres.
_CM = 100.0
# Up to this many stops the sortie search may join any two (every leg between them is
# followed and timed); above it, each stop only to its nearest.
_ALL_PAIRS_MAX = 80


def plan_in_band(site: SiteInputs, area: PlanArea, settings: PlanSettings, stages: Stages) -> Plan:
    """Plan a flight that photographs every target from inside the height band.

    Parameters
    ----------
    site, area
        The site and the DEM window (read for the plane at the band's ceiling over the
        highest terrain, which holds every cone the band can reach).
    settings
        The plan's settings; ``agl_band_m`` gives the band.
    stages
        Announces each stage and keeps its time.

    Returns
    -------
    Plan
        The checked flight, its missions and its certificate; ``band_flight`` holds the
        paths in three dimensions.
    """
    assert settings.agl_band_m is not None
    band = FlightBand(*settings.agl_band_m)
    model = flight_model(settings)
    tol = settings.position_tolerance_m
    stages.say(f"viewpoints of {len(site.names)} targets inside the band {band.describe()}")
    views = band_viewpoints(
        area.terrain,
        area.camera,
        site.targets_xy,
        area.ground_m,
        band.floor_m,
        band.ceiling_m,
        tol,
        MAX_BAND_VIEWPOINTS,
        site.names,
        settings.workers,
    )
    stages.lap("viewpoints")
    takeoff_m = float(np.ceil(band_levels(band.floor_m, band.ceiling_m, tol)[0] * _CM) / _CM)
    home_xyz = np.array([*site.home_xy, area.home_ground_m + takeoff_m])
    instance = _time_instance(
        area.terrain,
        band,
        views,
        home_xyz,
        model,
        takeoff_m,
        site.targets_xy.shape[0],
        settings.workers,
    )
    stages.lap("costs")
    tour = solve_stage(instance, settings, stages)
    order = np.asarray(tour.order, dtype=np.int64)
    stages.say("following the terrain between the stops")
    home_sorties = _HomeSorties(site, area, band, model, home_xyz, takeoff_m)
    perm = home_sorties.search(views.xyz[order], settings)
    order = order[perm]
    tour = dataclasses.replace(
        tour,
        order=tuple(order.tolist()),
        sees=tour.sees[perm],
        points_xy=None if tour.points_xy is None else tour.points_xy[perm],
    )
    stops = views.xyz[order]
    headings = None if views.heading_deg is None else views.heading_deg[order]
    flight = _fly(site, area, band, model, settings, stops, home_xyz, takeoff_m, tour, headings)
    stages.lap("sorties")
    unrefined_s = sum(x.flight_time_s for x in flight.sorties)
    if settings.refine:
        stages.say("moving the stops in three dimensions")
        keep = BandStops(
            area.terrain,
            area.camera,
            band,
            site.targets_xy,
            area.ground_m,
            tour.sees,
            headings,
            tol,
        )
        moved = refine_band_stops(keep, stops, home_xyz, model)
        if not np.array_equal(moved, stops):
            try:
                other = _fly(
                    site, area, band, model, settings, moved, home_xyz, takeoff_m, tour, headings
                )
            except PlanError:
                other = None  # (a moved stop the written mission no longer holds: keep them)
            if other is not None and sum(x.flight_time_s for x in other.sorties) < unrefined_s:
                flight, stops = other, moved
        stages.lap("refine")
    certificate = None
    time_bound = horizontal_bound = 0.0
    if settings.certify:
        budget = settings.bound_time_s or bound_time_s(settings.solve.time_limit_s)
        stages.say("preparing the bound's search (compiled on first use)")
        prepare_bound()
        stages.lap("bound compile")
        stages.say(f"bounding the shortest possible flight in the band (up to {budget:.1f} s)")
        horizontal_m = math.fsum(s.length_m for s in flight.sorties)
        started = time.perf_counter()
        outer = _outer(site, area, band, tol)
        certificate = _certify(outer, horizontal_m, budget)
        # What is left of the stage, and at least its share, for the K-tree of sorties.
        left_s = max(budget - (time.perf_counter() - started), SORTIES_SHARE * budget)
        certificate, time_bound = _with_sorties(
            site, area, band, model, outer, certificate, horizontal_m, settings, left_s
        )
        horizontal_bound = certificate.lower_bound_m
        stages.lap("bound")
    band_flight = BandFlight(
        band=band,
        stops_xyz=stops,
        paths_xyz=flight.paths,
        path_stop=flight.path_stop,
        lowest_m=flight.lowest_m,
        highest_m=flight.highest_m,
        time_bound_s=time_bound,
        horizontal_bound_m=horizontal_bound,
        estimate_s=float(tour.length),
        unrefined_s=unrefined_s,
    )
    return Plan(
        settings=settings,
        **site_fields(site, area),
        regions=(),
        instance=instance,
        tour=tour,
        legs=flight.legs,
        sorties=flight.sorties,
        missions=flight.missions,
        geofence_latlon=flight.geofence_latlon,
        flight_time_s=sum(s.flight_time_s for s in flight.sorties),
        timings_s=stages.timings_s,
        warnings=tuple(flight.warnings),
        certificate=certificate,
        optimal_over_candidates=tour.proven_optimal,
        band_flight=band_flight,
    )


def _time_instance(
    terrain: Terrain,
    band: FlightBand,
    views: BandViewpoints,
    home_xyz: FloatArray,
    model: FlightModel,
    takeoff_m: float,
    m: int,
    workers: int | None,
) -> Instance:
    """The GTSP over the band's candidates, costed in seconds of flight, each arrival paying
    its stop; from home the take-off and to home the landing.

    A leg's time is the flight model's for its horizontal length and the least climbing and
    descending that following the terrain inside the band needs there
    (``FlightModel.least_vertical_s``): never more than the path flown will take, and exact
    for a straight leg that stays in the band."""
    n = len(views.xyz)
    require_memory(
        6.0 * 8.0 * n * n,
        f"the flight-time table of {n} candidates in the band",
        "plan fewer targets at a time in the band",
    )
    xyz = np.vstack([views.xyz, home_xyz[None, :]])
    i, j = np.triu_indices(n + 1, k=1)
    d = np.hypot(xyz[j, 0] - xyz[i, 0], xyz[j, 1] - xyz[i, 1])
    # The ground under a leg only matters where the solver may fly it: between candidates
    # near each other, and from and to home. Elsewhere the ends' heights alone (still never
    # more than the path flown) keep the table cheap.
    near = (d <= _near_m(xyz[:n, :2])) | (j == n)
    peak = np.full(len(i), -np.inf)
    trough = np.full(len(i), np.inf)
    k = np.flatnonzero(near)
    a = np.column_stack([xyz[i[k], :2], np.zeros(k.size)])
    b = np.column_stack([xyz[j[k], :2], np.zeros(k.size)])
    # Lines at height 0: their lowest height above the surface is minus its highest point.
    profile = band_profile(terrain, a, b, workers)
    peak[k] = np.where(np.isfinite(profile.lowest_m), -profile.lowest_m, -np.inf)
    trough[k] = np.where(np.isfinite(profile.highest_m), -profile.highest_m, np.inf)
    peak += band.floor_m
    trough += band.ceiling_m
    forth = model.leg3_s(d, 0.0, model.least_vertical_s(d, xyz[i, 2], xyz[j, 2], peak, trough))
    back = model.leg3_s(d, 0.0, model.least_vertical_s(d, xyz[j, 2], xyz[i, 2], peak, trough))
    full = np.zeros((n + 1, n + 1))
    full[i, j] = forth
    full[j, i] = back
    table = np.ascontiguousarray(full[:n, :n] + model.stop_s)
    np.fill_diagonal(table, 0.0)
    out = model.takeoff_s(takeoff_m) + full[n, :n] + model.stop_s
    home = full[:n, n] + model.landing_s(takeoff_m)
    vp, tg = views.pairs
    return Instance(
        covers=Covers.from_pairs(vp, tg, n, m),
        distance=table,
        depot_distance=np.vstack([out, home]),
        points_xy=np.ascontiguousarray(views.xyz[:, :2]),
        owner=views.owner,
        heading_deg=views.heading_deg,
        name="band",
    )


def _near_m(points_xy: FloatArray) -> float:
    """How far apart two candidates may be for the ground under the leg between them to be
    costed: the distance within which each has its :data:`_NEAR_COUNT` nearest."""
    if len(points_xy) <= _NEAR_COUNT:
        return math.inf
    tree = cKDTree(points_xy)
    dist, _ = tree.query(points_xy, k=_NEAR_COUNT + 1)
    return float(np.max(dist[:, -1]))


class _Flight:
    """The band's flight as written: sorties, missions, paths and their checks."""

    def __init__(
        self,
        sorties: tuple[Sortie, ...],
        missions: tuple[Mission, ...],
        paths: tuple[FloatArray, ...],
        path_stop: tuple[IntArray, ...],
        legs: tuple[Leg, ...],
        lowest_m: float,
        highest_m: float,
        geofence_latlon: tuple[tuple[float, float], ...],
        warnings: list[str],
    ) -> None:
        self.sorties = sorties
        self.missions = missions
        self.paths = paths
        self.path_stop = path_stop
        self.legs = legs
        self.lowest_m = lowest_m
        self.highest_m = highest_m
        self.geofence_latlon = geofence_latlon
        self.warnings = warnings


def _fly(
    site: SiteInputs,
    area: PlanArea,
    band: FlightBand,
    model: FlightModel,
    settings: PlanSettings,
    stops: FloatArray,
    home_xyz: FloatArray,
    takeoff_m: float,
    tour: Tour,
    headings: FloatArray | None,
) -> _Flight:
    """Follow the terrain between the stops, cut the sorties, write and check the missions."""
    k = len(stops)
    terrain = area.terrain
    names = [f"stop {i + 1}" for i in range(k)]
    # Every leg the sorties might fly: home to each stop, each stop to the next, each back.
    outs = [_follow(site, terrain, home_xyz, stops[i], band) for i in range(k)]
    hops = [_follow(site, terrain, stops[i], stops[i + 1], band) for i in range(k - 1)]
    backs = [_follow(site, terrain, stops[i], home_xyz, band) for i in range(k)]
    legs = SortieLegs(
        out_m=np.array([_horizontal(p) for p in outs]),
        hop_m=np.array([_horizontal(p) for p in hops]),
        back_m=np.array([_horizontal(p) for p in backs]),
        out_s=np.array([_path_s(model, p) for p in outs]),
        hop_s=np.array([_path_s(model, p) + model.stop_s for p in hops]),
        back_s=np.array([_path_s(model, p) for p in backs]),
        ends_s=model.takeoff_s(takeoff_m) + model.stop_s + model.landing_s(takeoff_m),
    )
    endurance = None if settings.endurance_min is None else settings.endurance_min * 60.0
    sorties = cut_sorties(legs, endurance, names)
    home = GeoPoint(*site.home_lat_lon, math.floor(area.home_ground_m * _CM) / _CM)
    true_headings = _true_headings(site, stops, headings)
    missions, paths, path_stop = [], [], []
    for s in sorties:
        pieces = [outs[s.first]] + [hops[i] for i in range(s.first, s.stop - 1)]
        pieces.append(backs[s.stop - 1])
        path = np.vstack([pieces[0]] + [p[1:] for p in pieces[1:]])
        stop_of = np.full(len(path), -1, dtype=np.int64)
        at = 0
        for i, piece in zip(range(s.first, s.stop), pieces, strict=False):
            at += len(piece) - 1
            stop_of[at] = i
        stop_of[0] = stop_of[-1] = -2
        inner = path[1:]  # the take-off climbs to path[0]; the last point is over home
        latlon = xy_to_latlon(site.crs, inner[:, :2])
        heights = [math.floor((z - home.amsl_m) * _CM + 0.5) / _CM for z in inner[:, 2]]
        missions.append(
            build_mission(
                home,
                latlon,
                takeoff_m,
                settings.mission,
                None if true_headings is None else true_headings[s.first : s.stop].tolist(),
                heights,
                [bool(v >= 0) for v in stop_of[1:]],
            )
        )
        paths.append(path)
        path_stop.append(stop_of)
    written, checked_legs, lowest, highest = _check_written(
        site, area, band, tuple(missions), tuple(path_stop), tour.sees, settings, headings
    )
    warnings = []
    if len(sorties) > 1:
        warnings.append(
            f"the tour needs {len(sorties)} sorties to fit --endurance "
            f"{settings.endurance_min:g} min; each returns home"
        )
    fence_xy = geofence_polygon(
        np.vstack([[site.home_xy], *(p[:, :2] for p in written), site.targets_xy]),
        settings.geofence_margin_m,
    )
    return _Flight(
        sorties,
        tuple(missions),
        tuple(written),
        tuple(path_stop),
        checked_legs,
        lowest,
        highest,
        tuple(xy_to_latlon(site.crs, fence_xy)),
        warnings,
    )


def _follow(
    site: SiteInputs, terrain: Terrain, a: FloatArray, b: FloatArray, band: FlightBand
) -> FloatArray:
    """The path from ``a`` to ``b`` inside the band, both ends included."""
    if np.allclose(a, b):
        return np.vstack([a, b])
    fill_along(site.dem, terrain, a[None, :2], b[None, :2])
    path, _ = path_in_band(terrain, np.vstack([a, b]), band)
    return path


class _HomeSorties:
    """The sorties searched over the legs as the band flies them."""

    def __init__(
        self,
        site: SiteInputs,
        area: PlanArea,
        band: FlightBand,
        model: FlightModel,
        home_xyz: FloatArray,
        takeoff_m: float,
    ) -> None:
        self.site, self.area, self.band, self.model = site, area, band, model
        self.home_xyz, self.takeoff_m = home_xyz, takeoff_m

    def search(self, stops: FloatArray, settings: PlanSettings) -> IntArray:
        """The stops' flying order: the sorties found, one after another (the cut of
        :func:`_fly` then finds them, or a quicker cut of that order); the order as given
        without an endurance or when the search finds nothing quicker."""
        k = len(stops)
        ident = np.arange(k)
        if settings.endurance_min is None or k < 2:
            return ident
        endurance = settings.endurance_min * 60.0
        times = self._leg_times(stops)
        model = self.model
        given = cut_sorties(
            SortieLegs(
                out_m=np.zeros(k),
                hop_m=np.zeros(k - 1),
                back_m=np.zeros(k),
                out_s=times[k, :k],
                hop_s=times[ident[:-1], ident[1:]] + model.stop_s,
                back_s=times[:k, k],
                ends_s=model.takeoff_s(self.takeoff_m)
                + model.stop_s
                + model.landing_s(self.takeoff_m),
            ),
            endurance,
            [""] * k,
        )
        if len(given) == 1:
            return ident
        routes, _ = search_routes(
            stops[:, :2],
            self.site.home_xy,
            self.takeoff_m,
            model,
            endurance,
            [ident[s.first : s.stop] for s in given],
            SEARCH_SHARE * settings.solve.time_limit_s,
            settings.solve.seed,
            leg_times=times,
        )
        return np.concatenate(routes)

    def _leg_times(self, stops: FloatArray) -> FloatArray:
        """(k + 1, k + 1) seconds of every leg the search may fly, as :func:`_fly` flies
        it (row and column ``k`` home); inf for the pairs not followed."""
        k = len(stops)
        pts = np.vstack([stops, self.home_xyz])
        if k <= _ALL_PAIRS_MAX:
            pairs = {(i, j) for i in range(k + 1) for j in range(k + 1) if i != j}
        else:
            _, idx = cKDTree(stops[:, :2]).query(stops[:, :2], k=min(NEIGHBOURS + 1, k))
            pairs = {(i, int(j)) for i, row in enumerate(np.asarray(idx)) for j in row if j != i}
            pairs |= {(j, i) for i, j in pairs}
            pairs |= {(i, i + 1) for i in range(k - 1)} | {(i + 1, i) for i in range(k - 1)}
            pairs |= {(k, i) for i in range(k)} | {(i, k) for i in range(k)}
        times = np.full((k + 1, k + 1), np.inf)
        for i, j in pairs:
            path = _follow(self.site, self.area.terrain, pts[i], pts[j], self.band)
            times[i, j] = _path_s(self.model, path)
        return times


def _horizontal(path: FloatArray) -> float:
    return float(np.hypot(*np.diff(path[:, :2], axis=0).T).sum())


def _path_s(model: FlightModel, path: FloatArray) -> float:
    """A path's time from rest to rest; its inner waypoints are flown through."""
    d = np.hypot(*np.diff(path[:, :2], axis=0).T)
    rise = np.diff(path[:, 2])
    return float(model.leg3_s(d.sum(), 0.0, model.vertical_excess_s(d, rise)))


def _true_headings(
    site: SiteInputs, stops: FloatArray, headings: FloatArray | None
) -> FloatArray | None:
    """Each stop's heading as the mission gives it (true north), for a frame camera."""
    if headings is None:
        return None
    true: FloatArray = true_bearing_deg(site.crs, stops[:, :2], headings % 180.0)
    return np.round(true, 2) % 360.0


def _check_written(
    site: SiteInputs,
    area: PlanArea,
    band: FlightBand,
    missions: tuple[Mission, ...],
    path_stop: tuple[IntArray, ...],
    sees: BoolArray,
    settings: PlanSettings,
    headings: FloatArray | None,
) -> tuple[list[FloatArray], tuple[Leg, ...], float, float]:
    """Check the missions as the vehicle stores them (positions on the 1e-7 degree grid,
    heights in whole centimetres above the home written): every stop sees what the plan says
    it sees, and every leg lies inside the band everywhere."""
    written: list[FloatArray] = []
    legs: list[Leg] = []
    lowest, highest = math.inf, -math.inf
    for mission, stop_of in zip(missions, path_stop, strict=True):
        home = mission.home
        wps = [
            (item.params[4], item.params[5], item.params[6])
            for item in mission.items
            if item.command == 16  # MAV_CMD_NAV_WAYPOINT
        ]
        home_xy = latlon_to_xy(site.crs, [(home.lat_deg, home.lon_deg)])[0]
        xy = latlon_to_xy(site.crs, [(lat, lon) for lat, lon, _ in wps])
        z = np.array([home.amsl_m + h for _, _, h in wps])
        path = np.vstack(
            [[*home_xy, home.amsl_m + mission.altitude_rel_m], np.column_stack([xy, z])]
        )
        written.append(path)
        profile = band_profile(area.terrain, path[:-1], path[1:])
        low = float(profile.lowest_m.min())
        high = float(profile.highest_m.max())
        lowest, highest = min(lowest, low), max(highest, high)
        bad = np.flatnonzero(
            (profile.lowest_m < band.floor_m - 1e-6)
            | (profile.highest_m > band.ceiling_m + 1e-6)
            | (profile.unknown_fraction > 0.0)
        )
        if bad.size:
            i = int(bad[0])
            raise PlanError(
                f"leg {i + 1} of a sortie leaves the band {band.describe()} as written "
                f"({profile.lowest_m[i]:.1f} to {profile.highest_m[i]:.1f} m above the "
                "surface): widen --agl or report this"
            )
        names = ["home" if s == -2 else ("waypoint" if s < 0 else f"stop {s + 1}") for s in stop_of]
        lengths = np.hypot(*np.diff(path[:, :2], axis=0).T)
        legs.extend(
            Leg(names[i], names[i + 1], float(lengths[i]), float(profile.lowest_m[i]), 0.0)
            for i in range(len(path) - 1)
        )
        mask = stop_of >= 0
        stop_ids = stop_of[mask]
        eyes = path[mask]
        t_idx = [np.flatnonzero(sees[s]) for s in stop_ids]
        v = np.concatenate([np.full(len(t), k) for k, t in enumerate(t_idx)]).astype(np.int64)
        t = np.concatenate(t_idx).astype(np.int64)
        seen = sees_from(
            area.terrain,
            area.camera,
            eyes[v],
            site.targets_xy[t],
            area.ground_m[t],
            None if headings is None else headings[stop_ids][v],
            0.0,
            settings.workers,
        )
        if not seen.all():
            k = int(np.flatnonzero(~seen)[0])
            raise PlanError(
                f"stop {int(stop_ids[v[k]]) + 1} no longer sees target '{site.names[t[k]]}' as "
                "written to the mission: raise --position-tolerance or report this"
            )
    return written, tuple(legs), lowest, highest


def _outer(site: SiteInputs, area: PlanArea, band: FlightBand, hold_m: float) -> BandOuter:
    """Every target's outer star in the band (:mod:`urpt_gcs.visibility.band_outer`)."""
    return band_outer(
        area.terrain,
        site.targets_xy,
        area.ground_m,
        area.camera,
        band.ceiling_m,
        area.terrain_max_m,
        site.home_xy,
        hold_m,
    )


def _certify(outer: BandOuter, horizontal_m: float, budget_s: float) -> Certificate:
    """A lower bound of the horizontal length of any flight from home inside the band whose
    stops see every target from anywhere within the position tolerance: the shortest closed
    path from home through every target's outer star, bounded by the same search as the
    plane's."""
    bound = lower_bound(outer.regions, horizontal_m, budget_s)
    return Certificate(
        min(bound.value, horizontal_m),
        f"{bound.method} over outer stars in the band",
        bound.seconds,
        int(outer.regions.outer[0].reach_m.size),
        math.nan,
        bound.relaxed_tour_xy,
    )


def _with_sorties(
    site: SiteInputs,
    area: PlanArea,
    band: FlightBand,
    model: FlightModel,
    outer: BandOuter,
    certificate: Certificate,
    horizontal_m: float,
    settings: PlanSettings,
    time_limit_s: float,
) -> tuple[Certificate, float]:
    """The certificate raised by what the endurance forces on sorties from home
    (:func:`urpt_gcs.bound.sorties.sortie_bound`: their count and their horizontal length,
    returns home included), and the band's bound of the flight time (:func:`_time_bound`).

    A sortie in the band takes at least its take-off to the floor over home and its landing,
    its stops, and its horizontal length at the cruise speed: every leg is flown in AUTO at
    that speed, the way home too through waypoints that follow the terrain (RTL would fly
    straight), and climbing only adds to a leg. That is the sortie bound's budget.
    """
    if settings.endurance_min is None:
        return certificate, _time_bound(site, area, band, model, outer, certificate, 1)
    speed = model.cruise_m_s
    budget = SortieBudget(
        endurance_s=settings.endurance_min * 60.0,
        ends_s=model.takeoff_s(band.floor_m) + model.landing_s(band.floor_m),
        stop_s=model.stop_s,
        per_metre_s=1.0 / speed,
    )
    away = np.hypot(*(site.targets_xy - np.asarray(site.home_xy)).T) - outer.radius_m
    found = sortie_bound(
        site.targets_xy,
        outer.radius_m,
        np.maximum(away, 0.0),
        certificate.lower_bound_m,
        budget,
        horizontal_m,
        time_limit_s,
        sorties_through(outer.regions, horizontal_m),
    )
    value = max(certificate.lower_bound_m, min(found.length_m, horizontal_m))
    method = certificate.method
    if value > certificate.lower_bound_m:
        method = f"{method} + sorties"
    raised = dataclasses.replace(certificate, lower_bound_m=value, method=method)
    time_bound = max(
        _time_bound(site, area, band, model, outer, raised, max(found.sorties, 1)),
        found.flight_time_s,
    )
    # One time bound, the larger: the summary's sortie line and the band's line agree.
    found = dataclasses.replace(found, flight_time_s=time_bound)
    return dataclasses.replace(raised, sorties=found), time_bound


def _time_bound(
    site: SiteInputs,
    area: PlanArea,
    band: FlightBand,
    model: FlightModel,
    outer: BandOuter,
    certificate: Certificate,
    sorties: int,
) -> float:
    """A lower bound of the flight time of any flight in the band that photographs every
    target, as the flight model counts it, given at least ``sorties`` sorties.

    The take-off to the band's floor over home and the landing from it, once for each
    sortie; a stop for each of a set of targets no single photo can hold two of (their outer
    discs apart); and the legs, each of which takes at least its horizontal time and at least
    its vertical time. Their horizontal lengths add up to at least the certificate's bound;
    their climbs to at least the range of heights every such flight spans, less the
    take-off: it must rise to see the target whose outer disc sits highest (above its
    ground, and the floor over the disc's lowest corner) and sink to see the one whose disc
    sits lowest (the ceiling over its highest corner), and it starts and ends at home; its
    descents likewise. Sorties from home and back only climb and sink more than one flight
    through the same heights.
    """
    photos = len(greedy_disjoint(site.targets_xy, float(outer.radius_m.max())))
    speed = model.cruise_m_s
    home = area.home_ground_m
    rise_to = max(float(np.max(np.maximum(area.ground_m, outer.lowest_m + band.floor_m))), home)
    sink_to = min(float(np.min(outer.highest_m + band.ceiling_m)), home)
    vertical = max(rise_to - sink_to - band.floor_m, 0.0)
    legs = max(
        certificate.lower_bound_m / speed,
        vertical / model.climb_m_s + vertical / model.descent_m_s,
    )
    ends = model.takeoff_s(band.floor_m) + model.landing_s(band.floor_m)
    return sorties * ends + legs + max(photos, 1) * model.stop_s
