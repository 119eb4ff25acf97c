"""Mission files checked against the ``summary.json`` their plan wrote beside them.

A plan's folder states what its missions are: a single plan's ``summary.json`` lists every
stop (the photo waypoints, by sortie, at the positions written); a fleet's top-level
``summary.json`` names each vehicle's targets and sorties and, since it records them, the
SHA-256 of each mission file as written (:func:`mission_sha256`). ``upload --fleet`` claims
that each vehicle holds *its* mission, so :func:`check_missions` refuses, before anything is
sent, a folder whose files are not the ones its summary records: a mission copied over
another vehicle's, a vehicle's folder swapped, a sortie missing or added, a file changed
after planning. A summary without digests (written before they were recorded) is checked on
what it has: each vehicle's own summary, its stops and targets. A single ``upload`` claims
nothing about a plan, only that the vehicle holds the file; :func:`summary_warning` says
when the summary beside the file plans other stops for it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from urpt_gcs.errors import MissionFileError
from urpt_gcs.files.fleet_folder import (
    MISSION_FILE_NAME,
    SUMMARY_MAX_BYTES,
    SUMMARY_NAME,
    FleetFolder,
    FleetVehicle,
)
from urpt_gcs.files.mission_file import PLAN_STEM, read_mission
from urpt_gcs.flight.mission import Mission, photo_positions
from urpt_gcs.site.inputs import MISSION_FILE_MAX_BYTES, read_capped

__all__ = [
    "SAME_PLACE_DEG",
    "check_missions",
    "flies",
    "mission_digests",
    "mission_sha256",
    "sortie_of",
    "summary_warning",
]

# A summary's stop is a mission's photo waypoint if they agree to this (both on MAVLink's
# 1e-7 degree grid, and the .waypoints file writes 8 decimals).
SAME_PLACE_DEG = 1e-9
_FIX = "restore the folder as urpt-gcs plan wrote it, or plan the fleet again"


def mission_sha256(content: str | bytes) -> str:
    """The SHA-256, in hex, of a mission file's bytes (a ``str`` as UTF-8, as written)."""
    data = content.encode("utf-8") if isinstance(content, str) else content
    return hashlib.sha256(data).hexdigest()


def mission_digests(files: Mapping[str, str | bytes]) -> dict[str, str]:
    """File name -> SHA-256 of each mission file among a plan's rendered files."""
    return {
        name: mission_sha256(content)
        for name, content in sorted(files.items())
        if MISSION_FILE_NAME.fullmatch(name)
    }


def sortie_of(path: Path) -> int | None:
    """The sortie a mission file is by its name: ``mission`` 1, ``mission_<k>`` k."""
    if not PLAN_STEM.fullmatch(path.stem):
        return None
    return int(path.stem.partition("_")[2] or 1)


def _summary(folder: Path) -> dict[str, Any] | None:
    """The single-plan ``summary.json`` in ``folder``, or None without a usable one."""
    path = folder / SUMMARY_NAME
    try:
        if not path.is_file() or path.stat().st_size > SUMMARY_MAX_BYTES:
            return None
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("stops"), list) else None


def _stops(summary: dict[str, Any], sortie: int) -> list[tuple[float, float]] | None:
    """The positions of a sortie's stops, in order; None if the summary's stops are unusable."""
    try:
        return [
            (float(s["lat_deg"]), float(s["lon_deg"]))
            for s in summary["stops"]
            if s["sortie"] == sortie
        ]
    except (KeyError, TypeError, ValueError):
        return None


def flies(mission: Mission, stops: list[tuple[float, float]]) -> bool:
    """Whether the mission's photo waypoints are these stops, in this order."""
    flown = photo_positions(mission)
    return len(flown) == len(stops) and all(
        abs(a - c) <= SAME_PLACE_DEG and abs(b - d) <= SAME_PLACE_DEG
        for (a, b), (c, d) in zip(flown, stops, strict=True)
    )


def _difference(flown: list[tuple[float, float]], stops: list[tuple[float, float]]) -> str:
    """How a mission's photo waypoints differ from a summary's stops, in a few words."""
    if len(flown) != len(stops):
        return f"it has {len(flown)} photo waypoints, the summary {len(stops)} stops"
    k = next(
        k
        for k, ((a, b), (c, d)) in enumerate(zip(flown, stops, strict=True), start=1)
        if abs(a - c) > SAME_PLACE_DEG or abs(b - d) > SAME_PLACE_DEG
    )
    return f"its photo waypoint {k} is not at stop {k}"


def summary_warning(path: Path, mission: Mission) -> str | None:
    """A warning when the ``summary.json`` beside a mission file plans other stops for it.

    Parameters
    ----------
    path
        The mission file (``mission.plan``, ``mission_2.waypoints``, ...).
    mission
        Its mission, as read.

    Returns
    -------
    str or None
        One line naming the file and the summary; None when they agree, or when there is no
        single plan's summary beside it to ask.
    """
    sortie = sortie_of(path)
    summary = _summary(path.parent) if sortie is not None else None
    if summary is None or sortie is None:
        return None
    stops = _stops(summary, sortie)
    if stops is None or flies(mission, stops):
        return None
    return (
        f"'{path}' does not fly the stops '{path.parent / SUMMARY_NAME}' plans for it: it is "
        "not the mission planned there"
    )


def check_missions(fleet: FleetFolder) -> None:
    """Refuse a fleet folder whose mission files are not the ones its summary records.

    Each vehicle's files must be as many as its sorties; its own ``summary.json`` must plan
    the targets the fleet's gives it; each mission file must have the SHA-256 the fleet's
    summary recorded for it, or, where none was recorded, fly the stops the vehicle's own
    summary plans for that sortie.

    Raises
    ------
    MissionFileError
        One line naming the file, what it is instead, and the fix.
    """
    top = fleet.folder / SUMMARY_NAME
    owns = {v.number: _summary(v.folder) for v in fleet.vehicles}
    for vehicle in fleet.vehicles:
        count = len(vehicle.missions)
        if vehicle.sorties_planned is not None and vehicle.sorties_planned != count:
            planned = vehicle.sorties_planned
            raise MissionFileError(
                f"{vehicle.name}'s folder '{vehicle.folder}' holds {count} mission "
                f"file{'s' if count != 1 else ''} but '{top}' plans {planned} "
                f"sortie{'s' if planned != 1 else ''} for it: {_FIX}"
            )
        own = owns[vehicle.number]
        if own is not None:
            _check_targets(fleet, vehicle, own, top)
        for path in vehicle.missions:
            _check_mission(fleet, vehicle, path, owns, top)


def _check_targets(
    fleet: FleetFolder, vehicle: FleetVehicle, own: dict[str, Any], top: Path
) -> None:
    names = own.get("target_names")
    if not vehicle.targets or not isinstance(names, list):
        return
    planned = {str(n) for n in names}
    if planned == set(vehicle.targets):
        return
    whose = [v.name for v in fleet.vehicles if v is not vehicle and set(v.targets) == planned]
    what = (
        f"they are {whose[0]}'s"
        if whose
        else f"{len(planned)} targets, not its {len(vehicle.targets)}"
    )
    raise MissionFileError(
        f"'{vehicle.folder / SUMMARY_NAME}' plans other targets than '{top}' gives "
        f"{vehicle.name} ({what}): {_FIX}"
    )


def _check_mission(
    fleet: FleetFolder,
    vehicle: FleetVehicle,
    path: Path,
    owns: dict[int, dict[str, Any] | None],
    top: Path,
) -> None:
    recorded = dict(vehicle.mission_sha256)
    if recorded and path.name not in recorded:
        raise MissionFileError(
            f"'{path}' is not a mission '{top}' records for {vehicle.name} (it has "
            f"{', '.join(recorded)}): {_FIX}"
        )
    if path.name in recorded:
        data = read_capped(
            path,
            "mission file",
            "--fleet",
            MissionFileError,
            MISSION_FILE_MAX_BYTES,
            "give the mission urpt-gcs plan wrote",
        )
        digest = mission_sha256(data)
        if digest == recorded[path.name]:
            return
        whose = [
            f"{v.name}'s {name}"
            for v in fleet.vehicles
            for name, other in v.mission_sha256
            if other == digest and (v.number, name) != (vehicle.number, path.name)
        ]
        what = f"it is {whose[0]}" if whose else "it was changed after planning"
        raise MissionFileError(
            f"'{path}' is not the mission '{top}' records for {vehicle.name} ({what}): {_FIX}"
        )
    sortie = sortie_of(path)
    own = owns[vehicle.number]
    stops = None if own is None or sortie is None else _stops(own, sortie)
    if stops is None or sortie is None:
        return
    mission = read_mission(path, flag="urpt-gcs upload --fleet")
    if flies(mission, stops):
        return
    whose = [
        f"{v.name}'s sortie {k}"
        for v in fleet.vehicles
        if (other := owns[v.number]) is not None
        for k in range(1, len(v.missions) + 1)
        if (v.number, k) != (vehicle.number, sortie)
        and (theirs := _stops(other, k)) is not None
        and flies(mission, theirs)
    ]
    what = f"it flies {whose[0]}" if whose else _difference(photo_positions(mission), stops)
    raise MissionFileError(
        f"'{path}' does not fly the stops '{vehicle.folder / SUMMARY_NAME}' plans for "
        f"{vehicle.name}'s sortie {sortie} ({what}): {_FIX}"
    )
