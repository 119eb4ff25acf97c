"""urpt-gcs: terrain-aware mission planning for visual monitoring with a nadir camera.

``plan(dem, targets, settings)`` runs the whole pipeline and returns a :class:`Plan`; the
stages are modules of their own (terrain, targets, visibility, gtsp, solvers, mission,
formats) for anyone who wants to call them one by one.

The planner (numpy, rasterio, numba ...) is imported on first use of ``plan``, ``Plan`` or
``PlanSettings``, so that the command line starts, and answers Ctrl-C, before it has loaded.
Importing the package points numba's cache at the user's cache folder (:mod:`urpt_gcs.cache`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from urpt_gcs.cache import configure_numba_cache
from urpt_gcs.errors import UrptError

# Before any submodule can import numba, which reads its cache settings once, on import.
configure_numba_cache()

__version__ = "0.1.0"

if TYPE_CHECKING:
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.result import Plan
    from urpt_gcs.pipeline.settings import PlanSettings

__all__ = ["Plan", "PlanSettings", "UrptError", "__version__", "plan"]
_FROM_PLANNER = frozenset({"Plan", "PlanSettings", "plan"})


def __getattr__(name: str) -> Any:
    # PEP 562: the first `urpt_gcs.plan` imports the planner; Python caches nothing here, so
    # the names are bound into the module to make later look-ups ordinary ones.
    if name in _FROM_PLANNER:
        from urpt_gcs.pipeline import planner

        for exported in _FROM_PLANNER:
            globals()[exported] = getattr(planner, exported)
        return globals()[name]
    raise AttributeError(f"module 'urpt_gcs' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _FROM_PLANNER)
