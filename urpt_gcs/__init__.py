"""urpt-gcs: terrain-aware mission planning for visual monitoring with a nadir camera.

``plan(dem, targets, settings)`` runs the whole pipeline and returns a :class:`Plan`; the
stages are modules of their own (terrain, targets, visibility, gtsp, solvers, mission,
formats) for anyone who wants to call them one by one.
"""

from __future__ import annotations

__version__ = "0.1.0"

from urpt_gcs.errors import UrptError
from urpt_gcs.planner import Plan, PlanSettings, plan

__all__ = ["Plan", "PlanSettings", "UrptError", "__version__", "plan"]
