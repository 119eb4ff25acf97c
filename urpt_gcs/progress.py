"""Progress on a terminal: a line per stage that starts ticking once the stage passes a second.

The planner reports each stage's start; stages that finish within a second print nothing more.
A stage that takes longer shows its elapsed time, and the solver stage a bar towards its time
limit. Nothing is printed unless the stream is a terminal.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType
from typing import TextIO

_QUIET_S = 1.0
_TICK_S = 0.2
_BAR = 24


class StageProgress:
    """Callable progress sink for :func:`urpt_gcs.planner.plan`; use as a context manager."""

    def __init__(self, stream: TextIO, time_limit_s: float | None = None) -> None:
        self._stream = stream
        self._limit = time_limit_s
        self._stage = ""
        self._started = time.monotonic()
        self._shown = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True)

    def __enter__(self) -> StageProgress:
        self._thread.start()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        self._thread.join()
        with self._lock:
            self._end_line()

    def __call__(self, stage: str) -> None:
        with self._lock:
            self._end_line()
            self._stage = stage
            self._started = time.monotonic()

    def _end_line(self) -> None:
        if self._shown:
            self._stream.write(f"\r{self._line()}\n")
            self._stream.flush()
            self._shown = False

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
