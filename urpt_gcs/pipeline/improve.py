"""Stops moved within what they see, and the certified lower bound of the flight.

Both work on the terrain read so far (filled along new legs) and check every stop as the
mission will be written: the position margin, the written grid and the legs' clearance.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from urpt_gcs.bound.certificate import Certificate, certify
from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.bound.lower_bound import sorties_through
from urpt_gcs.bound.lower_bound import warm_up as warm_bound
from urpt_gcs.bound.sorties import SORTIES_SHARE, SortieBudget, sortie_bound, star_distances
from urpt_gcs.errors import PlanError
from urpt_gcs.flight.refinement import Refinement, refine_along, refine_tour
from urpt_gcs.flight.sorties import SortieOrder
from urpt_gcs.pipeline.area import PlanArea, SiteInputs, altitude_rel
from urpt_gcs.pipeline.missions import (
    CheckedFlight,
    check_site,
    flight_model,
    sorties_and_missions,
)
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.pipeline.stages import Stages
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.outer import finer_stars, outer_regions
from urpt_gcs.visibility.outer import warm_up as warm_walks

# Share of the bound's time the outer stars past the first ones (those far apart, walked
# whatever the clock) may take to walk; the bound itself has the rest, and never less than
# this share, so the stage keeps to its time unless the first stars alone overrun it.
_WALK_SHARE = 0.5

# How much shorter a tour read off the bound must be to replace the refined one.
_BETTER = 1e-6

# Seconds refinement may take at most: it ends when its steps are down to a few centimetres (so
# that a plan does not depend on the machine's load), this only guards against a runaway.
_REFINE_MAX_S = 60.0


def refine_stops(
    site: SiteInputs, area: PlanArea, tour: Tour, settings: PlanSettings
) -> tuple[Tour, Refinement]:
    """Move the stops within what they see, checked as the mission will be (the position
    margin, the written grid and the legs' clearance).

    Parameters
    ----------
    site, area
        The site and the area planned on.
    tour
        The tour with its stops given their position margin.
    settings
        The plan's settings (position tolerance, least clearance, workers).

    Returns
    -------
    tuple of (Tour, Refinement)
        The refined tour, and its length before and after.
    """
    return refine_tour(check_site(site, area, settings), tour, site.home_xy, _REFINE_MAX_S)


def bounds_tour(
    site: SiteInputs,
    area: PlanArea,
    tour: Tour,
    certificate: Certificate,
    settings: PlanSettings,
    flown_m: float,
    flown_s: float,
) -> tuple[tuple[Tour, SortieOrder | None, CheckedFlight], float, float] | None:
    """The tour read off the certified bound's relaxed tour and refined, checked as the
    mission will be, cut into sorties and checked, with its flown and refined lengths: when
    it is shorter than ``tour`` (the refined tour) and than ``flown_m`` as flown, and its
    flight no longer than ``flown_s`` (read off a relaxed tour, it may stop more often);
    else None, and None when a check as written refuses it.

    Parameters
    ----------
    site, area
        The site and the area planned on.
    tour
        The refined tour.
    certificate
        The certified bound, whose relaxed tour (if any) is read.
    settings
        The plan's settings.
    flown_m
        The refined tour's length as flown, every sortie from home and back.
    flown_s
        The refined tour's flight time as flown, every sortie's.

    Returns
    -------
    tuple or None
        ``((tour, sortie_order, flight), flown_m, refined_m)`` as
        :func:`~urpt_gcs.pipeline.missions.sorties_and_missions` gives them, with the new
        tour's length as flown and as refined; None when it is not shorter.
    """
    if certificate.relaxed_tour_xy is None:
        return None
    check = check_site(site, area, settings)
    read = refine_along(check, certificate.relaxed_tour_xy, site.home_xy, tour, _REFINE_MAX_S)
    if read is None:
        return None
    found = read[0]
    if found.length >= tour.length * (1.0 - _BETTER):
        return None
    try:
        flown = sorties_and_missions(site, area, found, settings, Stages(None))
    except PlanError:
        # A stop read off the relaxed tour that fails a check as written (on the edge of
        # what it sees, once rounded to the mission's grid): the refined tour stays.
        return None
    other_m = math.fsum(s.length_m for s in flown[2].sorties)
    other_s = math.fsum(s.flight_time_s for s in flown[2].sorties)
    if other_m >= flown_m or other_s > flown_s:
        return None
    return flown, other_m, found.length


def prepare_bound(site: SiteInputs, area: PlanArea) -> None:
    """Compile the bound's kernels and its star walks' (or load them from numba's cache)
    before the bound's clock starts: compiled within it, a cold cache would leave a bound
    much further from the flight than the same plan certifies once compiled."""
    warm_walks(area.terrain, site.targets_xy[0], float(area.ground_m[0]), area.camera)
    warm_bound()


def certify_flight(
    site: SiteInputs,
    area: PlanArea,
    instance: Instance,
    flown_m: float,
    tour_m: float,
    time_limit_s: float,
    settings: PlanSettings,
    budget: SortieBudget | None = None,
) -> Certificate:
    """The certified lower bound of every flight from home whose stops see every target from
    anywhere within the position tolerance of them, flown in sorties that each fit the
    endurance (:mod:`urpt_gcs.bound.sorties`).

    Parameters
    ----------
    site, area
        The site and the area planned on.
    instance
        The viewpoints' instance, whose geometric bound the certificate may also use.
    flown_m
        The flight's length as flown.
    tour_m
        A closed flight from home that photographs every target, in one piece: the bound of
        one flight searches below it (sorties, flown longer, would let it search wider).
    time_limit_s
        Seconds the stage may take, the outer stars' walk included (more only when the
        stars walked whatever the clock take over half of it).
    settings
        The plan's settings: workers, the position tolerance (how far from its waypoint a
        stop still photographs), the endurance and the flight model's speeds.
    budget
        What one sortie may spend (None: the settings' vehicle's).

    Returns
    -------
    Certificate
        The lower bound and how it was proved.
    """
    workers, hold_m = settings.workers, settings.position_tolerance_m
    started = time.perf_counter()
    regions, ratio = outer_regions(
        area.terrain,
        site.targets_xy,
        area.ground_m,
        area.camera,
        site.home_xy,
        workers=workers,
        hold_m=hold_m,
        time_limit_s=_WALK_SHARE * time_limit_s,
    )
    also = geometric_lower_bound(instance)
    tighten = finer_stars(area.terrain, area.camera, workers, hold_m)
    left_s = max(time_limit_s - (time.perf_counter() - started), _WALK_SHARE * time_limit_s)
    single = certify(regions, min(flown_m, tour_m), left_s, also, ratio, tighten)
    # What is left of the stage's time, and at least its share, for the K-tree of sorties
    # (which takes it only where two sorties or more are proven).
    sorties_s = max(time_limit_s - (time.perf_counter() - started), SORTIES_SHARE * time_limit_s)
    if budget is None:
        endurance = math.inf if settings.endurance_min is None else settings.endurance_min * 60.0
        budget = SortieBudget.of(flight_model(settings), altitude_rel(area), endurance)
    stars = regions.outer
    sorties = sortie_bound(
        np.asarray([s.center_xy for s in stars], dtype=np.float64).reshape(-1, 2),
        np.asarray([float(s.reach_m.max()) for s in stars]),
        star_distances(stars, site.home_xy),
        single.lower_bound_m,
        budget,
        flown_m,
        sorties_s,
        sorties_through(regions, flown_m),
    )
    value = float(max(single.lower_bound_m, min(sorties.length_m, flown_m)))
    method = single.method if value <= single.lower_bound_m else f"{single.method} + sorties"
    return dataclasses.replace(single, lower_bound_m=value, method=method, sorties=sorties)


__all__ = ["bounds_tour", "certify_flight", "prepare_bound", "refine_stops"]
