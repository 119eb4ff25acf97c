"""The root of the ``urpt-gcs`` command line and what its commands share.

A :class:`urpt_gcs.errors.UrptError` goes to stderr on one line and the exit status is 1.
Usage errors (unknown flags, a word where a number belongs) exit 2. What the library cannot
foresee is still one line, exit 1: an ``OSError`` (a name too long, a full disk) names the file
and a ``MemoryError`` the size it could not get. Ctrl-C prints ``urpt-gcs: interrupted`` and
exits 130, as a shell reports a command stopped by SIGINT.
"""

from __future__ import annotations

import errno
import sys
from collections.abc import Callable
from typing import Any, NoReturn

import click

from urpt_gcs import __version__
from urpt_gcs.errors import (
    SettingsError,
    UrptError,
    memory_error_message,
    os_error_message,
)
from urpt_gcs.flight.geofence import Geofence
from urpt_gcs.flight.mission import Mission
from urpt_gcs.pipeline.options import FLAGS

__all__ = [
    "INTERRUPTED_EXIT",
    "SITL_FLAGS",
    "RootGroup",
    "fail",
    "interrupted",
    "main",
    "terminal_progress",
    "upload_and_report",
]

INTERRUPTED_EXIT = 130  # 128 + SIGINT

# The simulated vehicle's settings (urpt_gcs.sim.VehicleSettings) as ``urpt-gcs sitl`` takes
# them; written here, not imported, so that a command does not load the simulator to fail.
SITL_FLAGS = {
    "speedup": "--speedup",
    "loss": "--loss",
    "latency_ms": "--latency",
    "drop_after": "--drop-after",
    "capacity": "--capacity",
    "boot_s": "--boot",
    "seed": "--seed",
}
# Every setting a command names in an error, by its flag (the plan's seed and the
# simulator's are both --seed).
_NAMES = {**SITL_FLAGS, **FLAGS}


def fail(exc: UrptError) -> NoReturn:
    """One line on stderr, exit 1; a setting is named by its flag."""
    text = exc.naming(_NAMES) if isinstance(exc, SettingsError) else str(exc)
    message = " ".join(text.split())
    click.echo(f"urpt-gcs: error: {message}", err=True)
    sys.exit(1)


def interrupted() -> NoReturn:
    """Ctrl-C: one line on stderr, exit 130."""
    click.echo("urpt-gcs: interrupted", err=True)
    sys.exit(INTERRUPTED_EXIT)


class RootGroup(click.Group):
    """The ``urpt-gcs`` group: turns what escapes a command into one line and an exit status."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            interrupted()
        except UrptError as exc:
            fail(exc)
        except MemoryError as exc:
            click.echo(f"urpt-gcs: error: {memory_error_message(exc)}", err=True)
            sys.exit(1)
        except OSError as exc:
            if exc.errno == errno.EPIPE:
                raise  # click quiets a closed pipe (``urpt-gcs ... | head``) itself
            click.echo(f"urpt-gcs: error: {os_error_message(exc)}", err=True)
            sys.exit(1)


def upload_and_report(
    mission: Mission,
    url: str,
    retries: int,
    timeout_s: float,
    quiet: bool,
    fence: Geofence | None = None,
) -> None:
    """Upload with a verified read-back (the mission, then its geofence if it has one); one
    line each on success, exit 1 on failure."""
    from urpt_gcs.vehicle.link import upload

    progress = terminal_progress()
    report = upload(
        mission, url, retries=retries, timeout_s=timeout_s, progress=progress, fence=fence
    )
    for warning in report.warnings:
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    if not quiet:
        tries = f"{report.attempts} attempts" if report.attempts > 1 else "1 attempt"
        click.echo(
            f"uploaded {report.items} items to {report.url} ({report.autopilot}); read back "
            f"identical in {report.elapsed_s:.2f} s ({tries})"
        )
        if report.fence is not None:
            click.echo(
                f"uploaded the geofence, {report.fence.description}: {report.fence.items} "
                f"fence items read back identical in {report.fence.elapsed_s:.2f} s"
            )


def terminal_progress() -> Callable[[str], None] | None:
    """A sink printing progress messages on stderr when it is a terminal, else None."""
    if not sys.stderr.isatty():
        return None
    return lambda msg: click.echo(f"... {msg}", err=True)


@click.group(cls=RootGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="urpt-gcs")
def main() -> None:
    """Plan, check and upload drone missions that photograph every target on real terrain."""
