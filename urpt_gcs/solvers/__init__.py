"""Solvers for the viewpoint GTSP, all behind one interface: ``Instance -> Tour``.

- ``exact``: dynamic programming over covered-target subsets; proves optimality.
- ``approx``: the paper's constant-factor algorithm, every photo point checked.
- ``ortools``: OR-Tools routing with guided local search (a baseline).
- ``auto``: ``exact`` when its estimated work fits the budget, else the best heuristic.
"""

from __future__ import annotations

from urpt_gcs.solvers.base import Solver, SolveSettings, Tour
from urpt_gcs.solvers.registry import SOLVER_CHOICES, SOLVERS, choose, prepare, solve

__all__ = [
    "SOLVERS",
    "SOLVER_CHOICES",
    "SolveSettings",
    "Solver",
    "Tour",
    "choose",
    "prepare",
    "solve",
]
