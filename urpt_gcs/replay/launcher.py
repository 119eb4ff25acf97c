"""Starting a firmware's own SITL for a replay, and always stopping it again.

What ArduCopter's and PX4's launchers (:mod:`urpt_gcs.replay.ardupilot`,
:mod:`urpt_gcs.replay.px4`) share: a fresh scratch folder, the process started in a session
of its own (so Ctrl-C reaches us only, and we stop it in order), its output in a log whose
last lines go into the error when it does not come up, and on leaving the ``with`` block, on
success, error and Ctrl-C alike, the process stopped by the pid it was started with and the
scratch folder removed. How each firmware is stopped and quoted is a :class:`SitlKind`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Launch", "RunningSitl", "SitlKind", "stop", "supervised", "tail"]


@dataclass(frozen=True, slots=True)
class RunningSitl:
    """A running SITL started by this tool.

    Attributes
    ----------
    url
        MAVSDK connection string that reaches it (loopback only).
    pid
        The process id of what was started.
    instance
        Its instance number (ArduPilot's ``-I N``, PX4's ``-i N``).
    folder
        The scratch folder it runs in, removed when it stops.
    speedup
        Simulated seconds per wall second.
    second_url
        ArduPilot: a pymavlink connection string of its second MAVLink port (SERIAL1), for a
        second ground station beside MAVSDK; None for PX4.
    """

    url: str
    pid: int
    instance: int
    folder: Path
    speedup: float
    second_url: str | None = None


@dataclass(frozen=True, slots=True)
class SitlKind:
    """How one firmware's SITL is named, stopped and quoted.

    Attributes
    ----------
    name
        For the messages ("ArduCopter SITL").
    stop_timeout_s
        How long it may take to exit after SIGTERM before it is killed.
    kill_session
        Also kill what is left of the session it leads (PX4's rcS runs its ``px4-*``
        commands there).
    tail_lines
        How many of its last output lines an error quotes.
    tail_separator
        What those lines are joined with.
    count_blank
        Whether blank lines count among ``tail_lines`` (they are never quoted).
    tail_chars
        At most this many characters of the quote, its end kept; None for no limit.
    """

    name: str
    stop_timeout_s: float
    kill_session: bool
    tail_lines: int
    tail_separator: str
    count_blank: bool
    tail_chars: int | None = None


def tail(log: Path, kind: SitlKind, lines: int | None = None) -> str:
    """The last ``lines`` (default ``kind.tail_lines``) lines of output in ``log``, on one line;
    '' if the log cannot be read."""
    try:
        text = log.read_text(errors="replace")
    except OSError:
        return ""
    count = kind.tail_lines if lines is None else lines
    said = text.splitlines()
    if kind.count_blank:
        said = said[-count:]
    said = [line.strip() for line in said if line.strip()]
    quote = kind.tail_separator.join(said[-count:])
    return quote if kind.tail_chars is None else quote[-kind.tail_chars :]


def stop(process: subprocess.Popen[bytes], kind: SitlKind) -> None:
    """Stop the process we started: SIGTERM, then SIGKILL if it lingers; with
    ``kind.kill_session``, then whatever is left of its session."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(kind.stop_timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()  # SIGKILL cannot be refused
    if kind.kill_session:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)


@dataclass(slots=True)
class Launch:
    """One launch in progress: its scratch folder, the process started last and what to
    clean up after it is stopped (see :func:`supervised`)."""

    kind: SitlKind
    folder: Path
    process: subprocess.Popen[bytes] | None = None
    cleanups: list[Callable[[], None]] = field(default_factory=list)

    def start(
        self, command: Sequence[str], cwd: Path, log: Path, env: dict[str, str] | None = None
    ) -> subprocess.Popen[bytes]:
        """Start ``command`` in ``cwd``, its output into ``log``; it is the one stopped."""
        with log.open("wb") as out:
            # Its own session: Ctrl-C reaches us only, and the launch stops it in order.
            self.process = subprocess.Popen(
                list(command),
                cwd=cwd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        return self.process

    def on_stop(self, cleanup: Callable[[], None]) -> None:
        """Call ``cleanup`` once the process is stopped, before the folder is removed."""
        self.cleanups.append(cleanup)


@contextlib.contextmanager
def supervised(kind: SitlKind, prefix: str) -> Iterator[Launch]:
    """A scratch folder named ``prefix``... for a launch; on leaving, the process started last
    is stopped, the cleanups run in order and the folder is removed."""
    launch = Launch(kind, Path(tempfile.mkdtemp(prefix=prefix)))
    try:
        yield launch
    finally:
        if launch.process is not None:
            stop(launch.process, kind)
        for cleanup in launch.cleanups:
            cleanup()
        shutil.rmtree(launch.folder, ignore_errors=True)
