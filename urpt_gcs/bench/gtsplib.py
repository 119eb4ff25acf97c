"""GTSPLIB benchmark: each solver beside the OR-Tools baseline, best-known values and GLNS.

For every instance, each run and each solver, the instance is solved with the run number as
seed and the same time limit for every solver: the one given, else three times GLNS's
published mean time for that instance (``glns_default.csv``), else 10 s. The cost is
recomputed from the returned tour with the file's integer distances, after checking that the
tour visits every set. ``best_known.csv`` and ``glns_default.csv`` are read from the folder
of the instances when they are there.
"""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from urpt_gcs.batch.table import rows_csv
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.files.formats.gtsplib import BENCH_FLAG, read_gtsplib
from urpt_gcs.files.output import write_all
from urpt_gcs.problem.instance import Instance
from urpt_gcs.progress import Progress
from urpt_gcs.site.inputs import GTSPLIB_MAX_BYTES, read_capped
from urpt_gcs.solvers import SOLVERS, SolveSettings, solve

__all__ = ["Row", "bench_solvers", "format_table", "results_csv", "run_gtsplib", "tour_cost"]

BASELINE = "ortools"
PREFERRED = "heuristic"
GLNS_TIME_FACTOR = 3.0
DEFAULT_TIME_LIMIT_S = 10.0
# The bar: ahead of the baseline on every instance with at least this many clusters.
LARGE_CLUSTERS = 40
_GLNS_COLUMNS = ("glns_default_mean_cost", "glns_default_mean_gap_pct", "glns_default_mean_time_s")


@dataclass(frozen=True, slots=True)
class _Published:
    """What is known about an instance before running anything."""

    best_known: float | None = None
    glns_cost: float | None = None
    glns_gap_pct: float | None = None
    glns_time_s: float | None = None


@dataclass(frozen=True, slots=True)
class Row:
    """One solve of one instance by one solver."""

    instance: str
    clusters: int
    nodes: int
    solver: str
    run: int
    time_limit_s: float
    cost: float
    time_s: float
    best_known: float | None
    gap_pct: float | None
    glns_cost: float | None
    glns_gap_pct: float | None
    glns_time_s: float | None


def bench_solvers(solvers: Sequence[str]) -> list[str]:
    """The solvers to run, in order: those named, then the OR-Tools baseline.

    Parameters
    ----------
    solvers
        Solver names (``auto`` allowed); empty means ``heuristic`` if it is registered.

    Returns
    -------
    list of str
        Each name once, ``ortools`` last.

    Raises
    ------
    SettingsError
        A name is not a registered solver.
    """
    chosen = list(solvers) if solvers else ([PREFERRED] if PREFERRED in SOLVERS else [])
    for name in chosen:
        if name not in SOLVERS and name != "auto":
            raise SettingsError.about(
                "{solver} {value!r} is not known: use one of {known}",
                value=name,
                known=", ".join(["auto", *SOLVERS]),
            )
    return [*dict.fromkeys(name for name in chosen if name != BASELINE), BASELINE]


def _number(path: Path, line: int, column: str, text: str | None) -> float | None:
    if text is None or not text.strip():
        return None
    try:
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(text)
    except ValueError:
        raise SettingsError(f"'{path}', line {line}: {column} {text!r} is not a number") from None
    return value


def _read_table(path: Path, columns: tuple[str, ...]) -> dict[str, dict[str, float | None]]:
    data = read_capped(
        path, "table", BENCH_FLAG, SettingsError, GTSPLIB_MAX_BYTES, "give the published CSV"
    )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SettingsError(f"'{path}' cannot be read: {exc}") from exc
    reader = csv.DictReader(io.StringIO(text))
    absent = [c for c in ("instance", *columns) if c not in (reader.fieldnames or [])]
    if absent:
        raise SettingsError(f"'{path}', line 1: the header lacks column(s) {', '.join(absent)}")
    table: dict[str, dict[str, float | None]] = {}
    for record in reader:
        line = reader.line_num
        table[record["instance"]] = {c: _number(path, line, c, record[c]) for c in columns}
    return table


def _published(directory: Path) -> dict[str, _Published]:
    """Best-known values and GLNS's published figures, from the CSV files beside the instances."""
    best: dict[str, dict[str, float | None]] = {}
    glns: dict[str, dict[str, float | None]] = {}
    if (directory / "best_known.csv").is_file():
        best = _read_table(directory / "best_known.csv", ("best_known",))
    if (directory / "glns_default.csv").is_file():
        glns = _read_table(directory / "glns_default.csv", _GLNS_COLUMNS)
    out: dict[str, _Published] = {}
    for name in {*best, *glns}:
        known = best.get(name, {}).get("best_known")
        row = glns.get(name, {})
        cost, gap, seconds = (row.get(c) for c in _GLNS_COLUMNS)
        if gap is None and cost is not None and known:
            gap = 100.0 * (cost / known - 1.0)
        out[name] = _Published(known, cost, gap, seconds)
    return out


def _instance_paths(directory: Path, only: Sequence[str] | None) -> list[Path]:
    """The ``*.gtsp`` files to run, smallest number of clusters first."""
    if not directory.is_dir():
        raise SettingsError(f"GTSPLIB folder '{directory}' does not exist or is not a folder")
    found = {p.stem: p for p in directory.glob("*.gtsp") if p.is_file()}
    if only:
        unknown = [name for name in only if name not in found]
        if unknown:
            raise SettingsError(f"--only {', '.join(unknown)}: no such .gtsp file in '{directory}'")
        found = {name: found[name] for name in dict.fromkeys(only)}
    if not found:
        raise SettingsError(f"GTSPLIB folder '{directory}' holds no .gtsp file")

    def key(name: str) -> tuple[int, str]:
        digits = name[: len(name) - len(name.lstrip("0123456789"))]
        return (int(digits) if digits else 0, name)

    return [found[name] for name in sorted(found, key=key)]


def tour_cost(instance: Instance, order: Sequence[int], solver: str) -> float:
    """The length of a solver's tour under the instance's own distances, after checking it.

    Parameters
    ----------
    instance
        The instance solved.
    order
        The tour's viewpoints (nodes), as the solver returned them.
    solver
        The solver's name, for the message.

    Returns
    -------
    float
        The closed tour's length (an integer for GTSPLIB files).

    Raises
    ------
    PlanError
        The tour has nodes outside the instance or misses a set.
    """
    idx = np.asarray(order, dtype=np.int64)
    if idx.size == 0 or (idx < 0).any() or (idx >= instance.n_viewpoints).any():
        raise PlanError(
            f"solver {solver} returned a tour with nodes outside {instance.name}: report this"
        )
    missing = instance.uncovered(idx)
    if missing:
        raise PlanError(
            f"solver {solver} returned a tour of {instance.name} that misses sets "
            f"{[t + 1 for t in missing][:5]}: report this"
        )
    # A single node is a tour of length 0, whatever the file's diagonal says.
    return 0.0 if len(set(idx.tolist())) == 1 else instance.tour_length(idx)


def run_gtsplib(
    directory: Path,
    solvers: Sequence[str] = (),
    time_limit_s: float | None = None,
    runs: int = 1,
    only: Sequence[str] | None = None,
    out_dir: Path | None = None,
    progress: Progress | None = None,
) -> list[Row]:
    """Solve GTSPLIB instances with each solver and the OR-Tools baseline at equal time.

    Parameters
    ----------
    directory
        Folder of ``*.gtsp`` files, with ``best_known.csv`` and ``glns_default.csv`` if known.
    solvers
        Solvers to compare; empty means ``heuristic`` if registered. ``ortools`` always runs.
    time_limit_s
        Seconds per solve; None gives each instance 3x GLNS's published mean time (or 10 s).
    runs
        Runs per instance and solver; run ``k`` uses seed ``k``.
    only
        Instance names (file stems) to run; None runs every file.
    out_dir
        If given, ``results.csv`` is (re)written there after each instance.
    progress
        Called with a short message before each solve.

    Returns
    -------
    list of Row
        One row per instance, run and solver.

    Raises
    ------
    SettingsError
        A bad argument, folder, instance or CSV file.
    PlanError
        A solver returned an invalid tour or none.
    """
    if runs < 1:
        raise SettingsError(f"--runs {runs} is below 1: give at least one run")
    if time_limit_s is not None:
        SolveSettings(time_limit_s=time_limit_s)
    names = bench_solvers(solvers)
    paths = _instance_paths(directory, only)
    known = _published(directory)
    say = progress or (lambda _msg: None)
    rows: list[Row] = []
    for path in paths:
        instance = read_gtsplib(path)
        facts = known.get(path.stem, _Published())
        limit = time_limit_s
        if limit is None:
            glns = facts.glns_time_s
            limit = GLNS_TIME_FACTOR * glns if glns else DEFAULT_TIME_LIMIT_S
        for run in range(runs):
            for name in names:
                say(f"{path.stem}: {name}, run {run + 1}/{runs}, {limit:.3g} s")
                started = time.perf_counter()
                tour = solve(instance, name, SolveSettings(time_limit_s=limit, seed=run))
                elapsed = time.perf_counter() - started
                cost = tour_cost(instance, tour.order, name)
                best = facts.best_known
                rows.append(
                    Row(
                        instance=path.stem,
                        clusters=instance.n_targets,
                        nodes=instance.n_viewpoints,
                        solver=name,
                        run=run,
                        time_limit_s=limit,
                        cost=cost,
                        time_s=elapsed,
                        best_known=best,
                        gap_pct=100.0 * (cost / best - 1.0) if best else None,
                        glns_cost=facts.glns_cost,
                        glns_gap_pct=facts.glns_gap_pct,
                        glns_time_s=facts.glns_time_s,
                    )
                )
        if out_dir is not None:
            write_all(out_dir, {"results.csv": results_csv(rows)})
    return rows


def results_csv(rows: Sequence[Row]) -> str:
    """The rows as CSV text (see :func:`urpt_gcs.batch.table.rows_csv`)."""
    return rows_csv(Row, rows)


def _mean(values: Sequence[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return sum(present) / len(present) if present else None


def _cell(value: float | None, digits: int, width: int) -> str:
    return f"{'-':>{width}}" if value is None else f"{value:>{width}.{digits}f}"


def format_table(rows: Sequence[Row]) -> str:
    """The benchmark as a text table, one line per instance, and a footer.

    Parameters
    ----------
    rows
        Rows from :func:`run_gtsplib`.

    Returns
    -------
    str
        Per instance: best known, GLNS's published mean cost, gap and time, and each solver's
        mean cost, gap and time over its runs. The footer gives each solver's mean gap, also
        over the instances GLNS has figures for, and, from 40 clusters up, on how many
        instances each solver is ahead of the OR-Tools baseline.
    """
    if not rows:
        return "no instances run"
    solvers = list(dict.fromkeys(row.solver for row in rows))
    instances = list(dict.fromkeys(row.instance for row in rows))
    by: dict[tuple[str, str], list[Row]] = {}
    for row in rows:
        by.setdefault((row.instance, row.solver), []).append(row)
    block = 32
    title = f"{'':<14}{'':>5}{'':>7}{'':>11}{'':>8} |"
    title += "".join(f" {label:^{block}} |" for label in ["GLNS default (published)", *solvers])
    head = f"{'instance':<14}{'sets':>5}{'nodes':>7}{'best_known':>11}{'limit_s':>8} |"
    head += f" {'cost':>13} {'gap_%':>9} {'time_s':>8} |" * (1 + len(solvers))
    lines = [title, head, "-" * len(head)]
    means: dict[tuple[str, str], tuple[float | None, float | None]] = {}
    for name in instances:
        first = by[(name, solvers[0])][0]
        line = (
            f"{name:<14}{first.clusters:>5}{first.nodes:>7}"
            f"{_cell(first.best_known, 0, 11)}{first.time_limit_s:>8.3g} |"
            f" {_cell(first.glns_cost, 1, 13)} {_cell(first.glns_gap_pct, 4, 9)}"
            f" {_cell(first.glns_time_s, 3, 8)} |"
        )
        for solver in solvers:
            runs = by.get((name, solver), [])
            cost = _mean([r.cost for r in runs])
            gap = _mean([r.gap_pct for r in runs])
            means[(name, solver)] = (cost, gap)
            line += (
                f" {_cell(cost, 1, 13)} {_cell(gap, 4, 9)}"
                f" {_cell(_mean([r.time_s for r in runs]), 3, 8)} |"
            )
        lines.append(line)
    lines.append("")
    lines.extend(_footer(rows, instances, solvers, means))
    return "\n".join(lines)


def _footer(
    rows: Sequence[Row],
    instances: list[str],
    solvers: list[str],
    means: dict[tuple[str, str], tuple[float | None, float | None]],
) -> list[str]:
    first = {row.instance: row for row in reversed(rows)}
    gaps = {s: _mean([means[(i, s)][1] for i in instances]) for s in solvers}
    listed = ", ".join(f"{s} {g:.4f} %" for s, g in gaps.items() if g is not None) or "-"
    out = [f"mean gap to best known over {len(instances)} instance(s): {listed}"]
    with_glns = [i for i in instances if first[i].glns_gap_pct is not None]
    if with_glns:
        parts = [f"GLNS default {_mean([first[i].glns_gap_pct for i in with_glns]):.4f} %"]
        parts += [f"{s} {_mean([means[(i, s)][1] for i in with_glns]):.4f} %" for s in solvers]
        out.append(f"mean gap over the {len(with_glns)} with GLNS figures: " + ", ".join(parts))
    large = [i for i in instances if first[i].clusters >= LARGE_CLUSTERS]
    contenders = [s for s in solvers if s != BASELINE]
    if not large:
        out.append(f"no instance with >= {LARGE_CLUSTERS} clusters was run")
    elif not contenders:
        out.append(
            f">= {LARGE_CLUSTERS} clusters: only the {BASELINE} baseline ran, nothing to compare"
        )
    for solver in contenders if large else []:
        ahead, tied, behind = 0, 0, []
        for i in large:
            mine, base = means[(i, solver)][0], means[(i, BASELINE)][0]
            if mine is not None and base is not None:
                ahead, tied = ahead + (mine < base), tied + (mine == base)
                behind += [i] if mine > base else []
        out.append(
            f">= {LARGE_CLUSTERS} clusters: {solver} ahead of {BASELINE} on {ahead} of "
            f"{len(large)} (tied {tied}, behind {len(behind)}"
            + (f": {', '.join(behind)}" if behind else "")
            + f"); ahead on every one: {'yes' if ahead == len(large) else 'no'}"
        )
    return out
