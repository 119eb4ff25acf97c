"""write_outputs(): every file of a plan, or of a fleet's plan, written into a folder as one set."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from urpt_gcs.files.fleet_output import check_fleet_out, write_fleet_products
from urpt_gcs.files.products import write_products
from urpt_gcs.pipeline.fleet import FleetPlan
from urpt_gcs.pipeline.result import Plan

__all__ = ["write_outputs"]


def write_outputs(result: Plan | FleetPlan, out: Path, with_map: bool = True) -> dict[str, Any]:
    """Write a plan's files (``mission.plan``, ``mission.waypoints``, ``plan.kml``,
    ``plan.geojson``, ``summary.json``, ``map.png``, ``map.html``), or a fleet's folder (one
    sub-folder per vehicle and the fleet's summary), into ``out`` as one set, as ``urpt-gcs
    plan`` does.

    Parameters
    ----------
    result
        What :func:`urpt_gcs.plan` or :func:`urpt_gcs.plan_fleet` returned.
    out
        The folder; it is created if missing, and an earlier plan's files in it are replaced
        as a set (any other file is left alone).
    with_map
        Draw ``map.png`` and ``map.html``.

    Returns
    -------
    dict
        The summary, as written to ``summary.json``.

    Raises
    ------
    OutputError
        ``out`` cannot hold the files, or one could not be written; ``out`` is as it was.
    """
    if isinstance(result, FleetPlan):
        destinations = check_fleet_out(Path(out), len(result.plans))
        return write_fleet_products(result, destinations, with_map)
    return write_products(result, Path(out), with_map)
