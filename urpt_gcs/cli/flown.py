"""``urpt-gcs flown``: what a real flight photographed, judged from its log."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path

import click

from urpt_gcs.cli._root import main
from urpt_gcs.cli.options import F

__all__ = ["flown_command", "log_option"]


def log_option(help_text: str) -> Callable[[F], F]:
    """``--log FLIGHT``, given once per flight."""
    return click.option(
        "--log",
        "logs",
        multiple=True,
        type=click.Path(dir_okay=False, path_type=Path),
        help=help_text,
    )


@main.command("flown")
@click.argument("plan_dir", metavar="OUT", type=click.Path(path_type=Path))
@log_option(
    "A log of a flight of the plan: a .tlog (QGroundControl, MAVProxy) or an ArduPilot "
    "DataFlash .bin; once per sortie flown."
)
@click.option(
    "--dem",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="The DSM; default: the one the plan's summary names.",
)
@click.option(
    "--targets",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="The target file; default: the targets where the plan put them.",
)
@click.option(
    "--report",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Where to write the report (JSON); default: OUT/flown.json.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
def flown_command(
    plan_dir: Path,
    logs: Sequence[Path],
    dem: Path | None,
    targets: Path | None,
    report: Path | None,
    as_json: bool,
) -> None:
    """Judge every target of the plan in OUT from the photos a flight's log holds: seen (by
    which photo) or missed."""
    from urpt_gcs.files.output import check_file, commit, refuse_inputs
    from urpt_gcs.replay.flown import FLOWN_FILE, flown_json, flown_text, judge_flown

    path = report if report is not None else plan_dir / FLOWN_FILE
    destination = check_file(path, "--report")
    inputs: dict[str, Path | str] = {f"--log {log}": log for log in logs}
    if dem is not None:
        inputs["--dem"] = dem
    if targets is not None:
        inputs["--targets"] = targets
    refuse_inputs([destination], inputs)
    verdict = judge_flown(plan_dir, logs, dem, targets)
    data = flown_json(verdict)
    commit([(destination, {path.name: json.dumps(data, indent=2) + "\n"})])
    click.echo(json.dumps(data, indent=2) if as_json else flown_text(verdict))
