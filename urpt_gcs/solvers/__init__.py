"""Solvers for the viewpoint GTSP, all behind one interface: ``Instance -> Tour``."""

from __future__ import annotations

from urpt_gcs.errors import SettingsError
from urpt_gcs.gtsp import Instance
from urpt_gcs.solvers.base import Solver, SolveSettings, Tour
from urpt_gcs.solvers.routing import RoutingSolver

SOLVERS: dict[str, type[Solver]] = {"ortools": RoutingSolver}
SOLVER_CHOICES = ("auto", *SOLVERS)

__all__ = ["SOLVERS", "SOLVER_CHOICES", "SolveSettings", "Solver", "Tour", "solve"]


def solve(instance: Instance, name: str = "auto", settings: SolveSettings | None = None) -> Tour:
    """Solve ``instance`` with the named solver; ``auto`` picks the best available."""
    settings = settings or SolveSettings()
    if name == "auto":
        name = "ortools"
    if name not in SOLVERS:
        raise SettingsError(
            f"--solver {name!r} is not known: use one of {', '.join(SOLVER_CHOICES)}"
        )
    return SOLVERS[name]().solve(instance, settings)
