"""Many plans at once: the sites of a jobs file, and their sweeps, one plan each.

A jobs file is TOML::

    [plan]                       # optional: settings every site starts from
    time-limit = 5
    no-map = true

    [cameras.wide]               # optional: named cameras, for a camera sweep: a cone
    fov = 40                     # (fov), or a frame camera as `plan` takes it (camera =
    [cameras.p4]                 # a preset, or sensor/focal/image), with headings and gsd
    camera = "phantom4rtk"
    gsd = 2.0

    [[site]]
    name = "quarry"              # the job's folder under --out
    dem = "quarry/dsm.tif"       # paths relative to the jobs file
    targets = "quarry/targets.kml"
    fov = 35                     # any `urpt-gcs plan` option, named as its flag
    [site.sweep]                 # optional: one plan per combination of values
    altitude = [80, 100]         # quarry-alt80-wide, quarry-alt80-p4, quarry-alt100-wide...
    camera = ["wide", "p4"]      # (or fov = [25, 30]: quarry-alt80-fov25, ...)

Each job is planned where it runs (:func:`run_job`: the DEM window is read there) and its
files are rendered there; this process commits each job's folder ``OUT/NAME`` all or none,
exactly as ``urpt-gcs plan --out OUT/NAME`` writes it, and writes ``OUT/batch.csv``, one row
per job. A job that fails is a row with its one-line error; the others go on.
"""

from __future__ import annotations

import difflib
import itertools
import math
import os
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from urpt_gcs.batch.cluster import Done, probe_workers, run_jobs
from urpt_gcs.batch.table import rows_csv
from urpt_gcs.errors import (
    ClusterError,
    JobsFileError,
    SettingsError,
    UrptError,
    memory_error_message,
    os_error_message,
)
from urpt_gcs.files.output import check_folder, commit, refuse_inputs
from urpt_gcs.pipeline.options import KINDS, PLAN_OPTIONS, TOML_KEYS
from urpt_gcs.pipeline.settings import PlanSettings, plan_settings
from urpt_gcs.site.inputs import read_settings_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "CAMERA_KEYS",
    "JOB_THREADS",
    "PLAN_KEYS",
    "RESULTS_FILE",
    "SITE_KEYS",
    "SWEEP_KEYS",
    "Job",
    "JobDone",
    "JobOutput",
    "Row",
    "check_inputs",
    "error_line",
    "output_folders",
    "read_jobs",
    "results_csv",
    "run_batch",
    "run_job",
    "summary_table",
    "write_results",
]

RESULTS_FILE = "batch.csv"
# Threads a job's line-of-sight tests use unless its site says otherwise: a worker is one
# process of one thread, and its neighbours have the other cores.
JOB_THREADS = 1

# The `urpt-gcs plan` options a site may set (every setting of the table a jobs file takes),
# and what each takes.
PLAN_KEYS: dict[str, str] = {o.key: KINDS[o.kind] for o in PLAN_OPTIONS if o.in_jobs}
_TEXT, _NUMBER = KINDS["text"], KINDS["number"]
CAMERA_KEYS = {
    key: PLAN_KEYS[key] for key in ("fov", "camera", "sensor", "focal", "image", "headings", "gsd")
}
SITE_KEYS = {"name", "dem", "targets", "sweep"}
SWEEP_KEYS = ("altitude", "camera", "fov")  # in the order their labels join a job's name
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


@dataclass(frozen=True, slots=True)
class Job:
    """One plan of a batch.

    Attributes
    ----------
    name
        The job's folder under the batch's output folder: the site's name, with its sweep
        values appended (``quarry-alt80``).
    site
        The site's name.
    dem, targets
        Absolute paths, as the workers must see them.
    settings
        The plan's settings.
    with_map
        Draw ``map.png`` and ``map.html``.
    sweep
        The swept settings of this job (``altitude``, ``camera``, ``fov``), for the results.
    out
        The job's output folder, as this process writes it (the summary lists its files).
    """

    name: str
    site: str
    dem: str
    targets: str
    settings: PlanSettings
    with_map: bool = True
    sweep: Mapping[str, str] = field(default_factory=dict)
    out: str = ""


@dataclass(frozen=True, slots=True)
class JobOutput:
    """What a job sends back: its summary and its files, to be committed by the caller."""

    summary: dict[str, Any]
    files: dict[str, str | bytes]


@dataclass(frozen=True, slots=True)
class Row:
    """One job's line of ``batch.csv``."""

    job: str
    site: str
    status: str
    altitude_m: float | None
    fov_deg: float | None
    camera: str
    samples: int
    solver: str
    targets: int | None
    tour_length_m: float | None
    flight_time_s: float | None
    sorties: int | None
    lower_bound_m: float | None
    gap_pct: float | None
    proven_optimal: bool | None
    wall_s: float | None
    worker: str
    error: str
    out: str


# -- the jobs file ---------------------------------------------------------------------------


def read_jobs(path: Path, out_dir: Path) -> list[Job]:
    """The jobs of a jobs file, sweeps expanded, each with its folder under ``out_dir``.

    Raises
    ------
    JobsFileError
        One line naming the file, the table and the key at fault, and the fix.
    """
    text = read_settings_text(path, "jobs file", "urpt-gcs batch", JobsFileError)
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise JobsFileError(f"{path}: not valid TOML ({exc}): fix the syntax") from None
    _known(path, "the file", document, {"plan", "cameras", "site"})
    defaults = _table(path, "[plan]", document.get("plan", {}))
    _options(path, "[plan]", defaults)
    cameras = _cameras(path, _table(path, "[cameras]", document.get("cameras", {})))
    sites = document.get("site")
    if not isinstance(sites, list) or not sites:
        raise JobsFileError(
            f"{path}: no [[site]] table: add one per site, with name, dem and targets"
        )
    jobs: list[Job] = []
    for number, raw in enumerate(sites, start=1):
        site = _table(path, f"[[site]] {number}", raw)
        jobs.extend(_site_jobs(path, number, site, defaults, cameras, out_dir))
    seen: dict[str, str] = {}
    for job in jobs:
        if job.name in seen:
            raise JobsFileError(
                f"{path}: two jobs are named '{job.name}' ({seen[job.name]} and [[site]] "
                f"'{job.site}'): give the sites different names"
            )
        seen[job.name] = f"[[site]] '{job.site}'"
    return jobs


def _table(path: Path, where: str, value: object) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise JobsFileError(f"{path}: {where} is not a table: write it as {where} key = value")
    return value


def _known(
    path: Path, where: str, table: Mapping[str, Any], keys: set[str] | dict[str, Any]
) -> None:
    for key in table:
        if key not in keys:
            close = difflib.get_close_matches(key, list(keys), n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"use one of {', '.join(keys)}"
            raise JobsFileError(f"{path}: {where}: unknown key '{key}': {hint}")


def _check_value(path: Path, where: str, key: str, kind: str, value: object) -> None:
    ok = {
        KINDS["number"]: isinstance(value, (int, float)) and not isinstance(value, bool),
        KINDS["integer"]: isinstance(value, int) and not isinstance(value, bool),
        KINDS["flag"]: isinstance(value, bool),
        KINDS["text"]: isinstance(value, str),
    }[kind]
    if not ok:
        raise JobsFileError(f"{path}: {where}, key '{key}': {value!r} is not {kind}: give {kind}")


def _options(path: Path, where: str, table: Mapping[str, Any]) -> None:
    _known(path, where, table, PLAN_KEYS)
    for key, value in table.items():
        _check_value(path, where, key, PLAN_KEYS[key], value)


def _cameras(path: Path, table: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    cameras = {}
    for name, raw in table.items():
        where = f"[cameras.{name}]"
        camera = _table(path, where, raw)
        _known(path, where, camera, CAMERA_KEYS)
        for key, value in camera.items():
            _check_value(path, where, key, CAMERA_KEYS[key], value)
        if not _NAME.fullmatch(name):
            raise JobsFileError(
                f"{path}: {where}: a camera's name goes into folder names: use letters, "
                "digits, '.', '_' and '-'"
            )
        cameras[name] = camera
    return cameras


def _site_jobs(
    path: Path,
    number: int,
    site: dict[str, Any],
    defaults: Mapping[str, Any],
    cameras: Mapping[str, Mapping[str, Any]],
    out_dir: Path,
) -> list[Job]:
    where = f"[[site]] {number}"
    for key in ("name", "dem", "targets"):
        if key not in site:
            raise JobsFileError(f"{path}: {where} has no '{key}': add {key} = \"...\"")
        _check_value(path, where, key, _TEXT, site[key])
    name = site["name"]
    if not _NAME.fullmatch(name) or len(name) > 100:
        raise JobsFileError(
            f"{path}: {where}, key 'name': {name!r} is the job's folder name: use up to 100 "
            "letters, digits, '.', '_' and '-', starting with a letter or digit"
        )
    where = f"[[site]] '{name}'"
    _known(path, where, site, SITE_KEYS | set(PLAN_KEYS))
    options = {k: v for k, v in site.items() if k in PLAN_KEYS}
    _options(path, where, options)
    in_sweep = f"[site.sweep] of '{name}'"
    sweep = _table(path, in_sweep, site.get("sweep", {}))
    _known(path, in_sweep, sweep, set(SWEEP_KEYS))
    if "camera" in sweep and "fov" in sweep:
        raise JobsFileError(
            f"{path}: {in_sweep}: a camera sets the fov, so sweep camera or fov, not both"
        )
    axes: list[list[tuple[str, Any]]] = []
    for key in SWEEP_KEYS:
        if key not in sweep:
            continue
        values = sweep[key]
        if not isinstance(values, list) or not values:
            raise JobsFileError(
                f"{path}: {in_sweep}, key '{key}': give a list of values, "
                f"e.g. {key} = {_example(key)}"
            )
        for value in values:
            _check_value(path, in_sweep, key, _TEXT if key == "camera" else _NUMBER, value)
            if key == "camera" and value not in cameras:
                known = ", ".join(cameras) or "none"
                raise JobsFileError(
                    f"{path}: {in_sweep}, key 'camera': no [cameras.{value}] table (known: "
                    f"{known}): add one with its fov"
                )
        if len({_label(v) for v in values}) < len(values):
            raise JobsFileError(f"{path}: {in_sweep}, key '{key}': a value is given twice")
        axes.append([(key, value) for value in values])
    base = path.parent
    dem, targets = (str((base / site[key]).absolute()) for key in ("dem", "targets"))
    jobs = []
    for combination in itertools.product(*axes):
        chosen: dict[str, Any] = {**defaults, **options}
        labels: dict[str, str] = {}
        suffix = ""
        for key, value in combination:
            labels[key] = _label(value)
            if key == "camera":
                # A named camera replaces whatever camera the site or [plan] described.
                chosen = {k: v for k, v in chosen.items() if k not in CAMERA_KEYS}
                chosen.update(cameras[value])
                suffix += f"-{value}"
            else:
                chosen[key] = value
                suffix += f"-{'alt' if key == 'altitude' else key}{_label(value)}"
        job_name = name + suffix
        if job_name == RESULTS_FILE:
            raise JobsFileError(
                f"{path}: {where}: a job named {RESULTS_FILE} would take the results' name: "
                "rename the site"
            )
        try:
            settings = plan_settings({"workers": JOB_THREADS, **chosen})
        except SettingsError as exc:
            raise JobsFileError(
                f"{path}: {where} (job {job_name}): {exc.naming(TOML_KEYS)}"
            ) from None
        jobs.append(
            Job(
                name=job_name,
                site=name,
                dem=dem,
                targets=targets,
                settings=settings,
                with_map=not chosen.get("no-map", False),
                sweep=labels,
                out=str(out_dir / job_name),
            )
        )
    return jobs


def _example(key: str) -> str:
    return {"altitude": "[80, 100, 120]", "camera": '["wide", "narrow"]'}.get(key, "[25, 30]")


def _label(value: object) -> str:
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


# -- running ---------------------------------------------------------------------------------


def run_job(job: Job) -> JobOutput:
    """Plan one job and render its files in memory, where it runs (a worker, or here).

    Raises
    ------
    UrptError
        The job's plan failed; the message is its one line.
    """
    # Runs on a worker process: the planner loads there, on its first job.
    from urpt_gcs.files.products import render_products
    from urpt_gcs.pipeline.planner import plan

    result = plan(Path(job.dem), Path(job.targets), job.settings)
    data, files = render_products(result, Path(job.out), with_map=job.with_map)
    return JobOutput(summary=data, files=files)


def check_inputs(jobs: Sequence[Job], client: Client | None, remote: bool) -> None:
    """Refuse, before any job is sent, a DEM or target file a worker cannot read.

    Raises
    ------
    ClusterError
        Naming the job, the file and the worker that cannot read it.
    """
    paths = sorted({p for job in jobs for p in (job.dem, job.targets)})
    where = {p: job for job in reversed(jobs) for p in (job.dem, job.targets)}
    if not remote:
        for p in paths:
            if not os.path.isfile(p):
                raise ClusterError(_missing(where[p], p, "this computer", "check the path"))
    if client is None:
        return
    for worker, missing in sorted(probe_workers(client, paths).items()):
        if missing:
            fix = (
                "put it where every worker reads it under the same path (a shared mount), "
                "or run without --scheduler"
                if remote
                else "check the path and its permissions"
            )
            raise ClusterError(_missing(where[missing[0]], missing[0], f"worker {worker}", fix))


def _missing(job: Job, path: str, who: str, fix: str) -> str:
    key = "dem" if path == job.dem else "targets"
    return f"[[site]] '{job.site}', {key} '{path}': {who} cannot read it: {fix}"


def output_folders(jobs: Sequence[Job], out_dir: Path, jobs_file: Path | None = None) -> None:
    """Refuse, before any job runs, an output folder the batch cannot write, or one that
    would replace an input (``jobs_file``, or a site's DEM or targets).

    Raises
    ------
    OutputError
        Naming the folder and the fix.
    """
    # The products module loads the planner; the jobs file is read and checked without it.
    from urpt_gcs.files.products import check_out

    destinations = [check_folder(out_dir, "--out", names=[RESULTS_FILE])]
    destinations += [check_out(Path(job.out)) for job in jobs]
    # No job may write over any job's inputs, nor the results over them.
    inputs: dict[str, str | Path] = {}
    if jobs_file is not None:
        inputs["the jobs file"] = jobs_file
    for job in jobs:
        inputs[f"[[site]] '{job.site}', dem"] = job.dem
        inputs[f"[[site]] '{job.site}', targets"] = job.targets
    refuse_inputs(destinations, inputs)


# Called as each job ends: (jobs done, jobs in all, its row).
JobDone = Callable[[int, int, "Row"], None]


def run_batch(
    jobs: Sequence[Job],
    out_dir: Path,
    client: Client | None = None,
    progress: JobDone | None = None,
    remote: bool = False,
) -> list[Row]:
    """Run every job (here, or on ``client``), commit each one's folder, write batch.csv.

    Parameters
    ----------
    jobs
        From :func:`read_jobs`.
    out_dir
        The batch's folder: ``batch.csv`` and one folder per job.
    client
        A Dask client (:func:`urpt_gcs.batch.cluster.open_client`), or None to plan here.
    progress
        Called as each job ends: (jobs ended, jobs, its row).
    remote
        The workers are not this computer's (``--scheduler``): the inputs are checked
        only on them.

    Returns
    -------
    list of Row
        One per job, in the jobs file's order. Ctrl-C writes the rows so far (the others
        ``interrupted``) and is raised again.

    Raises
    ------
    ClusterError, OutputError
        Before any job runs: an input a worker cannot read, an output that cannot be written.
    """
    # The products module loads the planner; the jobs file is read and checked without it.
    from urpt_gcs.files.products import check_out

    output_folders(jobs, out_dir)
    check_inputs(jobs, client, remote)
    rows: list[Row | None] = [None] * len(jobs)
    ended = 0

    def finish(end: Done[JobOutput]) -> None:
        nonlocal ended
        job = jobs[end.index]
        error = end.error
        if end.value is not None:
            try:
                commit([(check_out(Path(job.out)), end.value.files)])
            except UrptError as exc:
                error = exc
        row = rows[end.index] = _row(job, end, error)
        ended += 1
        if progress is not None:
            progress(ended, len(jobs), row)

    try:
        run_jobs(run_job, jobs, client, finish)
    finally:
        done = [
            row if row is not None else _row(job, None, None, "interrupted")
            for job, row in zip(jobs, rows, strict=True)
        ]
        write_results(done, out_dir)
    return done


def error_line(exc: BaseException) -> str:
    """A job's error on one line: the message of our errors, the kind of any other."""
    if isinstance(exc, SettingsError):
        text = exc.naming(TOML_KEYS)
    elif isinstance(exc, UrptError):
        text = str(exc)
    elif isinstance(exc, MemoryError):
        text = memory_error_message(exc)
    elif isinstance(exc, OSError):
        text = os_error_message(exc)
    else:
        text = f"internal error, please report it: {type(exc).__name__}: {exc}"
    return " ".join(text.split())


def _row(
    job: Job, end: Done[JobOutput] | None, error: BaseException | None, status: str = ""
) -> Row:
    data = end.value.summary if end is not None and end.value is not None else {}
    ok = end is not None and error is None
    return Row(
        job=job.name,
        site=job.site,
        status=status or ("ok" if ok else "failed"),
        altitude_m=data.get("altitude_amsl_m", job.settings.altitude_m),
        fov_deg=None if job.settings.frame is not None else job.settings.fov_deg,
        camera=job.sweep.get("camera", ""),
        samples=job.settings.samples,
        solver=data.get("solver", job.settings.solver),
        targets=data.get("targets"),
        tour_length_m=data.get("tour_length_m"),
        flight_time_s=data.get("flight_time_s"),
        sorties=len(data["sorties"]) if "sorties" in data else None,
        lower_bound_m=data.get("lower_bound_m"),
        gap_pct=data.get("gap_pct"),
        proven_optimal=data.get("proven_optimal"),
        wall_s=None if end is None or end.wall_s is None else round(end.wall_s, 3),
        worker="" if end is None else end.worker,
        error="" if error is None else error_line(error),
        out=job.out,
    )


def results_csv(rows: Sequence[Row]) -> str:
    """``batch.csv``: a header of the fields, absent values left empty."""
    return rows_csv(Row, rows)


def write_results(rows: Sequence[Row], out_dir: Path) -> None:
    """Write ``batch.csv``, all or nothing."""
    commit(
        [(check_folder(out_dir, "--out", names=[RESULTS_FILE]), {RESULTS_FILE: results_csv(rows)})]
    )


def summary_table(rows: Sequence[Row]) -> str:
    """The batch on one screen: a line per job."""
    width = max([len(r.job) for r in rows] + [3])
    lines = [
        f"{'job':<{width}}  status  targets  tour m    flight     sorties  gap %   wall s  worker"
    ]
    for r in rows:
        lines.append(
            f"{r.job:<{width}}  {r.status:<6}  {_cell(r.targets):>7}"
            f"  {_cell(r.tour_length_m, 1):>8}"
            f"  {_minutes(r.flight_time_s):>9}  {_cell(r.sorties):>7}  {_cell(r.gap_pct, 1):>5}"
            f"  {_cell(r.wall_s, 1):>6}  {r.worker}"
        )
        if r.error:
            lines.append(f"{'':<{width}}  {r.error}")
    return "\n".join(lines)


def _cell(value: float | int | None, digits: int = 0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}" if digits else str(value)


def _minutes(seconds: float | None) -> str:
    if seconds is None:
        return "-"
    total = round(seconds)
    return f"{total // 60} min {total % 60:02d} s"
