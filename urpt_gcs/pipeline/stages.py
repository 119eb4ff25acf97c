"""Stages: how the stage chain announces each stage and times it."""

from __future__ import annotations

import time

from urpt_gcs.progress import Progress


class Stages:
    """Announces each stage and keeps how long it took.

    Parameters
    ----------
    progress
        Called with a short message as each stage starts (None: stages run silently).

    Attributes
    ----------
    say
        Announces the stage about to start.
    timings_s
        Seconds each finished stage took, by the name given to :meth:`lap`.
    """

    def __init__(self, progress: Progress | None) -> None:
        self.say = progress or (lambda _msg: None)
        self.timings_s: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, name: str) -> None:
        """Record the time since the last lap (or the start) as stage ``name``'s.

        Parameters
        ----------
        name
            The stage just finished, as the plan's ``timings_s`` names it.
        """
        now = time.perf_counter()
        self.timings_s[name] = now - self._clock
        self._clock = now


__all__ = ["Stages"]
