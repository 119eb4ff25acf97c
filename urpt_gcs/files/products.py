"""The files a plan produces, rendered in memory and committed to ``--out`` as one set.

One sortie: ``mission.plan`` and ``mission.waypoints``; several: ``mission_1.plan``,
``mission_1.waypoints``, ``mission_2.plan``, ... Always ``summary.json``, ``plan.kml`` and
``plan.geojson``, and ``map.png`` with ``map.html`` (the same map as a page to pan, zoom and
hover, :mod:`urpt_gcs.files.mappage`) unless the caller asks for no map. Each ``.plan``
carries what its replay must check (:class:`~urpt_gcs.files.formats.qgc_plan.ReplayCheck`); a
``.waypoints`` has no room for it, and its replay reads ``summary.json`` beside it.

``--out`` holds one plan's files: a file of an earlier plan under one of these names
(:data:`PRODUCT_NAMES`) that this plan does not write is removed with the rest of the earlier
set, as is ``flown.json``, the report of a flight of it. Any other file in the folder is the
operator's and is left alone.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from urpt_gcs.errors import OutputError
from urpt_gcs.files.formats import plan_json, waypoints_text
from urpt_gcs.files.formats.geo import plan_geojson, plan_kml
from urpt_gcs.files.formats.qgc_plan import ReplayCheck
from urpt_gcs.files.output import Destination, check_file, check_folder, commit
from urpt_gcs.files.report import summary
from urpt_gcs.pipeline.result import Plan

SUMMARY_FILE = "summary.json"
MAP_FILE = "map.png"
MAP_PAGE_FILE = "map.html"
PRODUCT_NAMES = re.compile(
    r"mission(?:_[1-9][0-9]*)?\.(?:plan|waypoints)|summary\.json|map\.(?:png|html)"
    r"|plan\.(?:kml|geojson)"
    # What a flight of the earlier plan photographed (``urpt-gcs flown``): not of this plan.
    r"|flown\.json"
)


def mission_stems(plan: Plan) -> list[str]:
    """File stems of the missions: ``mission``, or ``mission_1``, ``mission_2``, ..."""
    if len(plan.missions) == 1:
        return ["mission"]
    return [f"mission_{k}" for k in range(1, len(plan.missions) + 1)]


def check_out(out_dir: Path) -> Destination:
    """Refuse an ``--out`` the products cannot be committed to, before anything is planned.

    Raises
    ------
    OutputError
        One line naming the folder and the fix.
    """
    return check_folder(out_dir, "--out", owns=PRODUCT_NAMES)


def check_extra(path: Path, flag: str, out: Destination) -> Destination:
    """Refuse a further output file (``--export-gtsp``) before anything is planned.

    It may lie outside ``--out``; it must not take the name of a product inside it.

    Raises
    ------
    OutputError
        One line naming the file and the fix.
    """
    folder = check_file(path, flag)
    same = os.path.realpath(folder.folder) == os.path.realpath(out.folder)
    if same and out.owned(path.name):
        raise OutputError(
            f"{flag} '{path}' is the name of one of the plan's own outputs in --out: "
            f"choose another {flag}"
        )
    return folder


def replay_checks(plan: Plan) -> list[ReplayCheck]:
    """Per sortie, what its replay must check: the targets its stops see, at the planned
    camera and clearance."""
    targets = plan.targets.targets
    checks = []
    for number, sortie in enumerate(plan.sorties, start=1):
        seen = plan.tour.sees[sortie.first : sortie.stop].any(axis=0)
        checks.append(
            ReplayCheck(
                fov_deg=plan.camera.fov_deg,
                min_clearance_m=plan.settings.min_clearance_m,
                targets=tuple(targets[t] for t in np.flatnonzero(seen).tolist()),
                sortie=number,
                sorties=len(plan.sorties),
                frame=plan.camera.frame,
                gsd_cm=plan.camera.gsd_cm,
            )
        )
    return checks


def render_products(
    plan: Plan, out_dir: Path, with_map: bool = True
) -> tuple[dict[str, Any], dict[str, str | bytes]]:
    """Every output of ``plan`` in memory: the summary, and file name -> content."""
    files: dict[str, str | bytes] = {}
    fence = [(lat, lon) for lat, lon in plan.geofence_latlon]
    for stem, mission, check in zip(
        mission_stems(plan), plan.missions, replay_checks(plan), strict=True
    ):
        files[f"{stem}.plan"] = plan_json(mission, geofence=fence, check=check)
        files[f"{stem}.waypoints"] = waypoints_text(mission)
    files["plan.kml"] = plan_kml(plan)
    files["plan.geojson"] = plan_geojson(plan)
    names = [*files, SUMMARY_FILE] + ([MAP_FILE, MAP_PAGE_FILE] if with_map else [])
    data = summary(plan, files=[str(out_dir / n) for n in names])
    files[SUMMARY_FILE] = json.dumps(data, indent=2) + "\n"
    if with_map:
        # matplotlib and Bokeh load only when a map is drawn.
        from urpt_gcs.files.mappage import render_map_page
        from urpt_gcs.files.mapview import render_map

        files[MAP_FILE] = render_map(plan, data)
        files[MAP_PAGE_FILE] = render_map_page(plan, data)
    return data, files


def write_products(
    plan: Plan,
    out: Path | Destination,
    with_map: bool = True,
    also: Sequence[tuple[Destination, Mapping[str, str | bytes]]] = (),
) -> dict[str, Any]:
    """Write every output of ``plan`` into ``out`` as one set; return the summary.

    Parameters
    ----------
    plan
        The plan.
    out
        The folder, or the :class:`Destination` :func:`check_out` returned for it.
    with_map
        Draw ``map.png`` and ``map.html``.
    also
        Further files committed in the same step (``--export-gtsp``): all are written or
        none, and ``out`` keeps its earlier set on any failure.

    Returns
    -------
    dict
        The summary, as in ``summary.json``.

    Raises
    ------
    OutputError
        A file could not be written; every destination is as it was.
    """
    destination = out if isinstance(out, Destination) else check_out(out)
    data, files = render_products(plan, destination.folder, with_map)
    commit([(destination, files), *also])
    return data


__all__ = [
    "MAP_FILE",
    "MAP_PAGE_FILE",
    "PRODUCT_NAMES",
    "SUMMARY_FILE",
    "check_extra",
    "check_out",
    "mission_stems",
    "render_products",
    "replay_checks",
    "write_products",
]
