"""Reading a mission file back: a ``.plan`` or ``.waypoints`` urpt-gcs wrote, and its fence.

``urpt-gcs upload`` and ``urpt-gcs replay`` both start here. A ``.plan`` carries the mission
and its geofence; a ``.waypoints`` file (Mission Planner's text format) only the mission. A
folder of urpt-gcs ``plan`` output holds ``mission.plan``, or one ``mission_N.plan`` per sortie
(:data:`PLAN_STEM`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from urpt_gcs.errors import MissionFileError
from urpt_gcs.files.formats import read_plan, read_waypoints
from urpt_gcs.flight.geofence import Geofence, read_plan_geofence
from urpt_gcs.flight.mission import Mission
from urpt_gcs.site.inputs import MISSION_FILE_MAX_BYTES, read_capped

__all__ = ["PLAN_STEM", "mission_files", "read_fence", "read_mission"]

# The name of a mission file urpt-gcs writes, without its extension: one sortie, or sortie N.
PLAN_STEM = re.compile(r"mission(?:_[1-9][0-9]*)?")


def read_mission(path: Path, flag: str = "--plan") -> Mission:
    """A ``.plan`` or ``.waypoints`` file (by extension), of at most 16 MiB.

    ``flag`` is where the operator gave the path, for the messages.
    """
    data = read_capped(
        path,
        "mission file",
        flag,
        MissionFileError,
        MISSION_FILE_MAX_BYTES,
        "give the mission urpt-gcs plan wrote",
    )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MissionFileError(f"mission file '{path}' cannot be read: {exc}") from None
    if path.suffix.lower() == ".waypoints":
        return read_waypoints(text, str(path))
    if path.suffix.lower() == ".plan":
        return read_plan(text, str(path))
    raise MissionFileError(
        f"'{path}' is neither a .plan nor a .waypoints file: give the mission urpt-gcs plan wrote"
    )


def read_fence(path: Path) -> Geofence:
    """The geofence of a ``.plan`` file; empty for a ``.waypoints`` file, which has none."""
    if path.suffix.lower() != ".plan":
        return Geofence()
    data = read_capped(
        path,
        "mission file",
        "--plan",
        MissionFileError,
        MISSION_FILE_MAX_BYTES,
        "give the mission urpt-gcs plan wrote",
    )
    return read_plan_geofence(data.decode("utf-8", errors="replace"), str(path))


def mission_files(paths: Sequence[Path]) -> list[Path]:
    """The mission files to replay: each file given, and for a folder its sorties'
    ``mission*.plan`` (or, without any, its ``mission*.waypoints``) in sortie order.

    Raises
    ------
    MissionFileError
        If a folder holds no mission urpt-gcs wrote.
    """
    files: list[Path] = []
    for path in paths:
        if not path.is_dir():
            files.append(path)
            continue
        found = sorted(path.glob("mission*.plan")) or sorted(path.glob("mission*.waypoints"))
        found = [f for f in found if PLAN_STEM.fullmatch(f.stem)]
        if not found:
            raise MissionFileError(
                f"--plan folder '{path}' holds no mission.plan or mission_N.plan: give the "
                "--out folder of urpt-gcs plan, or the mission files"
            )
        files.extend(sorted(found, key=lambda f: int(f.stem.partition("_")[2] or 0)))
    return files
