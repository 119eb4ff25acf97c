"""The files a plan produces, rendered in memory and written all-or-nothing.

One sortie: ``mission.plan`` and ``mission.waypoints``; several: ``mission_1.plan``,
``mission_1.waypoints``, ``mission_2.plan``, ... Always ``summary.json``, ``plan.kml`` and
``plan.geojson``, and ``map.png`` unless the caller asks for none.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from urpt_gcs.formats import plan_json, waypoints_text
from urpt_gcs.formats.geo import plan_geojson, plan_kml
from urpt_gcs.output import write_all
from urpt_gcs.planner import Plan
from urpt_gcs.report import summary

SUMMARY_FILE = "summary.json"
MAP_FILE = "map.png"


def mission_stems(plan: Plan) -> list[str]:
    """File stems of the missions: ``mission``, or ``mission_1``, ``mission_2``, ..."""
    if len(plan.missions) == 1:
        return ["mission"]
    return [f"mission_{k}" for k in range(1, len(plan.missions) + 1)]


def write_products(plan: Plan, out_dir: Path, with_map: bool = True) -> dict[str, Any]:
    """Write every output of ``plan`` into ``out_dir``; return the summary."""
    files: dict[str, str | bytes] = {}
    fence = [(lat, lon) for lat, lon in plan.geofence_latlon]
    for stem, mission in zip(mission_stems(plan), plan.missions, strict=True):
        files[f"{stem}.plan"] = plan_json(mission, geofence=fence)
        files[f"{stem}.waypoints"] = waypoints_text(mission)
    files["plan.kml"] = plan_kml(plan)
    files["plan.geojson"] = plan_geojson(plan)
    names = [*files, SUMMARY_FILE] + ([MAP_FILE] if with_map else [])
    data = summary(plan, files=[str(out_dir / n) for n in names])
    files[SUMMARY_FILE] = json.dumps(data, indent=2) + "\n"
    if with_map:
        from urpt_gcs.mapview import render_map

        files[MAP_FILE] = render_map(plan, data)
    write_all(out_dir, files)
    return data
