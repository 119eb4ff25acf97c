"""A fleet plan's folder, as ``urpt-gcs plan --vehicles K --out OUT`` writes it.

``OUT/summary.json`` holds a ``fleet`` block (each vehicle's folder, altitude, home,
targets, sorties and the SHA-256 of each of its mission files, and how the vehicles are kept
apart); ``OUT/vehicle_k/`` holds exactly what a single-vehicle plan writes. :func:`read_fleet`
reads the block and finds each vehicle's mission files; upload and replay work from what it
returns. A summary written before the digests were recorded has none, and reads the same.
A vehicle the plan left idle (``"idle": true``) has no targets, no sorties and no mission
files; upload and replay pass it by.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from urpt_gcs.errors import MissionFileError
from urpt_gcs.files.mission_file import PLAN_STEM

__all__ = [
    "MISSION_FILE_NAME",
    "SUMMARY_MAX_BYTES",
    "SUMMARY_NAME",
    "FleetFolder",
    "FleetVehicle",
    "Separation",
    "SeparationMode",
    "read_fleet",
]

SUMMARY_NAME = "summary.json"
SUMMARY_MAX_BYTES = 16 * 1024 * 1024
SeparationMode = Literal["altitude", "time"]
_SHA256 = re.compile(r"[0-9a-f]{64}")
# The name of a mission file a plan writes: one sortie's, or sortie N's, .plan or .waypoints.
MISSION_FILE_NAME = re.compile(PLAN_STEM.pattern + r"\.(?:plan|waypoints)")


@dataclass(frozen=True, slots=True)
class FleetVehicle:
    """One vehicle of a fleet plan.

    Attributes
    ----------
    number
        Its number in the plan (1, 2, ...), the order connections are given in.
    folder
        Its plan folder (``OUT/vehicle_k``).
    missions
        Its mission files in sortie order (``mission.plan``, or ``mission_1.plan`` ...).
    altitude_m
        Its flight altitude as the plan states it (the DEM's vertical datum).
    targets
        The names of the targets it was planned to photograph.
    flight_time_s
        Its planned flight time, if the summary states it.
    start_delay_s
        How long after the fleet's common start it takes off (the plan keeps vehicles that
        share a home or cross paths apart by these delays).
    sorties_planned
        How many sorties the summary says it flies (None: it does not say).
    mission_sha256
        (file name, SHA-256 in hex) of each mission file as the plan wrote it; empty for a
        summary written before these were recorded.
    idle
        The plan gives it nothing to fly (``missions`` and ``targets`` are empty).
    """

    number: int
    folder: Path
    missions: tuple[Path, ...]
    altitude_m: float
    targets: tuple[str, ...]
    flight_time_s: float | None = None
    start_delay_s: float = 0.0
    sorties_planned: int | None = None
    mission_sha256: tuple[tuple[str, str], ...] = ()
    idle: bool = False

    @property
    def name(self) -> str:
        return f"vehicle {self.number}"


@dataclass(frozen=True, slots=True)
class Separation:
    """How the plan keeps its vehicles apart.

    ``mode`` "altitude": each flies its own layer, ``min_m`` apart vertically; "time": one
    layer, tours timed to keep ``min_m`` horizontally. ``planned_closest_m`` is the plan's
    closest 3-D approach of any two vehicles at equal times (None if not stated).
    """

    mode: SeparationMode
    min_m: float
    planned_closest_m: float | None


@dataclass(frozen=True, slots=True)
class FleetFolder:
    """A fleet plan: its folder, its vehicles in order, and their separation."""

    folder: Path
    vehicles: tuple[FleetVehicle, ...]
    separation: Separation


def read_fleet(folder: Path, flag: str = "--fleet") -> FleetFolder:
    """Read the fleet plan in ``folder``.

    Raises
    ------
    MissionFileError
        If the folder holds no fleet summary, the summary lacks a field the contract names,
        or a vehicle's folder holds no mission.
    """
    summary_path = folder / SUMMARY_NAME
    fix = "give the --out folder of urpt-gcs plan --vehicles K"
    if not folder.is_dir():
        raise MissionFileError(f"{flag} '{folder}' is not a folder: {fix}")
    if not summary_path.is_file():
        raise MissionFileError(f"{flag} '{folder}' holds no {SUMMARY_NAME}: {fix}")
    if summary_path.stat().st_size > SUMMARY_MAX_BYTES:
        raise MissionFileError(f"'{summary_path}' is over 16 MiB: {fix}")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MissionFileError(f"'{summary_path}' is not JSON ({exc}): {fix}") from None
    block = summary.get("fleet") if isinstance(summary, dict) else None
    if not isinstance(block, dict):
        raise MissionFileError(
            f"'{summary_path}' has no \"fleet\" block: it is a single-vehicle plan; upload or "
            "replay it without --fleet"
        )
    where = f"'{summary_path}' fleet"
    rows = block.get("vehicles")
    if not isinstance(rows, list) or not rows:
        raise MissionFileError(f'{where}: "vehicles" is missing or empty: {fix}')
    vehicles = tuple(_vehicle(folder, row, i, where) for i, row in enumerate(rows, start=1))
    numbers = [v.number for v in vehicles]
    if numbers != list(range(1, len(vehicles) + 1)):
        raise MissionFileError(
            f"{where}: vehicles are numbered {numbers}, not 1 to {len(vehicles)}: {fix}"
        )
    return FleetFolder(folder, vehicles, _separation(block.get("separation"), where))


def _vehicle(folder: Path, row: Any, index: int, where: str) -> FleetVehicle:
    if not isinstance(row, dict):
        raise MissionFileError(f"{where}: vehicle entry {index} is not an object")
    number = row.get("vehicle")
    if not isinstance(number, int) or isinstance(number, bool):
        raise MissionFileError(f'{where}: vehicle entry {index} has no integer "vehicle"')
    name = row.get("dir")
    if (
        not isinstance(name, str)
        or not name
        or Path(name).is_absolute()
        or ".." in Path(name).parts
    ):
        raise MissionFileError(
            f'{where}: vehicle {number}\'s "dir" {name!r} is not a folder name inside the plan'
        )
    altitude = _number(row.get("altitude_m"), f'{where}: vehicle {number}\'s "altitude_m"')
    targets = row.get("targets", [])
    if not isinstance(targets, list) or not all(isinstance(t, str) for t in targets):
        raise MissionFileError(f'{where}: vehicle {number}\'s "targets" is not a list of names')
    sub = folder / name
    missions = _missions(sub)
    idle = row.get("idle", False)
    if not isinstance(idle, bool):
        raise MissionFileError(
            f'{where}: vehicle {number}\'s "idle" is {idle!r}, not true or false'
        )
    if idle:
        return _idle_vehicle(number, sub, missions, altitude, targets, where)
    if not missions:
        raise MissionFileError(
            f"vehicle {number}'s folder '{sub}' holds no mission.plan or mission_N.plan: plan "
            "the fleet again"
        )
    planned = row.get("flight_time_s")
    flight_s = None if planned is None else _number(planned, f"{where}: vehicle {number}'s time")
    delay_s = _number(row.get("start_delay_s", 0.0), f"{where}: vehicle {number}'s start delay")
    if delay_s < 0.0:
        raise MissionFileError(
            f"{where}: vehicle {number}'s start delay {delay_s:g} s is negative: plan the "
            "fleet again"
        )
    sorties = row.get("sorties")
    if sorties is not None and (
        not isinstance(sorties, int) or isinstance(sorties, bool) or sorties < 1
    ):
        raise MissionFileError(
            f'{where}: vehicle {number}\'s "sorties" is {sorties!r}, not a count: plan the '
            "fleet again"
        )
    return FleetVehicle(
        number,
        sub,
        missions,
        altitude,
        tuple(targets),
        flight_s,
        delay_s,
        sorties,
        _digests(row.get("mission_sha256", {}), f"{where}: vehicle {number}'s"),
    )


def _idle_vehicle(
    number: int,
    sub: Path,
    missions: tuple[Path, ...],
    altitude: float,
    targets: list[str],
    where: str,
) -> FleetVehicle:
    """A vehicle the plan leaves idle: refused if its folder holds a mission or the summary
    gives it targets, for either is not what this plan flies."""
    if missions:
        raise MissionFileError(
            f"{where}: vehicle {number} is idle, yet its folder '{sub}' holds "
            f"'{missions[0].name}', which this plan does not fly: plan the fleet again"
        )
    if targets:
        raise MissionFileError(
            f"{where}: vehicle {number} is idle, yet it is given {len(targets)} targets: plan "
            "the fleet again"
        )
    return FleetVehicle(number, sub, (), altitude, (), 0.0, 0.0, 0, (), idle=True)


def _digests(value: Any, what: str) -> tuple[tuple[str, str], ...]:
    """The ``mission_sha256`` block: mission file name -> its SHA-256 in hex."""
    if not isinstance(value, dict) or not all(
        isinstance(name, str)
        and MISSION_FILE_NAME.fullmatch(name)
        and isinstance(digest, str)
        and _SHA256.fullmatch(digest)
        for name, digest in value.items()
    ):
        raise MissionFileError(
            f'{what} "mission_sha256" is not mission file names with their SHA-256: plan the '
            "fleet again"
        )
    return tuple(sorted(value.items()))


def _missions(folder: Path) -> tuple[Path, ...]:
    if not folder.is_dir():
        return ()
    found = sorted(folder.glob("mission*.plan")) or sorted(folder.glob("mission*.waypoints"))
    found = [f for f in found if PLAN_STEM.fullmatch(f.stem)]
    return tuple(sorted(found, key=lambda f: int(f.stem.partition("_")[2] or 0)))


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MissionFileError(f"{what} is {value!r}, not a number: plan the fleet again")
    return float(value)


def _separation(block: Any, where: str) -> Separation:
    if not isinstance(block, dict):
        raise MissionFileError(f'{where}: "separation" is missing: plan the fleet again')
    mode = block.get("mode")
    if mode not in ("altitude", "time"):
        raise MissionFileError(
            f'{where}: separation mode {mode!r} is neither "altitude" nor "time"'
        )
    min_m = _number(block.get("min_m"), f'{where}: separation "min_m"')
    if min_m <= 0.0:
        raise MissionFileError(f'{where}: separation "min_m" {min_m:g} must be positive')
    closest = block.get("closest_approach_m")
    planned = None if closest is None else _number(closest, f'{where}: "closest_approach_m"')
    return Separation(mode, min_m, planned)
