"""plan(): from a DEM and a target file to a checked tour and its mission.

The stage chain, each stage a function of the values before it:

1. :func:`~urpt_gcs.pipeline.area.read_site` -- the targets and home in the planning CRS;
2. :func:`~urpt_gcs.pipeline.area.read_area` -- the DEM window and the flight plane;
3. visibility regions and viewpoints (:mod:`urpt_gcs.visibility`);
4. the tour over the viewpoints (:mod:`urpt_gcs.solvers`);
5. :func:`finish_plan` -- stops given their position margin, refined
   (:mod:`~urpt_gcs.pipeline.improve`), cut into sorties and written as missions checked
   against the terrain (:mod:`~urpt_gcs.pipeline.missions`), the flight certified, all in a
   :class:`~urpt_gcs.pipeline.result.Plan`.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from urpt_gcs.bound.certificate import bound_time_s
from urpt_gcs.flight.margin import robust_tour
from urpt_gcs.pipeline.area import (
    PlanArea,
    SiteInputs,
    read_area,
    read_band_area,
    read_site,
    site_fields,
)
from urpt_gcs.pipeline.band import plan_in_band
from urpt_gcs.pipeline.improve import bounds_tour, certify_flight, prepare_bound, refine_stops
from urpt_gcs.pipeline.missions import check_site, flight_model, sorties_and_missions
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.pipeline.stages import Stages, solve_stage
from urpt_gcs.problem.instance import Instance
from urpt_gcs.progress import Progress
from urpt_gcs.site.targets import TargetSet
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.cover import build_instance
from urpt_gcs.visibility.regions import Region, visibility_regions


def plan(
    dem_path: Path,
    targets_path: Path | TargetSet,
    settings: PlanSettings | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Plan a mission that photographs every target from the flight plane.

    Parameters
    ----------
    dem_path
        GeoTIFF DSM/DEM of the site.
    targets_path
        KML/KMZ, GeoJSON or CSV of the targets (a point named Home or Launch is the take-off),
        or the targets already read.
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
    stages = Stages(progress)
    stages.say("reading targets")
    site = read_site(dem_path, targets_path, settings)
    stages.lap("targets")
    stages.say("reading terrain")
    if settings.agl_band_m is not None:
        area = read_band_area(site, settings)
        stages.lap("terrain")
        return plan_in_band(site, area, settings, stages)
    area = read_area(site, settings)
    stages.lap("terrain")
    regions, instance = _viewpoints(site, area, settings, stages)
    tour = solve_stage(instance, settings, stages, flight_model(settings).stop_cost_m)
    return finish_plan(site, area, regions, instance, tour, settings, stages)


def finish_plan(
    site: SiteInputs,
    area: PlanArea,
    regions: tuple[Region, ...],
    instance: Instance,
    tour: Tour,
    settings: PlanSettings,
    stages: Stages,
) -> Plan:
    """From the solver's tour to the checked plan: stops given their margin, ordered and cut
    into sorties, written as missions and checked as written; with ``settings.certify``, the
    flight's certified lower bound.

    The fleet planner finishes each vehicle's share of the targets here too.

    Parameters
    ----------
    site, area
        The site and the area planned on (:func:`~urpt_gcs.pipeline.area.read_site`,
        :func:`~urpt_gcs.pipeline.area.read_area`).
    regions
        Each target's visibility region on the flight plane.
    instance
        The viewpoints the tour was solved over.
    tour
        The solver's tour.
    settings
        The plan's settings.
    stages
        Announces each stage and keeps its time; its timings go into the plan.

    Returns
    -------
    Plan
        The checked tour, its missions and everything computed on the way.
    """
    over_candidates = tour.proven_optimal
    stages.say(
        f"stops keeping their targets in the picture within {settings.position_tolerance_m:g} m"
    )
    tour, margin_warnings = robust_tour(
        check_site(site, area, settings), tour, site.home_xy, site.names
    )
    stages.lap("margin")
    refinement = None
    if settings.refine:
        stages.say("moving the stops within what they see")
        tour, refinement = refine_stops(site, area, tour, settings)
        stages.lap("refine")
    planned = tour
    tour, sortie_order, flight = sorties_and_missions(
        site, area, planned, settings, stages, instance
    )
    certificate = None
    if settings.certify:
        stages.say("preparing the bound (compiled on first use)")
        prepare_bound(site, area)
        stages.lap("compile")
        bound_s = settings.bound_time_s or bound_time_s(settings.solve.time_limit_s)
        stages.say(f"bounding the shortest possible flight (up to {bound_s:.1f} s)")
        flown_m = math.fsum(s.length_m for s in flight.sorties)
        certificate = certify_flight(
            site, area, instance, flown_m, planned.length, bound_s, settings
        )
        stages.lap("bound")
        if refinement is not None:
            stages.say("reading a tour off the bound")
            flown_s = math.fsum(s.flight_time_s for s in flight.sorties)
            better = bounds_tour(site, area, planned, certificate, settings, flown_m, flown_s)
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
        **site_fields(site, area),
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


def _viewpoints(
    site: SiteInputs, area: PlanArea, settings: PlanSettings, stages: Stages
) -> tuple[tuple[Region, ...], Instance]:
    """Each target's visibility region on the flight plane, and the viewpoints sampled from
    them with what each sees."""
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
    return regions, instance


__all__ = ["finish_plan", "plan"]
