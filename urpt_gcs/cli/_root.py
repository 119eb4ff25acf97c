"""The root of the ``urpt-gcs`` command line and what its commands share.

Only :class:`urpt_gcs.errors.UrptError` is caught: its message goes to stderr on one line and
the exit status is 1. Usage errors (unknown flags, a word where a number belongs) exit 2.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import click

from urpt_gcs import __version__
from urpt_gcs.errors import SettingsError, UrptError
from urpt_gcs.mission import Mission


def fail(exc: UrptError) -> None:
    message = " ".join(str(exc).split())
    click.echo(f"urpt-gcs: error: {message}", err=True)
    sys.exit(1)


def upload_and_report(
    mission: Mission, url: str, retries: int, timeout_s: float, quiet: bool
) -> None:
    """Upload with a verified read-back; one line on success, exit 1 on failure."""
    from urpt_gcs.link import upload

    progress = terminal_progress()
    try:
        report = upload(mission, url, retries=retries, timeout_s=timeout_s, progress=progress)
    except UrptError as exc:
        fail(exc)
        return
    for warning in report.warnings:
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    if not quiet:
        tries = f"{report.attempts} attempts" if report.attempts > 1 else "1 attempt"
        click.echo(
            f"uploaded {report.items} items to {report.url} ({report.autopilot}); read back "
            f"identical in {report.elapsed_s:.2f} s ({tries})"
        )


def terminal_progress() -> Callable[[str], None] | None:
    """A sink printing progress messages on stderr when it is a terminal, else None."""
    if not sys.stderr.isatty():
        return None
    return lambda msg: click.echo(f"... {msg}", err=True)


def parse_home(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        lat, lon = (float(p) for p in parts)
    except ValueError:
        raise SettingsError(
            f"--home {text!r} is not LAT,LON: give it as e.g. --home 47.3977,8.5456"
        ) from None
    return lat, lon


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="urpt-gcs")
def main() -> None:
    """Plan, check and upload drone missions that photograph every target on real terrain."""
