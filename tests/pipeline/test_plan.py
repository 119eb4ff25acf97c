"""End-to-end plans on the demo site and on real rasters, checked independently."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
from conftest import DEMO, REAL_DEMS, needs_shared
from pymavlink import mavutil
from support.independent import (
    FlownMission,
    Raster,
    check_mission,
    leg_clearances,
    load_raster,
    read_waypoints_file,
    sees,
)
from support.targets import REAL_CASES, kml_targets, valid_targets

from urpt_gcs.files.products import write_products
from urpt_gcs.pipeline import planner
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.solvers import SolveSettings

FAST = SolveSettings(time_limit_s=1.0)


def test_demo_plan_sees_every_target_and_clears_every_leg(tmp_path: Path) -> None:
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", PlanSettings(solve=FAST))
    data = write_products(result, tmp_path)
    problems = check_mission(
        DEMO / "site.tif",
        tmp_path / "mission.waypoints",
        kml_targets(DEMO / "targets.kml"),
        fov_deg=30.0,
        min_clearance_m=10.0,
    )
    assert problems == []
    assert data["targets"] == 16
    # The demo's walls, cliff and gully must actually cut some regions short.
    cut = [r for r in result.regions if r.reach_m.min() < 0.7 * r.cone_radius_m]
    assert len(cut) >= 4
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in (
        "targets",
        "tour_length_m",
        "lower_bound_m",
        "proven_optimal",
        "solver",
        "altitude_amsl_m",
        "fov_deg",
        "samples",
    ):
        assert key in summary
    # The reported length is the length of the written mission, measured independently.
    geod = pyproj.Geod(ellps="WGS84")
    wp = [
        (it["params"][4], it["params"][5])
        for it in json.loads((tmp_path / "mission.plan").read_text())["mission"]["items"]
        if it["command"] == mavutil.mavlink.MAV_CMD_NAV_WAYPOINT
    ]
    home = summary["home"]
    path = [(home["lat_deg"], home["lon_deg"]), *wp, (home["lat_deg"], home["lon_deg"])]
    lats, lons = zip(*path, strict=True)
    length = geod.line_length(lons, lats)
    assert length == pytest.approx(summary["tour_length_m"], rel=2e-3)
    assert summary["lower_bound_m"] <= summary["tour_length_m"]


def test_300_targets_on_the_demo_plan_and_check(tmp_path: Path) -> None:
    """Beyond the exact solver and the dense arrays of old: every target seen and every leg
    clear, checked independently on the written sorties."""
    targets = Path(__file__).resolve().parents[1] / "data" / "targets" / "demo_300_targets.csv"
    result = plan(DEMO / "site.tif", targets, PlanSettings(solve=SolveSettings(time_limit_s=3.0)))
    write_products(result, tmp_path, with_map=False)
    files = sorted(tmp_path.glob("mission*.waypoints"))
    assert len(files) == len(result.sorties)
    points = [
        (n, float(a), float(o))
        for n, a, o in (line.split(",") for line in targets.read_text().splitlines()[1:])
    ]
    assert len(points) == 300
    assert check_mission(DEMO / "site.tif", files, points, fov_deg=30.0, min_clearance_m=10.0) == []


def _demo_as_written(
    out: Path, tolerance_m: float
) -> tuple[Raster, FlownMission, dict[str, tuple[float, float]], list[dict[str, Any]]]:
    """The demo planned at ``tolerance_m`` and written to ``out``, read back independently:
    the raster, the written waypoints, the targets by name, the summary's stops."""
    settings = PlanSettings(solve=FAST, position_tolerance_m=tolerance_m)
    write_products(plan(DEMO / "site.tif", DEMO / "targets.kml", settings), out, with_map=False)
    flown = read_waypoints_file(out / "mission.waypoints")
    targets = {name: (lat, lon) for name, lat, lon in kml_targets(DEMO / "targets.kml")}
    stops = json.loads((out / "summary.json").read_text())["stops"]
    assert len(stops) == len(flown.waypoints)
    return load_raster(DEMO / "site.tif"), flown, targets, stops


@pytest.mark.parametrize("tolerance_m", [1.5, 3.0])
def test_every_stop_sees_its_targets_from_around_its_waypoint(
    tmp_path: Path, tolerance_m: float
) -> None:
    """A vehicle that photographs up to --position-tolerance off its waypoint (PX4 brakes
    past it) still sees every target its stop is counted for: checked independently from
    eight points around each written waypoint, just inside the tolerance."""
    raster, flown, targets, stops = _demo_as_written(tmp_path, tolerance_m)
    geod = pyproj.Geod(ellps="WGS84")
    missed = []
    for stop, (lat, lon, amsl) in zip(stops, flown.waypoints, strict=True):
        for azimuth in range(0, 360, 45):
            x, y, _ = geod.fwd(lon, lat, azimuth, 0.95 * tolerance_m)
            for name in stop["sees"]:
                ok, why = sees(raster, targets[name], (y, x, amsl), fov_deg=30.0)
                if not ok:
                    missed.append((stop["order"], name, azimuth, why))
    assert missed == []


@pytest.mark.parametrize("tolerance_m", [1.5, 5.0])
def test_every_stop_keeps_its_targets_in_the_cone_from_its_whole_tolerance_disc(
    tmp_path: Path, tolerance_m: float
) -> None:
    """The disc of --position-tolerance around each written waypoint, not only points of its
    rim, lies inside the cone's circle at every target the stop is counted for: R - d >= r,
    measured independently in the DEM's CRS, the cone's radius from the height as written
    over the DEM's bilinear ground at the target (1 mm for arithmetic)."""
    raster, flown, targets, stops = _demo_as_written(tmp_path, tolerance_m)
    tan = math.tan(math.radians(30.0))
    margins = []
    for stop, (lat, lon, amsl) in zip(stops, flown.waypoints, strict=True):
        ex, ey = raster.to_src.transform(lon, lat)
        for name in stop["sees"]:
            t_lat, t_lon = targets[name]
            tx, ty = raster.to_src.transform(t_lon, t_lat)
            ground = float(raster.height(np.array([t_lon]), np.array([t_lat]))[0])
            margin = (amsl - ground) * tan - math.hypot(tx - ex, ty - ey) - tolerance_m
            margins.append((margin, stop["order"], name))
    assert len(margins) >= 16
    assert min(margins)[0] >= -1e-3, sorted(margins)[:3]


def test_the_missions_as_written_are_measured_for_the_disc_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without the margin stage (and refinement) the solver's stops sit on the edge of what
    they see: the check of the missions as written names each one whose disc leaves the
    picture, in a warning."""
    monkeypatch.setattr(planner, "robust_tour", lambda site, tour, home, names: (tour, []))
    settings = PlanSettings(solve=FAST, position_tolerance_m=5.0, refine=False)
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    short = [w for w in result.warnings if "in the picture only within" in w]
    assert short, result.warnings
    assert all(w.endswith("not 5 m: a vehicle that stops farther off may miss it") for w in short)


@needs_shared(REAL_DEMS)
@pytest.mark.parametrize(("name", "count", "box_m"), REAL_CASES)
def test_real_rasters_plan_and_check(
    tmp_path: Path, name: str, count: int, box_m: float | None
) -> None:
    dem = REAL_DEMS / name
    targets = valid_targets(dem, count, seed=3, box_m=box_m)
    csv = tmp_path / "targets.csv"
    csv.write_text(
        "name,lat,lon\n" + "".join(f"{n},{lat:.9f},{lon:.9f}\n" for n, lat, lon in targets)
    )
    result = plan(dem, csv, PlanSettings(solve=FAST))
    out = tmp_path / "out"
    write_products(result, out, with_map=False)
    # A long tour is split into sorties (mission_1, mission_2, ...): together they see all.
    files = sorted(out.glob("mission*.waypoints"))
    assert len(files) == len(result.sorties)
    assert check_mission(dem, files, targets, fov_deg=30.0, min_clearance_m=10.0) == []
    assert np.isfinite(result.terrain.elevation_m).any()
    # Reported clearances are exact maxima of the surface: never above what dense samples of
    # the written legs show, and within what such samples can miss. A geographic DEM is
    # planned through a fitted affine map, good to millimetres here.
    slack = 0.01 if result.dem.needs_warp else 1e-3
    dense = leg_clearances(load_raster(dem), [read_waypoints_file(f) for f in files], 1 / 64)
    independent = np.array([c for sortie in dense for c in sortie])
    reported = np.array([leg.min_clearance_m for leg in result.legs])
    known = np.isfinite(independent) & np.isfinite(reported)
    assert known.any()
    assert np.all(reported[known] <= independent[known] + slack)
    assert np.all(reported[known] >= independent[known] - 0.05)
