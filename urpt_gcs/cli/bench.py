"""``urpt-gcs bench``: the solver studies."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import click

from urpt_gcs.cli._root import main, terminal_progress
from urpt_gcs.cli.options import NON_NEGATIVE, POSITIVE, out_option

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "bench_cetsp_command",
    "bench_client",
    "bench_group",
    "bench_gtsplib_command",
    "bench_paper_command",
    "bench_scale_command",
    "cluster_options",
]


@main.group("bench")
def bench_group() -> None:
    """Benchmarks: the solvers on published instance sets, beside published results."""


@bench_group.command("gtsplib")
@click.argument("directory", type=click.Path(path_type=Path))
@click.option(
    "--time-limit",
    type=POSITIVE,
    default=None,
    help="Seconds per solve [default: 3x GLNS's published mean time, else 10].",
)
@click.option("--runs", type=int, default=1, show_default=True, help="Runs (seeds) per solver.")
@click.option("--only", default=None, metavar="NAME[,NAME]", help="Run only these instances.")
@out_option("Folder for results.csv.")
@click.option(
    "--solver",
    default=None,
    metavar="NAME[,NAME]",
    help="Solver(s) to compare [default: heuristic]; OR-Tools always runs as the baseline.",
)
def bench_gtsplib_command(
    directory: Path,
    time_limit: float | None,
    runs: int,
    only: str | None,
    out: Path | None,
    solver: str | None,
) -> None:
    """Solve GTSPLIB files in DIRECTORY; compare with best_known.csv and glns_default.csv."""
    from urpt_gcs.bench.gtsplib import format_table, run_gtsplib

    results_out(out)

    def names(text: str | None) -> list[str]:
        return [part.strip() for part in (text or "").split(",") if part.strip()]

    rows = run_gtsplib(
        directory,
        solvers=names(solver),
        time_limit_s=time_limit,
        runs=runs,
        only=names(only) or None,
        out_dir=out,
        progress=terminal_progress(),
    )
    click.echo(format_table(rows))


def results_out(out: Path | None) -> None:
    """Refuse an ``--out`` that ``results.csv`` cannot be written to, before the bench runs
    (a bench can take hours)."""
    if out is not None:
        from urpt_gcs.files.output import check_folder

        check_folder(out, "--out", names=["results.csv"])


def cluster_options(command: Callable[..., None]) -> Callable[..., None]:
    """``--scheduler`` and ``--workers``: run a bench's instances on a Dask cluster."""
    command = click.option(
        "--workers",
        type=click.IntRange(min=1),
        default=None,
        help="Run on a local Dask cluster of this many worker processes [default: here].",
    )(command)
    return click.option(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Run on this Dask scheduler (tcp://host:8786) [default: here].",
    )(command)


@contextlib.contextmanager
def bench_client(scheduler: str | None, workers: int | None) -> Iterator[Client | None]:
    """No client without --scheduler or --workers (run here), else the cluster's."""
    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers sizes a local cluster: not with --scheduler")
    if scheduler is None and workers is None:
        yield None
        return
    from urpt_gcs.batch.cluster import describe_client, open_client

    with open_client(scheduler, workers) as client:
        click.echo(f"running on {describe_client(client)}", err=True)
        yield client


@bench_group.command("cetsp")
@click.argument("directory", type=click.Path(path_type=Path))
@click.option(
    "--time-limit", type=POSITIVE, default=60.0, show_default=True, help="Seconds per instance."
)
@click.option("--only", default=None, metavar="NAME[,NAME]", help="Run only these instances.")
@click.option(
    "--min-discs",
    type=click.IntRange(min=0),
    default=None,
    help="Run only instances with at least this many discs.",
)
@click.option(
    "--max-discs",
    type=click.IntRange(min=0),
    default=None,
    help="Run only instances with at most this many discs.",
)
@out_option("Folder for results.csv.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the search.")
@click.option(
    "--threads",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Order searches per instance run side by side (one core each).",
)
@click.option(
    "--peer",
    default=None,
    metavar="CMD",
    help="Run this CETSP solver beside ours, one CPU each, and compare: a command with "
    "{instance} (the file) and optionally {name}, {time_s}, {seed}, that prints "
    "'TOUR x1 y1 x2 y2 ...' on stdout (see benchmarks/README.md).",
)
@click.option(
    "--peer-grace",
    type=NON_NEGATIVE,
    default=None,
    help="Seconds past the time limit before the peer is killed [default: 2 + 10 % of the "
    "time limit].",
)
@cluster_options
def bench_cetsp_command(
    directory: Path,
    time_limit: float,
    only: str | None,
    min_discs: int | None,
    max_discs: int | None,
    out: Path | None,
    seed: int,
    threads: int,
    peer: str | None,
    peer_grace: float | None,
    scheduler: str | None,
    workers: int | None,
) -> None:
    """Solve and bound the CETSP instances in DIRECTORY (laid out like bench/cetsp)."""
    from urpt_gcs.bench.cetsp import format_table, run_cetsp

    names = [part.strip() for part in (only or "").split(",") if part.strip()]
    if peer is None:
        if peer_grace is not None:
            raise click.UsageError("--peer-grace is the peer's: give it with --peer")
    else:
        if threads != 1 or scheduler is not None or workers is not None:
            raise click.UsageError(
                "--peer runs ours on one core beside the peer: not with --threads, --workers "
                "or --scheduler"
            )
        from urpt_gcs.bench.cetsp_peer import format_peer_table, run_cetsp_peer

        results_out(out)
        compared = run_cetsp_peer(
            directory,
            peer,
            time_limit_s=time_limit,
            only=names or None,
            out_dir=out,
            progress=terminal_progress(),
            seed=seed,
            min_discs=min_discs,
            max_discs=max_discs,
            grace_s=peer_grace,
        )
        click.echo(format_peer_table(compared))
        return

    results_out(out)

    with bench_client(scheduler, workers) as client:
        rows = run_cetsp(
            directory,
            time_limit_s=time_limit,
            only=names or None,
            out_dir=out,
            progress=terminal_progress(),
            seed=seed,
            client=client,
            min_discs=min_discs,
            max_discs=max_discs,
            threads=threads,
        )
    click.echo(format_table(rows))


@bench_group.command("paper")
@click.option("--quick", is_flag=True, help="A small subset of the study (what CI runs).")
@out_option("Folder for results.csv.")
@click.option(
    "--heuristic-time",
    type=POSITIVE,
    default=1.0,
    show_default=True,
    help="Seconds the heuristic gets per instance.",
)
@click.option(
    "--bound-time",
    type=POSITIVE,
    default=10.0,  # urpt_gcs.bench.paper.BOUND_S (not imported here: the CLI starts light)
    show_default=True,
    help="Seconds the certified lower bound gets per instance (it stops sooner where it "
    "can rise no further).",
)
@click.option(
    "--bound-gap",
    type=NON_NEGATIVE,
    default=0.1,  # urpt_gcs.bench.paper.BOUND_GAP, in percent
    show_default=True,
    help="Percent: the bound's stars are walked finer only while the tour is more than "
    "this above the bound.",
)
@cluster_options
def bench_paper_command(
    quick: bool,
    out: Path | None,
    heuristic_time: float,
    bound_time: float,
    bound_gap: float,
    scheduler: str | None,
    workers: int | None,
) -> None:
    """Reproduce the paper's simulation study: 540 instances on random TIN terrains."""
    from urpt_gcs.bench.paper import format_tables, run_paper

    results_out(out)

    with bench_client(scheduler, workers) as client:
        rows = run_paper(
            quick=quick,
            out_dir=out,
            heuristic_s=heuristic_time,
            progress=terminal_progress(),
            client=client,
            bound_s=bound_time,
            bound_gap=bound_gap / 100.0,
        )
    click.echo(format_tables(rows))


@bench_group.command("scale")
@click.option(
    "--targets",
    "targets",
    default="100,1000",
    show_default=True,
    metavar="N[,N]",
    help="Target counts, one synthetic site and plan each.",
)
@click.option(
    "--size",
    "size_px",
    type=int,
    default=10_000,
    show_default=True,
    help="Side of the synthetic DSM in cells (0.3 m each).",
)
@click.option("--seed", type=int, default=1, show_default=True, help="Seed of the sites.")
@out_option("Folder for results.csv.")
def bench_scale_command(targets: str, size_px: int, seed: int, out: Path | None) -> None:
    """Plan synthetic Pix4D-like sites: per-stage wall time, peak RSS, visibility/read ratio."""
    from urpt_gcs.bench.scale import format_table, run_scale

    results_out(out)

    try:
        counts = [int(part) for part in targets.split(",") if part.strip()]
    except ValueError:
        raise click.BadParameter(f"{targets!r} is not a list of numbers, e.g. 100,1000") from None
    rows = run_scale(counts, size_px=size_px, out_dir=out, seed=seed, progress=terminal_progress())
    click.echo(format_table(rows))
