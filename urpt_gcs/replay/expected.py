"""What a replay judges: the camera, the clearance and the targets a mission was planned for.

What is checked comes with the mission (:func:`expected_checks`): a ``.plan`` urpt-gcs wrote
names the camera half-angle, the least clearance and the targets of its sortie
(:class:`~urpt_gcs.files.formats.qgc_plan.ReplayCheck`); a ``.waypoints`` has no room for them and
takes them from the ``summary.json`` beside it, if that describes it; otherwise every target
of the target file at ``--fov``. A ``--fov`` or ``--min-clearance`` given overrides the plan's,
with a warning where they differ.

Which targets are judged (:func:`chosen_targets`): the sortie's own. A plan's only sortie
replayed alone is the whole plan, and its PASS says every target of ``--targets`` was seen:
so every target of the file is judged as well, each where the file puts it; one the plan was
not made for, or that the file puts elsewhere, is marked as such. A sortie of several, or a
flight of a set, is judged on its own targets (the set on every target, by
:func:`urpt_gcs.replay.judge.judge_set`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from urpt_gcs.files.formats.qgc_plan import read_replay_check
from urpt_gcs.files.plan_check import SAME_PLACE_DEG, flies, sortie_of
from urpt_gcs.flight.mission import Mission
from urpt_gcs.replay.band_track import band_of_summary
from urpt_gcs.site.camera import Frame
from urpt_gcs.site.targets import Target, TargetSet, read_targets

__all__ = [
    "DEFAULT_FOV_DEG",
    "DEFAULT_MIN_CLEARANCE_M",
    "SAME_PLACE_DEG",
    "SAME_TARGET_DEG",
    "SUMMARY_FILE",
    "Expected",
    "Unplanned",
    "chosen_targets",
    "expected_checks",
    "target_set",
]

# What a replay checks when neither the mission nor a flag says.
DEFAULT_FOV_DEG = 30.0
DEFAULT_MIN_CLEARANCE_M = 10.0
SUMMARY_FILE = "summary.json"
# A target of --targets is where the plan put it if they agree to this (about 10 cm).
SAME_TARGET_DEG = 1e-6
# Why a target judged was not one the plan was made for: not among its targets at all, or
# at another place in --targets than in the plan.
Unplanned = Literal["", "extra", "moved"]


@dataclass(frozen=True, slots=True)
class Expected:
    """What a replay judges, and where that came from.

    Attributes
    ----------
    fov_deg
        Camera half-angle from nadir.
    min_clearance_m
        Least height above the terrain the cruise legs must keep.
    targets
        The targets to be photographed with their positions, or None: by ``names``.
    names
        The names of the targets, to be found in the target file; None with ``targets``
        None: every target of the file.
    source
        Where these came from, for the report (``mission_2.plan, sortie 2 of 3``).
    warnings
        Flags that override the mission's, or a summary that does not fit.
    frame, gsd_cm
        The plan's frame camera (None: the cone) and the ground resolution it had to reach.
    band
        The height band (floor, ceiling above the surface) the plan follows the terrain in,
        from the summary; None for a plan on one flight plane.
    whole
        The mission is its plan's only sortie: replayed alone, every target of the target
        file is judged too (:func:`chosen_targets`).
    """

    fov_deg: float
    min_clearance_m: float
    targets: tuple[Target, ...] | None = None
    names: tuple[str, ...] | None = None
    source: str = "--fov and --min-clearance, every target of --targets"
    warnings: tuple[str, ...] = ()
    frame: Frame | None = None
    gsd_cm: float | None = None
    band: tuple[float, float] | None = None
    whole: bool = False


def expected_checks(
    plan_path: Path, mission: Mission, fov_deg: float | None, min_clearance_m: float | None
) -> Expected:
    """What a replay of ``plan_path`` checks; see the module docstring.

    Parameters
    ----------
    plan_path
        The mission file, as read into ``mission``.
    mission
        Its mission, to tell whether a ``summary.json`` beside it describes it.
    fov_deg, min_clearance_m
        ``--fov`` and ``--min-clearance`` if given, else None.

    Raises
    ------
    MissionFileError
        If a plan's ``urptGcs`` key is not usable.
    """
    warnings: list[str] = []
    if plan_path.suffix.lower() == ".plan":
        check = read_replay_check(plan_path.read_text(encoding="utf-8"), str(plan_path))
        if check is None:
            planned = None
        else:
            planned = (check.fov_deg, check.min_clearance_m)
            where = f"{plan_path.name}, sortie {check.sortie} of {check.sorties}"
            targets: tuple[Target, ...] | None = check.targets
            names: tuple[str, ...] | None = None
            camera = (check.frame, check.gsd_cm)
            whole = check.sorties == 1
    else:
        targets = None
        planned, where, names, whole = _from_summary(plan_path, mission, warnings)
        camera = _camera_from_summary(plan_path) if planned is not None else (None, None)
    band = _band_from_summary(plan_path, mission, warnings)
    if planned is None:
        return Expected(
            fov_deg if fov_deg is not None else DEFAULT_FOV_DEG,
            min_clearance_m if min_clearance_m is not None else DEFAULT_MIN_CLEARANCE_M,
            warnings=tuple(warnings),
            band=band,
        )
    fov, clearance = planned
    for flag, given, value, unit in (
        ("--fov", fov_deg, fov, " deg"),
        ("--min-clearance", min_clearance_m, clearance, " m"),
    ):
        if given is not None and given != value:
            warnings.append(
                f"{flag} {given:g}{unit} overrides the {value:g}{unit} {plan_path.name} was "
                "planned for"
            )
    return Expected(
        fov_deg if fov_deg is not None else fov,
        min_clearance_m if min_clearance_m is not None else clearance,
        targets,
        names,
        where,
        tuple(warnings),
        *camera,
        band=band,
        whole=whole,
    )


def _band_from_summary(
    path: Path, mission: Mission, warnings: list[str]
) -> tuple[float, float] | None:
    """The height band of the ``summary.json`` beside a mission file, if it describes it."""
    summary_path = path.parent / SUMMARY_FILE
    number = sortie_of(path)
    if number is None or not summary_path.is_file():
        return None
    try:
        data: Any = json.loads(summary_path.read_text(encoding="utf-8"))
        band = band_of_summary(data)
        if band is None:
            return None
        stops = [
            (float(s["lat_deg"]), float(s["lon_deg"]))
            for s in data["stops"]
            if s["sortie"] == number
        ]
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        warnings.append(
            f"'{summary_path}' names no usable height band ({exc}): the track is not judged "
            "against one"
        )
        return None
    if not flies(mission, stops):
        return None
    return band


def _camera_from_summary(path: Path) -> tuple[Frame | None, float | None]:
    """The frame camera a ``summary.json`` names (None, None for the cone)."""
    try:
        data: Any = json.loads((path.parent / SUMMARY_FILE).read_text(encoding="utf-8"))
        camera = data.get("camera")
        if camera is None:
            return None, None
        w, h = (float(v) for v in camera["sensor_mm"])
        iw, ih = (int(v) for v in camera["image_px"])
        frame = Frame(w, h, float(camera["focal_mm"]), iw, ih)
        gsd = camera.get("gsd_cm_required")
        return frame, None if gsd is None else float(gsd)
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
        return None, None


def _from_summary(
    path: Path, mission: Mission, warnings: list[str]
) -> tuple[tuple[float, float] | None, str, tuple[str, ...] | None, bool]:
    """The camera, clearance and target names for a .waypoints from the summary beside it,
    and whether it is the plan's only sortie."""
    summary_path = path.parent / SUMMARY_FILE
    number = sortie_of(path)
    if not summary_path.is_file() or number is None:
        return None, "", None, False
    fallback = "checking every target of --targets at --fov instead: plan again to fix it"
    try:
        data: Any = json.loads(summary_path.read_text(encoding="utf-8"))
        stops = [s for s in data["stops"] if s["sortie"] == number]
        placed = [(float(s["lat_deg"]), float(s["lon_deg"])) for s in stops]
        names = tuple(dict.fromkeys(str(n) for s in stops for n in s["sees"]))
        planned = (float(data["fov_deg"]), float(data.get("min_clearance_m", math.nan)))
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        warnings.append(f"'{summary_path}' is not a summary urpt-gcs wrote ({exc}); {fallback}")
        return None, "", None, False
    # The summary's stops are the photo waypoints: a band plan's missions also fly through
    # waypoints without a photo that follow the terrain.
    if not flies(mission, placed):
        warnings.append(
            f"'{summary_path}' does not describe {path.name} (its sortie {number} has other "
            f"stops); {fallback}"
        )
        return None, "", None, False
    if not math.isfinite(planned[1]):
        planned = (planned[0], DEFAULT_MIN_CLEARANCE_M)
    sorties = len(data.get("sorties", [])) or 1
    where = f"{SUMMARY_FILE} for {path.name}, sortie {number} of {sorties}"
    return planned, where, names, sorties == 1


def target_set(targets: Path | TargetSet) -> TargetSet:
    """The targets of a file, or the ones given."""
    return targets if isinstance(targets, TargetSet) else read_targets(targets)


def chosen_targets(
    expected: Expected,
    targets_path: Path | TargetSet,
    problems: list[str],
    every_target: bool = False,
) -> tuple[list[Target], dict[str, Unplanned]]:
    """The targets to judge, and those of them the plan was not made for.

    Parameters
    ----------
    expected
        What the mission names: its own targets, the file's by name, or none (the file's all).
    targets_path
        ``--targets``, or the targets already read.
    problems
        Receives a line for each target named that the file lacks.
    every_target
        With ``expected.whole``: judge every target of the file as well, each where the file
        puts it.

    Returns
    -------
    list of Target, dict
        The targets in the plan's order, then the file's others; by name, "extra" for a
        target the plan does not name and "moved" for one the file puts elsewhere.
    """
    given = target_set(targets_path)
    every = given.targets
    if expected.targets is None and expected.names is None:
        return list(every), {}
    by_name = {t.name: t for t in every}
    if expected.targets is not None:
        own = list(expected.targets)
    else:
        assert expected.names is not None
        missing = [n for n in expected.names if n not in by_name]
        problems.extend(
            f"target {name} of {expected.source} is not in '{given.source}': give the target "
            "file the plan was made from"
            for name in missing
        )
        own = [by_name[n] for n in expected.names if n in by_name]
    if not (every_target and expected.whole):
        return own, {}
    unplanned: dict[str, Unplanned] = {}
    chosen = []
    for target in own:
        there = by_name.get(target.name, target)
        if (
            abs(there.lat_deg - target.lat_deg) > SAME_TARGET_DEG
            or abs(there.lon_deg - target.lon_deg) > SAME_TARGET_DEG
        ):
            unplanned[target.name] = "moved"
        chosen.append(there if target.name in unplanned else target)
    named = {t.name for t in own}
    extra = [t for t in every if t.name not in named]
    unplanned.update((t.name, "extra") for t in extra)
    return chosen + extra, unplanned
