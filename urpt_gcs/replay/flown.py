"""What a real flight photographed: a plan's targets judged from the photos its logs hold.

:func:`judge_flown` reads each log (:mod:`urpt_gcs.replay.flightlog`), finds which sortie of
the plan it flew, and judges the photos where they were really taken, at the attitude they
report, by the rules every replay is judged by (:mod:`urpt_gcs.replay.judge`): the line of
sight over the DSM, the camera's cone or its frame turned to the photo's heading, the GSD.
All the logs' photos together are then judged on every target of the plan: each is seen, by
a photo of a log, or missed. :func:`remaining_targets` gives the missed ones, for a plan that
re-flies only them (``urpt-gcs plan --resume``).

Which sortie a log flew: the mission it holds (the upload in a ``.tlog``, CMD in a DataFlash
log) must put a waypoint on every stop of one sortie; a log without a mission is placed by
its photos, the sortie whose stops most of them were taken at. A log that fits no sortie, or
comes from the other autopilot than the plan was made for, is refused in one line.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urpt_gcs.errors import SettingsError
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.files.plan_check import SAME_PLACE_DEG
from urpt_gcs.replay.expected import SUMMARY_FILE, expected_checks, target_set
from urpt_gcs.replay.flightlog import FlightLog, read_flight_log
from urpt_gcs.replay.judge import ReplayReport, TargetSeen, judge, judge_set
from urpt_gcs.replay.record import Flight, VehicleIdentity
from urpt_gcs.sim.model import EARTH_RADIUS_M
from urpt_gcs.site.targets import Target, TargetSet

__all__ = [
    "FLOWN_FILE",
    "FlownReport",
    "LogVerdict",
    "flown_json",
    "flown_text",
    "judge_flown",
    "plan_dem",
    "plan_summary",
    "plan_targets",
    "remaining_targets",
]

FLOWN_FILE = "flown.json"
# A logged waypoint is on a planned stop within this: MAVLink's 1e-7 degree grid, twice.
WAYPOINT_MATCH_DEG = 2 * SAME_PLACE_DEG
# A photo was taken at a stop if within this of it: a real copter holds a waypoint to well
# under a metre in calm air, and wind and GPS add a few.
PHOTO_AT_STOP_M = 10.0
_NAMES = {"ardupilot": "ArduPilot", "px4": "PX4", "unknown": "an unknown autopilot"}


@dataclass(frozen=True, slots=True)
class LogVerdict:
    """One log: what it held, the sortie it flew and that sortie's own judgement."""

    log: FlightLog
    sortie: int
    report: ReplayReport


@dataclass(frozen=True, slots=True)
class FlownReport:
    """Every target of a plan, seen (by which photo of which log) or missed."""

    plan: Path
    logs: tuple[LogVerdict, ...]
    targets: tuple[TargetSeen, ...]
    plan_targets: TargetSet

    @property
    def missed(self) -> list[str]:
        """Names of the targets no photo saw, in the plan's order."""
        return [t.name for t in self.targets if t.photo is None]


def plan_summary(plan_dir: Path) -> dict[str, Any]:
    """The plan folder's ``summary.json``.

    Raises
    ------
    SettingsError
        If the folder holds no summary of one vehicle's plan.
    """
    path = plan_dir / SUMMARY_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SettingsError(
            f"'{plan_dir}' holds no {SUMMARY_FILE}: give the --out folder of urpt-gcs plan"
        ) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SettingsError(f"'{path}' cannot be read ({exc}): plan it again") from None
    if not isinstance(data, dict) or "stops" not in data:
        if isinstance(data, dict) and "fleet" in data:
            raise SettingsError(
                f"'{plan_dir}' is a fleet's folder: give the folder of the vehicle that flew "
                f"(e.g. '{plan_dir / 'vehicle_1'}')"
            )
        raise SettingsError(f"'{path}' is not a plan's summary: give the --out folder of a plan")
    return data


def plan_targets(plan_dir: Path) -> TargetSet:
    """The targets the plan was made for, where it put them (its ``plan.geojson``)."""
    path = plan_dir / "plan.geojson"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        targets = tuple(
            Target(f["properties"]["name"], *reversed(f["geometry"]["coordinates"][:2]))
            for f in data["features"]
            if f["properties"].get("kind") == "target"
        )
    except FileNotFoundError:
        raise SettingsError(
            f"'{plan_dir}' holds no plan.geojson: give --targets, the file it was planned from"
        ) from None
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise SettingsError(
            f"'{path}' cannot be read ({exc}): give --targets, the file it was planned from"
        ) from None
    return TargetSet(targets, None, str(path))


def plan_dem(summary: dict[str, Any], given: Path | None) -> Path:
    """The DSM: ``given``, else the one the plan's summary names (SettingsError if missing)."""
    if given is not None:
        return given
    path = Path(str((summary.get("dem") or {}).get("path", "")))
    if not path.is_file():
        raise SettingsError(
            f"the DSM the plan was made on ('{path}') is not there from this folder: give it "
            "with --dem"
        )
    return path


def _mission_files(plan_dir: Path, sorties: int) -> list[Path]:
    names = (
        ["mission.plan"] if sorties == 1 else [f"mission_{k}.plan" for k in range(1, sorties + 1)]
    )
    paths = [plan_dir / n for n in names]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise SettingsError(
            f"'{plan_dir}' lacks {missing[0].name}, which its {SUMMARY_FILE} names: give the "
            "whole folder urpt-gcs plan wrote"
        )
    return paths


def _distance_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    north = math.radians(a[0] - b[0]) * EARTH_RADIUS_M
    east = math.radians(a[1] - b[1]) * EARTH_RADIUS_M * math.cos(math.radians(b[0]))
    return math.hypot(north, east)


def _sortie_of_log(log: FlightLog, stops: dict[int, list[tuple[float, float]]]) -> int:
    """The sortie ``log`` flew; SettingsError if none fits."""
    fix = "give the log of a flight of this plan"
    if log.mission:
        logged = [(w.lat_deg, w.lon_deg) for w in log.mission]
        for sortie, places in stops.items():
            if all(
                any(
                    abs(lat - a) <= WAYPOINT_MATCH_DEG and abs(lon - b) <= WAYPOINT_MATCH_DEG
                    for a, b in logged
                )
                for lat, lon in places
            ):
                return sortie
        raise SettingsError(
            f"--log '{log.path}' flew a mission of {len(log.mission)} waypoints that is no "
            f"sortie of this plan (none has all its stops among them): {fix}"
        )
    votes: Counter[int] = Counter()
    for photo in log.photos:
        here = (photo.lat_deg, photo.lon_deg)
        near = [
            (_distance_m(here, place), sortie)
            for sortie, places in stops.items()
            for place in places
        ]
        distance, sortie = min(near)
        if distance <= PHOTO_AT_STOP_M:
            votes[sortie] += 1
    if not votes:
        raise SettingsError(
            f"--log '{log.path}': none of its {len(log.photos)} photos was taken within "
            f"{PHOTO_AT_STOP_M:g} m of a stop of this plan: {fix}"
        )
    return votes.most_common(1)[0][0]


def judge_flown(
    plan_dir: Path,
    log_paths: Sequence[Path],
    dem_path: Path | None = None,
    targets_path: Path | None = None,
) -> FlownReport:
    """Judge every target of the plan in ``plan_dir`` from the photos of ``log_paths``.

    Parameters
    ----------
    plan_dir
        The ``--out`` folder of one vehicle's plan.
    log_paths
        The logs of its flights (``.tlog`` or DataFlash ``.bin``), one per sortie flown.
    dem_path
        The DSM; None: the one the plan's summary names.
    targets_path
        The target file; None: the targets where the plan put them (its ``plan.geojson``).

    Raises
    ------
    SettingsError
        One line: no plan there, a log that cannot be read or belongs to no sortie of it,
        a log of the other autopilot, the DSM not found.
    """
    summary = plan_summary(plan_dir)
    if not log_paths:
        raise SettingsError("give at least one --log: the flight's .tlog or DataFlash .bin")
    sorties = max(1, len(summary.get("sorties") or []))
    files = _mission_files(plan_dir, sorties)
    stops: dict[int, list[tuple[float, float]]] = {k: [] for k in range(1, sorties + 1)}
    for stop in summary["stops"]:
        stops.setdefault(int(stop["sortie"]), []).append((stop["lat_deg"], stop["lon_deg"]))
    dem_path = plan_dem(summary, dem_path)
    targets = target_set(targets_path) if targets_path is not None else plan_targets(plan_dir)
    firmware = str(summary.get("firmware", ""))
    verdicts = []
    for path in log_paths:
        log = read_flight_log(path)
        if log.autopilot in ("ardupilot", "px4") and firmware and log.autopilot != firmware:
            raise SettingsError(
                f"--log '{path}' is of a {_NAMES[log.autopilot]} vehicle, but the plan was made "
                f"for {_NAMES.get(firmware, firmware)}: give the log of the vehicle that flew it"
            )
        sortie = _sortie_of_log(log, stops)
        plan_file = files[sortie - 1]
        mission = read_mission(plan_file)
        expected = expected_checks(plan_file, mission, None, None)
        vehicle = VehicleIdentity(_NAMES[log.autopilot], log.firmware, f"log {path.name}")
        flight = Flight(None, log.photos, log.track, log.duration_s, log.duration_s, vehicle)
        report = judge(flight, mission, dem_path, targets, expected, path.name)
        verdicts.append(LogVerdict(log, sortie, report))
    together = judge_set([v.report for v in verdicts], dem_path, targets)
    return FlownReport(plan_dir, tuple(verdicts), together.targets, targets)


def remaining_targets(report: FlownReport) -> TargetSet:
    """The targets of ``report`` no photo saw, as a target set to plan."""
    missed = set(report.missed)
    kept = tuple(t for t in report.plan_targets.targets if t.name in missed)
    logs = ", ".join(v.log.path.name for v in report.logs)
    source = f"{len(kept)} targets of '{report.plan}' not photographed in {logs}"
    return TargetSet(kept, None, source)


def flown_json(report: FlownReport) -> dict[str, Any]:
    """The report as ``flown.json`` holds it."""
    return {
        "plan": str(report.plan),
        "logs": [
            {
                "path": str(v.log.path),
                "kind": v.log.kind,
                "autopilot": v.log.autopilot,
                "firmware": v.log.firmware,
                "sortie": v.sortie,
                "photos": len(v.log.photos),
                "track_fixes": len(v.log.track),
                "cut_short": v.log.armed_at_end,
                "warnings": list(v.log.warnings),
                "min_clearance_m": v.report.min_clearance_m,
            }
            for v in report.logs
        ],
        "targets": len(report.targets),
        "seen": len(report.targets) - len(report.missed),
        "missed": report.missed,
        "by_target": [
            {
                "name": t.name,
                "seen": t.photo is not None,
                "photo": t.photo,
                "log": t.plan or None,
                "offset_m": None if t.offset_m is None else round(t.offset_m, 2),
                "why_not": t.reason or None,
            }
            for t in report.targets
        ],
    }


def flown_text(report: FlownReport) -> str:
    """The report for the operator, one screen."""
    lines = [f"flown: {report.plan}"]
    for v in report.logs:
        log = v.log
        who = f"{_NAMES[log.autopilot]} {log.firmware}".strip()
        lines.append(
            f"  log {log.path.name}: {who}, sortie {v.sortie}, {len(log.photos)} photos, "
            f"{len(log.track)} fixes"
        )
        lines.extend(f"    warning: {w}" for w in log.warnings)
    seen = len(report.targets) - len(report.missed)
    lines.append(f"  targets {seen} of {len(report.targets)} seen")
    width = max((len(t.name) for t in report.targets), default=0)
    for t in report.targets:
        if t.photo is not None:
            lines.append(f"    {t.name:<{width}}  seen: photo {t.photo} of {t.plan}")
        else:
            lines.append(f"    {t.name:<{width}}  MISSED: {t.reason}")
    if report.missed:
        lines.append(
            f"  re-fly the {len(report.missed)} missed with: urpt-gcs plan --resume "
            f"{report.plan} " + " ".join(f"--log {v.log.path}" for v in report.logs) + " --out OUT2"
        )
    else:
        lines.append("  every target was photographed")
    return "\n".join(lines)
