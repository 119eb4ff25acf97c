"""What a plan inside a height band (``--agl FLOOR:CEILING``) adds to its report.

A band plan flies no plane: each stop has its own height, and between the stops waypoints
without a photo keep the vehicle inside the band as the terrain rises and falls. Its report
gives the band, each stop's height (above mean sea level in the DEM's datum, above home as
the mission writes it, and above the surface below it), how many waypoints only shape the
path, the lowest and highest height above the surface anywhere along the paths, and the
flight time against its certified lower bound. Everything here reads the missions as
written (:attr:`~urpt_gcs.pipeline.result.BandFlight.paths_xyz`), so it describes what is
flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.pipeline.result import BandFlight, Plan

__all__ = [
    "BandStop",
    "band_lines",
    "band_stop_lines",
    "band_stops",
    "band_summary",
    "eye_heights_m",
    "path_profile",
]

# Heights are written in whole centimetres.
_CM = 2


@dataclass(frozen=True, slots=True)
class BandStop:
    """A photo stop of a band plan as its mission flies it.

    Attributes
    ----------
    order
        Its number in flight order over every sortie, from 1.
    sortie
        Its sortie, from 1.
    x_m, y_m
        Where it is, in the planning CRS.
    amsl_m
        Its height in the DEM's vertical datum.
    above_home_m
        Its height above home, as the mission writes it.
    above_surface_m
        Its height above the surface right below it.
    from_previous_m
        The horizontal length of the path from the stop before it (or from home).
    eta_s
        When the vehicle gets there, from arming.
    """

    order: int
    sortie: int
    x_m: float
    y_m: float
    amsl_m: float
    above_home_m: float
    above_surface_m: float
    from_previous_m: float
    eta_s: float


def _flight(plan: Plan) -> BandFlight:
    flight = plan.band_flight
    if flight is None:
        raise ValueError("the plan flies a plane, not a band")
    return flight


def band_stops(plan: Plan) -> list[BandStop]:
    """Every photo stop of a band plan, in flight order, with its heights and its ETA.

    Parameters
    ----------
    plan
        A plan with ``band_flight``.

    Returns
    -------
    list of BandStop
        The stops of every sortie in turn; ``eta_s`` on the plan's flight model, each piece of
        path flown from rest to rest through its waypoints (as the plan costs it).
    """
    flight = _flight(plan)
    model = plan.flight_model
    out = []
    for number, (path, stop_of, mission) in enumerate(
        zip(flight.paths_xyz, flight.path_stop, plan.missions, strict=True), start=1
    ):
        home_amsl = mission.home.amsl_m
        eta = model.takeoff_s(mission.altitude_rel_m)
        previous = 0
        at = np.flatnonzero(stop_of >= 0)
        surface = plan.terrain.sample(path[at, 0], path[at, 1])
        for j, ground in zip(at.tolist(), surface.tolist(), strict=True):
            piece = path[previous : j + 1]
            d = np.hypot(*np.diff(piece[:, :2], axis=0).T)
            rise = np.diff(piece[:, 2])
            eta += float(model.leg3_s(d.sum(), 0.0, model.vertical_excess_s(d, rise)))
            z = float(path[j, 2])
            out.append(
                BandStop(
                    order=int(stop_of[j]) + 1,
                    sortie=number,
                    x_m=float(path[j, 0]),
                    y_m=float(path[j, 1]),
                    amsl_m=round(z, _CM),
                    above_home_m=round(z - home_amsl, _CM),
                    above_surface_m=round(z - ground, _CM) if math.isfinite(ground) else math.nan,
                    from_previous_m=round(float(d.sum()), 2),
                    eta_s=round(eta, 1),
                )
            )
            eta += model.stop_s
            previous = j
    return out


def eye_heights_m(plan: Plan) -> FloatArray:
    """The height (DEM datum) of each stop of the tour, in flight order: the plane's for a
    plane plan, each stop's own in a band."""
    if plan.band_flight is None:
        return np.full(len(plan.tour.order), plan.camera.altitude_m)
    heights: FloatArray = plan.band_flight.stops_xyz[:, 2].copy()
    return heights


def path_profile(plan: Plan, sortie: int, samples: int = 2000) -> dict[str, FloatArray]:
    """A sortie's path against the terrain below it, along its horizontal distance.

    Parameters
    ----------
    plan
        A plan with ``band_flight``.
    sortie
        The sortie, from 0.
    samples
        At most this many points along the path at which the surface is read (no closer
        than half a DEM cell).

    Returns
    -------
    dict
        ``distance_m`` and ``z_m``: the path's points (horizontal distance from the start,
        height in the DEM's datum), linear between them; ``stop``: each point's stop index
        (-1 a waypoint without a photo, -2 over home); ``at_m`` and ``surface_m``: the
        surface sampled densely along the path (NaN where the DEM has no value).
    """
    flight = _flight(plan)
    path = flight.paths_xyz[sortie]
    steps = np.hypot(*np.diff(path[:, :2], axis=0).T)
    distance = np.concatenate([[0.0], np.cumsum(steps)])
    total = float(distance[-1])
    count = int(min(samples, max(2.0 * total / max(plan.terrain.cell_m, 1e-9), 2.0))) + 1
    at = np.linspace(0.0, total, count)
    x = np.interp(at, distance, path[:, 0])
    y = np.interp(at, distance, path[:, 1])
    return {
        "distance_m": distance,
        "z_m": path[:, 2].copy(),
        "stop": flight.path_stop[sortie].copy(),
        "at_m": at,
        "surface_m": plan.terrain.sample(x, y),
    }


def band_summary(plan: Plan) -> dict[str, Any]:
    """The band plan's own figures for ``summary.json`` (the ``band`` key).

    Parameters
    ----------
    plan
        A plan with ``band_flight``.

    Returns
    -------
    dict
        ``floor_m``, ``ceiling_m``; ``takeoff_above_home_m``; ``inserted_waypoints``;
        ``lowest_above_surface_m`` and ``highest_above_surface_m`` along the paths;
        ``time_bound_s`` (a lower bound of the flight time of any flight in the band that
        photographs every target), ``time_gap_pct`` (the flight time over it, rounded up;
        None without a bound), ``horizontal_bound_m`` and ``estimate_s`` (the solver's
        table's time for its own tour), ``unrefined_flight_time_s`` (the flight with the solver's
        stops where it put them, before they moved in three dimensions).
    """
    flight = _flight(plan)
    bound = flight.time_bound_s
    gap = (plan.flight_time_s - bound) / bound * 100.0 if bound > 0.0 else math.nan
    return {
        "floor_m": flight.band.floor_m,
        "ceiling_m": flight.band.ceiling_m,
        "takeoff_above_home_m": round(plan.mission.altitude_rel_m, 2),
        "inserted_waypoints": flight.inserted,
        "lowest_above_surface_m": round(flight.lowest_m, 2),
        "highest_above_surface_m": round(flight.highest_m, 2),
        "time_bound_s": round(flight.time_bound_s, 1) if bound > 0.0 else None,
        "time_gap_pct": (
            math.ceil(max(gap, 0.0) * 100.0 - 1e-9) / 100.0 if math.isfinite(gap) else None
        ),
        "horizontal_bound_m": (
            math.floor(flight.horizontal_bound_m * 1000.0) / 1000.0 if bound > 0.0 else None
        ),
        "estimate_s": round(flight.estimate_s, 1),
        "unrefined_flight_time_s": round(flight.unrefined_s, 1),
    }


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s:02d} s"


def band_lines(data: dict[str, Any]) -> list[str]:
    """The summary's lines about the band, from :func:`band_summary`'s dictionary under
    ``band`` in the summary (in place of the plane's altitude and clearance)."""
    band = data["band"]
    lines = [
        f"band           {band['floor_m']:g} to {band['ceiling_m']:g} m above the surface; "
        f"take-off to {band['takeoff_above_home_m']:.1f} m above home",
        f"heights        {band['lowest_above_surface_m']:.1f} to "
        f"{band['highest_above_surface_m']:.1f} m above the surface along every path; "
        f"{band['inserted_waypoints']} waypoints without a photo follow the terrain",
    ]
    if band["time_bound_s"] is None:
        lines.append("time bound     none (not certified)")
    else:
        lines.append(
            f"time bound     {_minutes(band['time_bound_s'])} (no flight in the band that sees "
            f"every target is shorter); the flight time is {band['time_gap_pct']:.1f} % over "
            f"it; horizontal bound {band['horizontal_bound_m']:.1f} m"
        )
    lines.append(
        f"estimate       {_minutes(band['estimate_s'])} (the solver's table for its tour: "
        "the least climbing each leg needs)"
    )
    return lines


def band_stop_lines(stops: list[dict[str, Any]], shown: int) -> list[str]:
    """The stops table of a band plan: order, sortie, horizontal path from the previous
    stop, ETA, heights AMSL / above home / above the surface, and what each sees."""
    lines = ["stops          #  sortie  from prev   ETA        AMSL   >home  >surface  sees"]
    for stop in stops[:shown]:
        surface = stop["height_above_surface_m"]
        lines.append(
            f"               {stop['order']:<3d}{stop['sortie']:^7d}"
            f"{stop['from_previous_m']:8.1f} m  {_minutes(stop['eta_s']):>9s}"
            f"  {stop['height_amsl_m']:7.1f} {stop['height_above_home_m']:7.1f}"
            f" {'n/a' if surface is None else f'{surface:8.1f}'}  {', '.join(stop['sees'])}"
        )
    return lines
