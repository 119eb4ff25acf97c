"""urpt-gcs: terrain-aware mission planning for visual monitoring with a nadir camera.

The public API, everything the command line does, as calls:

- :func:`plan` (DEM and targets -> :class:`Plan`) and :func:`plan_fleet` (-> :class:`FleetPlan`),
  with :class:`PlanSettings` (holding :class:`SolveSettings` and :class:`MissionSettings`),
  :class:`FleetSettings` and :class:`VehicleSpec`;
- :func:`write_outputs`: a plan's files (``.plan``, ``.waypoints``, KML, GeoJSON, summary, map)
  written into a folder as one set;
- :func:`upload`: one :class:`Mission` to a vehicle through MAVSDK, read back and compared
  item by item (:class:`UploadSettings`, :class:`UploadReport`);
- :func:`judge_flown`: what real flights of a plan photographed, from their logs
  (:class:`FlownReport`), and :func:`remaining_targets` to plan the rest;
- the errors, all rooted at :class:`UrptError`.

The stages behind them are packages of their own, in pipeline order: ``site`` (inputs,
targets, terrain, camera), ``visibility``, ``problem`` / ``solvers`` / ``bound`` (terrain-free:
tours and their certified lower bound), ``flight`` (from a tour to checked missions),
``pipeline`` (the stage chain), ``files``, ``vehicle``; ``sim`` and ``replay`` fly plans on a
simulated or real SITL vehicle; ``batch``, ``bench`` and ``cli`` sit on top.

Everything but the errors is imported on first use, so that the command line starts, and
answers Ctrl-C, before numpy, rasterio and numba have loaded. Importing the package points
numba's cache at the user's cache folder (:mod:`urpt_gcs.cache`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from urpt_gcs.cache import configure_numba_cache
from urpt_gcs.errors import (
    ClusterError,
    DemError,
    JobsFileError,
    LinkError,
    MissionFileError,
    OutputError,
    PlanError,
    SettingsError,
    TargetsError,
    UrptError,
)

# Before any submodule can import numba, which reads its cache settings once, on import.
configure_numba_cache()

__version__ = "0.1.0"

if TYPE_CHECKING:
    from urpt_gcs.files.write import write_outputs
    from urpt_gcs.flight.mission import Mission, MissionSettings
    from urpt_gcs.pipeline.fleet import FleetPlan, IdleVehicle, plan_fleet
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.result import Plan
    from urpt_gcs.pipeline.settings import FleetSettings, PlanSettings, VehicleSpec
    from urpt_gcs.replay.flown import FlownReport, judge_flown, remaining_targets
    from urpt_gcs.solvers import SolveSettings, Tour
    from urpt_gcs.vehicle.link import UploadReport, UploadSettings, upload

# Each name loaded on first use, and the module it comes from.
_LAZY = {
    "plan": "urpt_gcs.pipeline.planner",
    "plan_fleet": "urpt_gcs.pipeline.fleet",
    "write_outputs": "urpt_gcs.files.write",
    "upload": "urpt_gcs.vehicle.link",
    "Plan": "urpt_gcs.pipeline.result",
    "FleetPlan": "urpt_gcs.pipeline.fleet",
    "IdleVehicle": "urpt_gcs.pipeline.fleet",
    "PlanSettings": "urpt_gcs.pipeline.settings",
    "FleetSettings": "urpt_gcs.pipeline.settings",
    "VehicleSpec": "urpt_gcs.pipeline.settings",
    "Mission": "urpt_gcs.flight.mission",
    "MissionSettings": "urpt_gcs.flight.mission",
    "SolveSettings": "urpt_gcs.solvers",
    "Tour": "urpt_gcs.solvers",
    "UploadSettings": "urpt_gcs.vehicle.link",
    "UploadReport": "urpt_gcs.vehicle.link",
    "judge_flown": "urpt_gcs.replay.flown",
    "FlownReport": "urpt_gcs.replay.flown",
    "remaining_targets": "urpt_gcs.replay.flown",
}

__all__ = [
    "ClusterError",
    "DemError",
    "FleetPlan",
    "FleetSettings",
    "FlownReport",
    "IdleVehicle",
    "JobsFileError",
    "LinkError",
    "Mission",
    "MissionFileError",
    "MissionSettings",
    "OutputError",
    "Plan",
    "PlanError",
    "PlanSettings",
    "SettingsError",
    "SolveSettings",
    "TargetsError",
    "Tour",
    "UploadReport",
    "UploadSettings",
    "UrptError",
    "VehicleSpec",
    "__version__",
    "judge_flown",
    "plan",
    "plan_fleet",
    "remaining_targets",
    "upload",
    "write_outputs",
]


def __getattr__(name: str) -> Any:
    # PEP 562: the first look-up of a lazy name imports its module and binds the name here,
    # so later look-ups are ordinary ones.
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'urpt_gcs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
