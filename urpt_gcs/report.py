"""Report: the plan summarised for the operator, as a screen of text and as JSON."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from urpt_gcs.planner import Plan


def _round(x: float, digits: int = 2) -> float | None:
    return round(x, digits) if math.isfinite(x) else None


def summary(plan: Plan, files: list[str] | None = None) -> dict[str, Any]:
    """The plan's key figures; what ``summary.json`` holds."""
    tour = plan.tour
    inst = plan.instance
    names = [t.name for t in plan.targets.targets]
    stops = []
    previous = np.asarray(plan.home_xy)
    assert tour.points_xy is not None
    for k, (xy, sees, item) in enumerate(
        zip(tour.points_xy, tour.sees, _waypoint_items(plan), strict=True), start=1
    ):
        stops.append(
            {
                "order": k,
                "lat_deg": item[0],
                "lon_deg": item[1],
                "sees": [names[t] for t in np.flatnonzero(sees).tolist()],
                "from_previous_m": round(float(np.hypot(*(xy - previous))), 2),
            }
        )
        previous = xy
    return {
        "targets": len(names),
        "target_names": names,
        "viewpoints": inst.n_viewpoints,
        "tour_stops": len(tour.order),
        "tour_length_m": round(tour.length, 3),
        "lower_bound_m": round(tour.lower_bound, 3),
        "gap_pct": _round(100.0 * tour.gap, 2),
        "proven_optimal": tour.proven_optimal,
        "solver": tour.solver,
        "solve_s": round(tour.solve_s, 3),
        "flight_time_s": round(plan.flight_time_s, 1),
        "altitude_amsl_m": round(plan.camera.altitude_m, 2),
        "altitude_above_home_m": round(plan.altitude_rel_m, 2),
        "terrain_max_m": round(plan.terrain_max_m, 2),
        "fov_deg": plan.camera.fov_deg,
        "samples": plan.settings.samples,
        "firmware": plan.mission.firmware,
        "hold_s": plan.settings.mission.hold_s,
        "cruise_speed_m_s": plan.settings.mission.cruise_speed_m_s,
        "home": {
            "lat_deg": plan.mission.home.lat_deg,
            "lon_deg": plan.mission.home.lon_deg,
            "ground_m": round(plan.home_ground_m, 2),
            "source": plan.home_source,
        },
        "dem": {
            "path": str(plan.dem.path),
            "crs": plan.crs.to_string(),
            "cell_m": round(plan.terrain.cell_m, 4),
            "read_window_px": list(plan.terrain.read_window_px),
            "source_shape_px": list(plan.terrain.source_shape_px),
        },
        "min_leg_clearance_m": _round(
            min((leg.min_clearance_m for leg in plan.legs), default=math.nan)
        ),
        "stops": stops,
        "timings_s": {k: round(v, 3) for k, v in plan.timings_s.items()},
        "warnings": list(plan.warnings),
        "files": files or [],
    }


def _waypoint_items(plan: Plan) -> list[tuple[float, float]]:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    return [
        (item.params[4], item.params[5])
        for item in plan.mission.items
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT
    ]


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s:02d} s"


def summary_text(data: dict[str, Any]) -> str:
    """One screen of text from :func:`summary`'s dictionary."""
    if data["proven_optimal"]:
        quality = f"proven optimal over the {data['viewpoints']} candidate viewpoints"
    elif data["gap_pct"] is None:
        quality = "no lower bound available"
    else:
        quality = (
            f"at most {data['gap_pct']:.1f} % above optimal "
            f"(lower bound {data['lower_bound_m']:.1f} m)"
        )
    home = data["home"]
    lines = [
        f"targets        {data['targets']}  ({', '.join(data['target_names'][:6])}"
        + (", ..." if data["targets"] > 6 else "")
        + ")",
        f"viewpoints     {data['viewpoints']} candidates, {data['tour_stops']} in the tour",
        f"tour           {data['tour_length_m']:.1f} m, {quality}",
        f"solver         {data['solver']} in {data['solve_s']:.2f} s",
        f"flight time    {_minutes(data['flight_time_s'])} (estimated at "
        f"{data['cruise_speed_m_s']:g} m/s, {data['hold_s']:g} s hold per photo)",
        f"altitude       {data['altitude_amsl_m']:.1f} m AMSL, "
        f"{data['altitude_above_home_m']:.1f} m"
        f" above home; highest terrain {data['terrain_max_m']:.1f} m",
        f"camera         half-angle {data['fov_deg']:g} deg, {data['samples']} azimuths",
        f"home           {home['lat_deg']:.7f}, {home['lon_deg']:.7f} ({home['source']})",
        f"clearance      at least {data['min_leg_clearance_m']} m over terrain on every leg",
        f"firmware       {data['firmware']}",
    ]
    lines += [f"warning        {w}" for w in data["warnings"]]
    if data["files"]:
        lines.append("files          " + "\n               ".join(data["files"]))
    return "\n".join(lines)
