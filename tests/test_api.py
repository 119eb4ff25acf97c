"""The public API a Python user finds at the top of the package, pinned."""

from __future__ import annotations

import subprocess
import sys

import urpt_gcs

PUBLIC = {
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
}


def test_the_exported_names_are_the_pinned_ones() -> None:
    assert set(urpt_gcs.__all__) == PUBLIC


def test_every_exported_name_resolves_to_its_own_object() -> None:
    from urpt_gcs.files.write import write_outputs
    from urpt_gcs.pipeline.fleet import plan_fleet
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.result import Plan
    from urpt_gcs.vehicle.link import upload

    for name in PUBLIC:
        assert getattr(urpt_gcs, name) is not None, name
    assert urpt_gcs.plan is plan
    assert urpt_gcs.plan_fleet is plan_fleet
    assert urpt_gcs.write_outputs is write_outputs
    assert urpt_gcs.upload is upload
    assert urpt_gcs.Plan is Plan
    assert issubclass(urpt_gcs.SettingsError, urpt_gcs.UrptError)
    assert issubclass(urpt_gcs.SettingsError, ValueError)


def test_the_errors_come_without_loading_the_planner() -> None:
    code = (
        "import sys, urpt_gcs; urpt_gcs.UrptError; "
        "print(any(m.startswith(('numpy', 'rasterio', 'numba')) for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
