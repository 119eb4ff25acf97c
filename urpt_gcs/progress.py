"""Progress of a plan, stage by stage.

The planner reports each stage's start; a stage ends when the next one starts or the display
closes. On a terminal, a stage that passes a second gets a line that ticks: its elapsed time,
and for the solver stage a bar towards its time limit. A background thread redraws it, so it
keeps moving while compiled code (numba kernels, OR-Tools) runs on the main thread. Anywhere
else (a log file, a pipe) each stage prints one line as it ends, with its time:
``... visibility of 16 targets: 0.05 s`` (the CLI writes those on stdout, before the summary,
so that stderr holds only errors and warnings); a stage that fails prints nothing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import TextIO

# The one progress channel every stage reports through: called with a line saying what starts
# (a stage's name, a transfer's step); a :class:`StageProgress` is one.
Progress = Callable[[str], None]

_QUIET_S = 1.0
_TICK_S = 0.2
_BAR = 24


class StageProgress:
    """Callable progress sink for :func:`urpt_gcs.pipeline.planner.plan`; use as a context manager.

    Parameters
    ----------
    stream
        Where to write (the CLI passes stderr).
    time_limit_s
        The solver's time limit, for the solver stage's bar.
    live
        Redraw a ticking line (a terminal) rather than print a line per stage; by default,
        whether ``stream`` is a terminal.
    """

    def __init__(
        self, stream: TextIO, time_limit_s: float | None = None, live: bool | None = None
    ) -> None:
        self._stream = stream
        self._limit = time_limit_s
        self._live = stream.isatty() if live is None else live
        self._stage = ""
        self._started = time.monotonic()
        self._shown = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True)

    def __enter__(self) -> StageProgress:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        with self._lock:
            self._end_stage(failed=kind is not None)

    def __call__(self, stage: str) -> None:
        with self._lock:
            self._end_stage(failed=False)
            self._stage = stage
            self._started = time.monotonic()
        # Ticking starts with the first stage: a display never told of one stays silent.
        if self._live and not (self._thread.is_alive() or self._stop.is_set()):
            self._thread.start()

    def _end_stage(self, failed: bool) -> None:
        if not self._stage:
            return
        if self._shown:
            self._stream.write(f"\r{self._line()}\n")
            self._shown = False
        elif not (self._live or failed):
            self._stream.write(f"... {self._stage}: {time.monotonic() - self._started:.2f} s\n")
        self._stream.flush()
        self._stage = ""

    def _line(self) -> str:
        elapsed = time.monotonic() - self._started
        text = f"... {self._stage} {elapsed:5.1f} s"
        if self._limit and self._stage.startswith("solving"):
            done = min(elapsed / self._limit, 1.0)
            filled = int(done * _BAR)
            text += f" [{'#' * filled}{'.' * (_BAR - filled)}] of {self._limit:g} s"
        return text

    def _tick(self) -> None:
        while not self._stop.wait(_TICK_S):
            with self._lock:
                if self._stage and time.monotonic() - self._started >= _QUIET_S:
                    self._stream.write(f"\r{self._line()}")
                    self._stream.flush()
                    self._shown = True


__all__ = ["Progress", "StageProgress"]
