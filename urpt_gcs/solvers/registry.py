"""The solvers by name: which one ``auto`` picks, compiling its kernels ahead, solving."""

from __future__ import annotations

from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers.approx import ApproxSolver
from urpt_gcs.solvers.base import Solver, SolveSettings, Tour
from urpt_gcs.solvers.exact import ExactSolver, exact_work
from urpt_gcs.solvers.exact import warm_up as warm_exact
from urpt_gcs.solvers.heuristic import HeuristicSolver
from urpt_gcs.solvers.heuristic import warm_up as warm_heuristic
from urpt_gcs.solvers.routing import RoutingSolver

SOLVERS: dict[str, type[Solver]] = {
    "exact": ExactSolver,
    "approx": ApproxSolver,
    "heuristic": HeuristicSolver,
    "ortools": RoutingSolver,
}
SOLVER_CHOICES = ("auto", *SOLVERS)
# Heuristics in order of preference for `auto` when the exact solver would take too long.
_FALLBACKS = ("heuristic", "ortools")

__all__ = ["SOLVERS", "SOLVER_CHOICES", "choose", "prepare", "solve"]


def choose(instance: Instance, name: str = "auto") -> str:
    """The solver ``name`` stands for on ``instance``."""
    if name != "auto":
        if name not in SOLVERS:
            raise SettingsError.about(
                "{solver} {value!r} is not known: use one of {known}",
                value=name,
                known=", ".join(SOLVER_CHOICES),
            )
        return name
    if exact_work(instance).fits_budget:
        return "exact"
    return next(s for s in _FALLBACKS if s in SOLVERS)


def prepare(name: str) -> None:
    """Compile the named solver's kernels now (numba; cached on disk after the first run), so
    that its time limit is spent searching."""
    # The exact solver seeds itself with the heuristic's search; approx tours its centres
    # with the exact solver.
    if name in ("exact", "approx"):
        warm_exact()
    elif name == "heuristic":
        warm_heuristic()


def solve(instance: Instance, name: str = "auto", settings: SolveSettings | None = None) -> Tour:
    """Solve ``instance`` with the named solver; ``auto`` picks by :func:`choose`."""
    return SOLVERS[choose(instance, name)]().solve(instance, settings or SolveSettings())
