"""``urpt-gcs batch``: the sites of a jobs file, planned on a Dask cluster."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from urpt_gcs.cli._root import main
from urpt_gcs.cli.options import out_option

__all__ = ["batch_command"]


@main.command("batch")
@click.argument("jobs_file", metavar="JOBS.toml", type=click.Path(path_type=Path))
@out_option("Folder for batch.csv and one folder per job.", required=True)
@click.option(
    "--scheduler",
    default=None,
    metavar="ADDRESS",
    help="Run on this Dask scheduler (tcp://host:8786) [default: start a local cluster].",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    help="Worker processes of the local cluster [default: every core].",
)
@click.option("--quiet", is_flag=True, help="Print nothing but errors.")
def batch_command(
    jobs_file: Path, out: Path, scheduler: str | None, workers: int | None, quiet: bool
) -> None:
    """Plan every site of JOBS.toml (and its sweeps); each job's folder is what plan writes."""
    from urpt_gcs.batch.cluster import describe_client, open_client
    from urpt_gcs.batch.jobs import (
        Row,
        check_inputs,
        output_folders,
        read_jobs,
        run_batch,
        summary_table,
    )

    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers sizes the local cluster: not with --scheduler")
    started = time.perf_counter()

    def ended(count: int, total: int, row: Row) -> None:
        if quiet:
            return
        where = ", ".join(
            part
            for part in (
                "" if row.wall_s is None else f"{row.wall_s:.1f} s",
                f"on {row.worker}" if row.worker else "",
            )
            if part
        )
        if row.status == "ok":
            sorties = f"{row.sorties} sortie{'s' if row.sorties != 1 else ''}"
            what = f"ok, {row.tour_length_m:.0f} m, {sorties}"
        else:
            what = row.status
        line = f"[{count}/{total}] {row.job} {what}" + (f" ({where})" if where else "")
        click.echo(line + (f": {row.error}" if row.error else ""))

    jobs = read_jobs(jobs_file, out)
    # What can be refused here is refused before a cluster is started.
    output_folders(jobs, out, jobs_file)
    check_inputs(jobs, None, remote=scheduler is not None)
    with open_client(scheduler, workers) as client:
        if not quiet:
            click.echo(f"{len(jobs)} jobs on {describe_client(client)}")
        rows = run_batch(jobs, out, client, ended, remote=scheduler is not None)
    failed = [r for r in rows if r.status != "ok"]
    if not quiet:
        click.echo(summary_table(rows))
        click.echo(
            f"{len(rows) - len(failed)} of {len(rows)} jobs planned in "
            f"{time.perf_counter() - started:.1f} s; results in {out / 'batch.csv'}"
        )
    if failed:
        click.echo(
            f"urpt-gcs: error: {len(failed)} of {len(rows)} jobs failed "
            f"({', '.join(r.job for r in failed)}): see {out / 'batch.csv'}",
            err=True,
        )
        sys.exit(1)
