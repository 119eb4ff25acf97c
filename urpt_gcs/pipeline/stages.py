"""Stages: how the stage chain announces each stage and times it."""

from __future__ import annotations

import dataclasses
import time

from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.instance import Instance
from urpt_gcs.progress import Progress
from urpt_gcs.solvers import Tour, choose, prepare, solve


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
        """Add the time since the last lap (or the start) to stage ``name``'s.

        Parameters
        ----------
        name
            The stage just finished, as the plan's ``timings_s`` names it.
        """
        now = time.perf_counter()
        self.timings_s[name] = self.timings_s.get(name, 0.0) + now - self._clock
        self._clock = now


def solve_stage(
    instance: Instance, settings: PlanSettings, stages: Stages, stop_cost_m: float = 0.0
) -> Tour:
    """The solver's tour over the viewpoints, its kernels compiled first so that its time
    limit is spent searching; with ``stop_cost_m`` (unless the settings give their own), the
    solvers that can weigh a stop's cost against the tour's length do (the heuristic, on
    the plane).

    Parameters
    ----------
    instance
        The viewpoints, what each sees and what flying between them costs.
    settings
        The plan's settings (``solver`` and ``solve``).
    stages
        Announces the compile and the solve and keeps their times.

    Returns
    -------
    Tour
        The solver's tour.
    """
    solver = choose(instance, settings.solver)
    stages.say(f"preparing the {solver} solver (compiled on first use)")
    prepare(solver)
    stages.lap("compile")
    stages.say(f"solving ({instance.n_viewpoints} viewpoints)")
    solve_settings = settings.solve
    if solve_settings.stop_cost == 0.0 and stop_cost_m > 0.0:
        solve_settings = dataclasses.replace(solve_settings, stop_cost=stop_cost_m)
    tour = solve(instance, solver, solve_settings)
    stages.lap("solve")
    return tour


__all__ = ["Stages", "solve_stage"]
