"""The CETSP benchmark: flat ground, where every visibility region is a disc.

A folder laid out like ``bench/cetsp`` holds ``instances/NAME.txt`` (a header line
``# NAME ... depot=X,Y|none``, then one disc per line, ``x y r``) and ``best_known.csv``
(``name, n_discs, depot, best_known_length, ..., proven_optimal, lower_bound, notes``). Each
instance goes through :func:`urpt_gcs.solvers.continuous.solve_regions` -- the same
discretise, solve, refine and bound path as a planning site -- and the results are written
to ``results.csv`` with the columns of :data:`COLUMNS`.
"""

from __future__ import annotations

import csv
import functools
import io
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from urpt_gcs.batch.cluster import map_jobs
from urpt_gcs.errors import SettingsError
from urpt_gcs.files.output import write_all
from urpt_gcs.problem.regions import RegionSet
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.continuous import solve_regions

__all__ = [
    "COLUMNS",
    "Published",
    "Row",
    "format_table",
    "instance_job",
    "instance_paths",
    "read_instance",
    "read_published",
    "results_csv",
    "run_cetsp",
    "write_results",
]

if TYPE_CHECKING:
    from distributed import Client

COLUMNS = ("instance", "n_discs", "length", "lower_bound", "best_known", "gap_pct", "time_s")
_DEPOT = re.compile(r"depot=(\S+)")


@dataclass(frozen=True, slots=True)
class Published:
    """What ``best_known.csv`` says of an instance."""

    best_known: float | None
    proven_optimal: bool


@dataclass(frozen=True, slots=True)
class Row:
    """One instance's result; ``gap_pct`` is the certified gap, length against bound."""

    instance: str
    n_discs: int
    length: float
    lower_bound: float
    best_known: float | None
    proven_optimal: bool
    gap_pct: float
    time_s: float
    discrete_length: float

    @property
    def above_best_pct(self) -> float | None:
        if self.best_known is None or self.best_known <= 0.0:
            return None
        return 100.0 * (self.length / self.best_known - 1.0)


def read_instance(path: Path) -> RegionSet:
    """The discs and depot of one instance file.

    Raises
    ------
    SettingsError
        Naming the file and line that cannot be read.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SettingsError(f"{path}: cannot be read ({exc.strerror}); check the path") from None
    lines = text.splitlines()
    if not lines or not lines[0].startswith("#"):
        raise SettingsError(f"{path}: the first line must be '# NAME ... depot=X,Y|none'")
    depot = None
    match = _DEPOT.search(lines[0])
    if match and match.group(1) != "none":
        try:
            x, y = (float(v) for v in match.group(1).split(","))
        except ValueError:
            raise SettingsError(f"{path}: depot {match.group(1)!r} is not X,Y") from None
        depot = (x, y)
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.startswith("#"):
            continue
        try:
            x, y, r = (float(v) for v in line.split()[:3])
        except ValueError:
            raise SettingsError(f"{path}:{number}: expected 'x y r', got {line!r}") from None
        rows.append((x, y, r))
    if not rows:
        raise SettingsError(f"{path}: holds no disc")
    return RegionSet(discs=np.asarray(rows, dtype=np.float64), depot_xy=depot, name=path.stem)


def read_published(directory: Path) -> dict[str, Published]:
    """``best_known.csv`` of ``directory`` by instance name (empty when there is none)."""
    path = directory / "best_known.csv"
    if not path.is_file():
        return {}
    out: dict[str, Published] = {}
    with path.open(encoding="utf-8", newline="") as f:
        for row in csv.DictReader(f):
            try:
                value: float | None = float(row.get("best_known_length") or "nan")
            except ValueError:
                value = None
            if value is not None and not math.isfinite(value):
                value = None
            proven = (row.get("proven_optimal") or "").strip() == "yes"
            out[row["name"]] = Published(value, proven)
    return out


def instance_paths(
    directory: Path,
    only: Sequence[str] | None = None,
    min_discs: int | None = None,
    max_discs: int | None = None,
) -> list[Path]:
    """The instance files of ``directory`` (``instances/*.txt``), by size then name; only
    those with ``min_discs`` to ``max_discs`` discs where those are given.

    Raises
    ------
    SettingsError
        When the folder has no instances, ``only`` names one it does not hold, or none has
        a number of discs in the range.
    """
    folder = directory / "instances"
    if not folder.is_dir():
        raise SettingsError(
            f"{directory}: no instances/ folder; give a folder laid out like bench/cetsp"
        )
    paths = {p.stem: p for p in folder.glob("*.txt")}
    if only:
        missing = [n for n in only if n not in paths]
        if missing:
            raise SettingsError(f"--only: {', '.join(missing)} not in {folder}; check the names")
        chosen = [paths[n] for n in only]
    else:
        chosen = list(paths.values())
    if not chosen:
        raise SettingsError(f"{folder}: holds no instance (*.txt)")

    def size(p: Path) -> tuple[int, str]:
        with p.open(encoding="utf-8") as f:
            return sum(1 for line in f if line.strip() and not line.startswith("#")), p.stem

    lo = 0 if min_discs is None else min_discs
    hi = math.inf if max_discs is None else max_discs
    sized = sorted((size(p), p) for p in chosen)
    kept = [p for (n, _), p in sized if lo <= n <= hi]
    if not kept:
        wanted = f"at least {lo}" if max_discs is None else f"{lo} to {max_discs}"
        raise SettingsError(
            f"--min-discs/--max-discs: no instance of {folder} has {wanted} discs (they "
            f"have {sized[0][0][0]} to {sized[-1][0][0]}); widen the range"
        )
    return kept


def instance_job(job: tuple[Path, Published], settings: SolveSettings) -> Row:
    """Solve and bound one instance file (with its published figures), as a job for
    :func:`urpt_gcs.batch.cluster.map_jobs`."""
    path, published = job
    regions = read_instance(path)
    started = time.perf_counter()
    tour = solve_regions(regions, settings)
    return Row(
        instance=path.stem,
        n_discs=regions.n,
        length=tour.length,
        lower_bound=tour.lower_bound,
        best_known=published.best_known,
        proven_optimal=published.proven_optimal,
        gap_pct=100.0 * tour.gap,
        time_s=time.perf_counter() - started,
        discrete_length=tour.discrete_length,
    )


def run_cetsp(
    directory: Path,
    time_limit_s: float = 60.0,
    only: Sequence[str] | None = None,
    out_dir: Path | None = None,
    progress: Callable[[str], None] | None = None,
    seed: int = 0,
    client: Client | None = None,
    min_discs: int | None = None,
    max_discs: int | None = None,
    threads: int = 1,
) -> list[Row]:
    """Solve and bound every instance of ``directory`` (those named in ``only``, with
    ``min_discs`` to ``max_discs`` discs); write ``results.csv`` to ``out_dir``. Each
    instance's order search runs ``threads`` searches side by side.

    With a Dask ``client`` (:func:`urpt_gcs.batch.cluster.open_client`) every instance is a task;
    the rows are the ones a serial run gives (the seed is fixed) but for the times, as far as
    the time limit lets each search go equally far.
    """
    settings = SolveSettings(time_limit_s=time_limit_s, seed=seed, threads=threads)
    published = read_published(directory)
    say = progress or (lambda _msg: None)
    paths = instance_paths(directory, only, min_discs, max_discs)
    jobs = [(path, published.get(path.stem, Published(None, False))) for path in paths]
    rows: list[Row] = []

    def done(_index: int, row: Row) -> None:
        rows.append(row)
        say(f"[{len(rows)}/{len(jobs)}] {row.instance}: {row.n_discs} discs, {row.length:.4f}")
        if out_dir is not None and client is None:
            write_results(rows, out_dir)

    ordered = map_jobs(functools.partial(instance_job, settings=settings), jobs, client, done)
    if out_dir is not None:
        write_results(ordered, out_dir)
    return ordered


def results_csv(rows: Sequence[Row]) -> str:
    """``results.csv``: one line per instance, the columns of :data:`COLUMNS`."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        best = "" if r.best_known is None else f"{r.best_known:.6f}"
        w.writerow(
            [
                r.instance,
                r.n_discs,
                f"{r.length:.6f}",
                f"{r.lower_bound:.6f}",
                best,
                f"{r.gap_pct:.4f}",
                f"{r.time_s:.2f}",
            ]
        )
    return buf.getvalue()


def write_results(rows: Sequence[Row], out_dir: Path) -> Path:
    """Write ``results.csv`` into ``out_dir``, whole or not at all."""
    return write_all(out_dir, {"results.csv": results_csv(rows)})[0]


def format_table(rows: Sequence[Row]) -> str:
    """A table: length, certified bound and gap, and the distance to the best known."""
    head = (
        f"{'instance':<28} {'discs':>5} {'length':>12} {'bound':>12} {'gap %':>8} "
        f"{'best known':>12} {'above %':>8} {'refined %':>9} {'time s':>7}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        above = r.above_best_pct
        best = "-" if r.best_known is None else f"{r.best_known:.3f}"
        gain = 100.0 * (1.0 - r.length / r.discrete_length) if r.discrete_length > 0 else 0.0
        lines.append(
            f"{r.instance:<28} {r.n_discs:>5} {r.length:>12.3f} {r.lower_bound:>12.3f} "
            f"{r.gap_pct:>8.2f} {best:>12} {'-' if above is None else f'{above:.3f}':>8} "
            f"{gain:>9.3f} {r.time_s:>7.1f}"
        )
    known = [r.above_best_pct for r in rows if r.above_best_pct is not None]
    if known:
        lines.append(
            f"mean above best known {sum(known) / len(known):.3f} % over {len(known)}; "
            f"worst {max(known):.3f} %; median certified gap "
            f"{float(np.median([r.gap_pct for r in rows])):.2f} %"
        )
    return "\n".join(lines)
