"""Plans whose ``map.html`` the tests open: written as ``plan`` writes them, each into a
folder of its own.

- the demo with a frame camera (photo frames, a GSD per stop) and target names that are
  markup, script or TeX (:data:`HOSTILE`);
- the generated ridge planned inside a band of 30 to 120 m above the surface (waypoints that
  follow the terrain, a profile per sortie);
- the demo shared by a fleet of two.
"""

from __future__ import annotations

import csv
from pathlib import Path

import rasterio
from conftest import DEMO
from rasterio.transform import from_origin

from support.band_sites import (
    RIDGE_CELL_M,
    RIDGE_CRS,
    RIDGE_ORIGIN,
    ridge_surface,
    ridge_targets_csv,
)
from urpt_gcs.files.products import write_products
from urpt_gcs.files.write import write_outputs
from urpt_gcs.pipeline.fleet import FleetPlan, plan_fleet
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import FleetSettings, PlanSettings, VehicleSpec
from urpt_gcs.site.camera import CAMERAS
from urpt_gcs.site.targets import read_targets
from urpt_gcs.solvers import SolveSettings

__all__ = ["BAND_M", "HOSTILE", "write_band", "write_fleet", "write_framed"]

# Demo targets renamed (1-based) to names that are markup, script or TeX.
HOSTILE = {
    1: "<script>alert(1)</script>",
    2: "$x$",
    3: '<img src=x onerror="alert(2)">',
    4: "$$\\frac{1}{2}$$ & <b>bold</b>",
}
# The band of the ridge's plan, metres above the surface.
BAND_M = (30.0, 120.0)
# Quick plans: a second for the solver, half a second for the bound.
_FAST = {"solve": SolveSettings(time_limit_s=1.0), "bound_time_s": 0.5}


def write_framed(root: Path) -> tuple[Plan, Path]:
    """Plan the demo with a Phantom 4 RTK and :data:`HOSTILE` names; its files in
    ``root/out``."""
    demo = read_targets(DEMO / "targets.kml")
    assert demo.home is not None
    targets = root / "targets.csv"
    with targets.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["name", "lat", "lon"])
        writer.writerow([demo.home.name, demo.home.lat_deg, demo.home.lon_deg])
        for k, t in enumerate(demo.targets, start=1):
            writer.writerow([HOSTILE.get(k, t.name), t.lat_deg, t.lon_deg])
    settings = PlanSettings(frame=CAMERAS["phantom4rtk"].frame, **_FAST)
    result = plan(DEMO / "site.tif", targets, settings)
    write_products(result, root / "out")
    return result, root / "out"


def write_band(root: Path) -> tuple[Plan, Path]:
    """Plan the ridge inside :data:`BAND_M`; its files in ``root/out``."""
    z = ridge_surface()
    dem = root / "ridge.tif"
    profile = {
        "driver": "GTiff",
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": "float32",
        "transform": from_origin(*RIDGE_ORIGIN, RIDGE_CELL_M, RIDGE_CELL_M),
        "nodata": -10000.0,
        "crs": RIDGE_CRS,
    }
    with rasterio.open(dem, "w", **profile) as out:
        out.write(z.astype("float32"), 1)
    targets = root / "targets.csv"
    ridge_targets_csv(targets)
    result = plan(dem, targets, PlanSettings(agl_band_m=BAND_M, **_FAST))
    assert result.band_flight is not None and result.band_flight.inserted > 0
    write_products(result, root / "out")
    return result, root / "out"


def write_fleet(root: Path) -> tuple[FleetPlan, Path]:
    """Plan the demo for two vehicles from its home; the fleet's folder is ``root/out``."""
    fleet = FleetSettings((VehicleSpec(), VehicleSpec()))
    result = plan_fleet(DEMO / "site.tif", DEMO / "targets.kml", PlanSettings(**_FAST), fleet)
    write_outputs(result, root / "out")
    return result, root / "out"
