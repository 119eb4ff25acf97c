"""A fleet plan's files: one ordinary plan folder per vehicle and the fleet's own summary.

``OUT/vehicle_k/`` holds exactly what ``plan --out`` writes for vehicle k alone (so
``upload`` and ``sitl replay --plan`` work on it unchanged); ``OUT/summary.json`` holds the
``fleet`` block (every vehicle's layer, home, speed, flight time, length, sorties, targets,
start delay and the SHA-256 of each of its mission files as written; the makespan, its lower
bound and gap; the separation and the planned closest approach), and ``OUT/map.png``,
``OUT/map.html``, ``OUT/plan.kml`` and ``OUT/plan.geojson`` show every vehicle in its own
colour. Everything is
committed as one set: all of it appears, or none. A vehicle left idle has ``"idle": true``,
why in ``"idle_reason"``, no targets, no sorties, and an empty folder (the products of an
earlier plan in it are removed with the rest of the earlier set).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from urpt_gcs.files.formats.geo import fleet_geojson, fleet_kml
from urpt_gcs.files.output import Destination, commit
from urpt_gcs.files.plan_check import mission_digests
from urpt_gcs.files.products import (
    MAP_FILE,
    MAP_PAGE_FILE,
    SUMMARY_FILE,
    check_out,
    render_products,
)
from urpt_gcs.pipeline.fleet import FleetPlan, IdleVehicle

__all__ = [
    "check_fleet_out",
    "fleet_map_title",
    "fleet_summary",
    "fleet_summary_text",
    "vehicle_dir",
    "write_fleet_products",
]


def vehicle_dir(number: int) -> str:
    return f"vehicle_{number}"


def check_fleet_out(out_dir: Path, vehicles: int) -> list[Destination]:
    """Refuse, before any planning, an ``--out`` the fleet's files cannot be committed to;
    the vehicles' folders first, then the top folder (the order they are committed in)."""
    top = check_out(out_dir)
    return [*(check_out(out_dir / vehicle_dir(k)) for k in range(1, vehicles + 1)), top]


def _round(x: float | None, digits: int = 2) -> float | None:
    return None if x is None or not math.isfinite(x) else round(x, digits)


def _delayed(fleet: FleetPlan, times_s: tuple[float, ...]) -> float:
    """The last landing of flights of these times started with the plan's delays."""
    delays = fleet.separation.start_delays_s
    return max(d + t for d, t in zip(delays, times_s, strict=True))


def fleet_summary(
    fleet: FleetPlan, files: list[str], missions: Sequence[Mapping[str, str | bytes]] = ()
) -> dict[str, Any]:
    """What the top-level ``summary.json`` holds; ``missions``, each vehicle's files as
    rendered (name -> content), give the digests ``upload --fleet`` checks them by."""
    sep = fleet.separation
    closest = sep.closest
    vehicles = []
    for number, (plan, delay, finish) in enumerate(
        zip(fleet.plans, sep.start_delays_s, fleet.finish_s, strict=True), start=1
    ):
        if isinstance(plan, IdleVehicle):
            vehicles.append(_idle_row(plan))
            continue
        vehicles.append(
            {
                "vehicle": number,
                "dir": vehicle_dir(number),
                "idle": False,
                "altitude_m": round(plan.camera.altitude_m, 2),
                "altitude_above_home_m": round(plan.altitude_rel_m, 2),
                "home_lat": plan.mission.home.lat_deg,
                "home_lon": plan.mission.home.lon_deg,
                "speed_m_s": plan.settings.mission.cruise_speed_m_s,
                "endurance_min": plan.settings.endurance_min,
                "flight_time_s": round(plan.flight_time_s, 1),
                "start_delay_s": delay,
                "finish_s": round(finish, 1),
                "length_m": round(plan.flown_length_m, 2),
                "sorties": len(plan.sorties),
                "stops": len(plan.tour.order),
                "targets": [t.name for t in plan.targets.targets],
            }
        )
        if missions:
            vehicles[-1]["mission_sha256"] = mission_digests(missions[number - 1])
    bound = fleet.bound
    return {
        "fleet": {
            "vehicles": vehicles,
            "makespan_s": round(fleet.makespan_s, 1),
            "makespan_bound_s": round(bound.bound_s, 1),
            "makespan_gap_pct": _round(100.0 * fleet.gap),
            "bound": {
                "reach_s": round(bound.reach_s, 1),
                "share_s": round(bound.share_s, 1),
                "pigeonhole_s": round(bound.pigeonhole_s, 1),
                "sorties_s": round(bound.sorties_s, 1),
            },
            # The naive split: the single-vehicle tour cut into K contiguous pieces, each
            # piece's tour solved again on its own vehicle's layer (the search's start); and
            # the pieces flown exactly as cut, on the single tour's layer; both started with
            # the plan's start delays.
            "naive_split_makespan_s": round(_delayed(fleet, fleet.tours.start_times_s), 1),
            "naive_cut_makespan_s": round(_delayed(fleet, fleet.tours.naive_times_s), 1),
            # The naive split finished as the plans are (margins, refinement, checks,
            # separation): the plan lands no later (null: it could not be flown).
            "naive_flown_makespan_s": _round(fleet.naive_flown_s, 1),
            "search": {
                "moves": fleet.tours.moves,
                "resolves": fleet.tours.resolves,
                "search_s": round(fleet.tours.search_s, 3),
            },
            "single_vehicle": {
                "length_m": round(fleet.single_length_m, 2),
                "flight_time_s": round(fleet.single_flight_time_s, 1),
            },
            "separation": {
                "mode": sep.mode,
                "layer_spacing_m": sep.layer_spacing_m,
                "min_m": sep.min_m,
                "closest_approach_m": None if closest is None else round(closest.distance_m, 2),
                "closest_horizontal_m": _round(sep.closest_horizontal_m),
                "closest_vehicles": None if closest is None else list(closest.vehicles),
                "closest_at_s": None if closest is None else round(closest.at_s, 1),
                "closest_lat": None if sep.closest_latlon is None else sep.closest_latlon[0],
                "closest_lon": None if sep.closest_latlon is None else sep.closest_latlon[1],
                "start_delays_s": list(sep.start_delays_s),
                "timing_slack_s": round(sep.timing_slack_s, 1),
            },
        },
        "targets": sum(len(p.targets.targets) for p in fleet.flying if p is not None),
        "timings_s": {k: round(v, 3) for k, v in fleet.timings_s.items()},
        "warnings": [
            f"vehicle {number}: {w}"
            for number, plan in enumerate(fleet.flying, start=1)
            if plan is not None
            for w in plan.warnings
        ],
        "files": files,
    }


def _idle_row(idle: IdleVehicle) -> dict[str, Any]:
    """A vehicle left idle as the summary lists it: its layer, home and speed, nothing to fly."""
    return {
        "vehicle": idle.number,
        "dir": vehicle_dir(idle.number),
        "idle": True,
        "idle_reason": idle.reason,
        "altitude_m": round(idle.altitude_m, 2),
        "altitude_above_home_m": round(idle.altitude_rel_m, 2),
        "home_lat": idle.home_lat_lon[0],
        "home_lon": idle.home_lat_lon[1],
        "speed_m_s": idle.settings.mission.cruise_speed_m_s,
        "endurance_min": idle.settings.endurance_min,
        "flight_time_s": 0.0,
        "start_delay_s": 0.0,
        "finish_s": 0.0,
        "length_m": 0.0,
        "sorties": 0,
        "stops": 0,
        "targets": [],
    }


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s:02d} s"


def _naive_line(f: dict[str, Any], count: int) -> str:
    """The naive split as flown where it could be finished, else as cut (an estimate)."""
    pieces = f"the single-vehicle tour cut into {count} piece{'s' if count != 1 else ''}"
    flown = f.get("naive_flown_makespan_s")
    if flown is None:
        return f"{_minutes(f['naive_split_makespan_s'])} ({pieces}, estimated)"
    return f"{_minutes(flown)} ({pieces}, finished and flown as the plans are)"


def fleet_summary_text(data: dict[str, Any]) -> str:
    """One screen of text from :func:`fleet_summary`'s dictionary."""
    f = data["fleet"]
    sep = f["separation"]
    gap = "no bound" if f["makespan_gap_pct"] is None else f"gap {f['makespan_gap_pct']:.1f} %"
    count = len(f["vehicles"])
    idle = [v for v in f["vehicles"] if v.get("idle")]
    flying = f", {count - len(idle)} flying" if idle else ""
    lines = [
        f"fleet          {count} vehicle{'s' if count != 1 else ''}{flying}, "
        f"{data['targets']} targets",
        f"makespan       {_minutes(f['makespan_s'])} (last landing); lower bound "
        f"{_minutes(f['makespan_bound_s'])}, {gap}",
        f"naive split    {_naive_line(f, count)}; one vehicle alone "
        f"{_minutes(f['single_vehicle']['flight_time_s'])}",
        "vehicle  layer (m)  above home  start  flight        length     sorties  targets",
    ]
    for v in f["vehicles"]:
        if v.get("idle"):
            lines.append(f"  {v['vehicle']:<6d}{v['altitude_m']:9.1f}  idle: nothing to fly")
            continue
        names = ", ".join(v["targets"][:5]) + (", ..." if len(v["targets"]) > 5 else "")
        lines.append(
            f"  {v['vehicle']:<6d}{v['altitude_m']:9.1f}{v['altitude_above_home_m']:11.1f} m"
            f"{v['start_delay_s']:6.0f} s  {_minutes(v['flight_time_s']):>12s}"
            f"{v['length_m']:9.0f} m{v['sorties']:7d}    {len(v['targets'])}: {names}"
        )
    if sep["mode"] == "altitude":
        how = f"altitude layers {sep['layer_spacing_m']:g} m apart"
    else:
        how = f"one layer, at least {sep['min_m']:g} m apart horizontally along the tracks"
    closest = (
        "never in the air together"
        if sep["closest_approach_m"] is None
        else f"closest approach {sep['closest_approach_m']:.1f} m (horizontally "
        f"{sep['closest_horizontal_m']:.1f} m) between vehicles {sep['closest_vehicles'][0]} "
        f"and {sep['closest_vehicles'][1]} at {sep['closest_at_s']:.0f} s, with either "
        f"up to {sep['timing_slack_s']:g} s early or late"
    )
    lines.append(f"separation     {how}; {closest}")
    delayed = [(k, d) for k, d in enumerate(sep["start_delays_s"], start=1) if d > 0]
    if delayed:
        lines.append(
            "start delays   "
            + ", ".join(f"vehicle {k} {d:g} s" for k, d in delayed)
            + " after the first take-off (to keep the separation)"
        )
    lines += [
        f"idle           vehicle {v['vehicle']} stays on the ground: {v['idle_reason']}"
        for v in idle
    ]
    lines += [f"warning        {w}" for w in data["warnings"]]
    if data["files"]:
        lines.append("files          " + "\n               ".join(data["files"]))
    return "\n".join(lines)


def write_fleet_products(
    fleet: FleetPlan, destinations: list[Destination], with_map: bool = True
) -> dict[str, Any]:
    """Write every vehicle's folder and the fleet's files as one set; return the summary.

    ``destinations`` are :func:`check_fleet_out`'s. Raises OutputError with every destination
    as it was when a file cannot be written.
    """
    *folders, top = destinations
    writes: list[tuple[Destination, dict[str, str | bytes]]] = []
    summaries: list[dict[str, Any] | None] = []
    listed: list[str] = []
    for plan, dest in zip(fleet.flying, folders, strict=True):
        # A vehicle left idle gets an empty set: an earlier plan's mission there is removed.
        data, files = (None, {}) if plan is None else render_products(plan, dest.folder, with_map)
        writes.append((dest, files))
        summaries.append(data)
        listed += [str(dest.folder / name) for name in files]
    own = {"plan.kml": fleet_kml(fleet.flying), "plan.geojson": fleet_geojson(fleet.flying)}
    names = [*own, SUMMARY_FILE] + ([MAP_FILE, MAP_PAGE_FILE] if with_map else [])
    rendered = [files for _dest, files in writes]
    data = fleet_summary(fleet, [str(top.folder / n) for n in names] + listed, rendered)
    top_files: dict[str, str | bytes] = {**own, SUMMARY_FILE: json.dumps(data, indent=2) + "\n"}
    if with_map:
        # matplotlib and Bokeh load only when a map is drawn.
        from urpt_gcs.files.mappage import render_fleet_page
        from urpt_gcs.files.mapview import render_fleet_map

        title = fleet_map_title(data)
        top_files[MAP_FILE] = render_fleet_map(fleet.flying, title)
        top_files[MAP_PAGE_FILE] = render_fleet_page(fleet.flying, summaries, title)
    commit([*writes, (top, top_files)])
    return data


def fleet_map_title(data: dict[str, Any]) -> str:
    """The fleet map's title, two lines from :func:`fleet_summary`'s dictionary: the
    makespan against its bound, then the separation."""
    f = data["fleet"]
    gap = "" if f["makespan_gap_pct"] is None else f", gap {f['makespan_gap_pct']:.1f} %"
    return (
        f"{len(f['vehicles'])} vehicles, {data['targets']} targets: makespan "
        f"{f['makespan_s'] / 60:.1f} min (bound {f['makespan_bound_s'] / 60:.1f} min{gap})\n"
        f"separation: {f['separation']['mode']}, closest approach "
        f"{f['separation']['closest_approach_m']} m"
    )
