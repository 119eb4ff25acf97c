"""The files a plan produces, rendered in memory and written all-or-nothing."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from urpt_gcs.formats import plan_json, waypoints_text
from urpt_gcs.output import write_all
from urpt_gcs.planner import Plan
from urpt_gcs.report import summary

PLAN_FILE = "mission.plan"
WAYPOINTS_FILE = "mission.waypoints"
SUMMARY_FILE = "summary.json"


def write_products(plan: Plan, out_dir: Path) -> dict[str, Any]:
    """Write mission.plan, mission.waypoints and summary.json; return the summary."""
    names = [PLAN_FILE, WAYPOINTS_FILE, SUMMARY_FILE]
    data = summary(plan, files=[str(out_dir / n) for n in names])
    files = {
        PLAN_FILE: plan_json(plan.mission),
        WAYPOINTS_FILE: waypoints_text(plan.mission),
        SUMMARY_FILE: json.dumps(data, indent=2) + "\n",
    }
    write_all(out_dir, files)
    return data
