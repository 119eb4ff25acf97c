"""Plans on DEMs in other units and CRSs, checked against the metre DEM and the ellipsoid.

The demo site stored in feet, in US survey feet, in Web Mercator and with its heights in a
second band must give the plan the metre DEM gives, and a State Plane DEM in feet must plan
with true lengths. The deterministic ``approx`` solver is used so that equal inputs give
equal tours.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
import rasterio
import rasterio.warp
from click.testing import CliRunner
from conftest import DEMO, WriteDem
from support.independent import check_mission, load_raster, read_waypoints_file, sees

import urpt_gcs.pipeline.improve as improve
from urpt_gcs.cli import main
from urpt_gcs.errors import PlanError
from urpt_gcs.files.products import write_products
from urpt_gcs.files.report import summary_text
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.site.targets import read_targets
from urpt_gcs.solvers import SolveSettings

SITE = DEMO / "site.tif"
TARGETS = DEMO / "targets.kml"
SETTINGS = PlanSettings(solver="approx", solve=SolveSettings(time_limit_s=1.0))
GEOD = pyproj.Geod(ellps="WGS84")


def _targets(path: Path) -> list[tuple[str, float, float]]:
    return [(t.name, t.lat_deg, t.lon_deg) for t in read_targets(path).targets]


def _plan_and_write(dem: Path, out: Path, targets: Path = TARGETS) -> dict[str, Any]:
    return write_products(plan(dem, targets, SETTINGS), out, with_map=False)


def _geodesic_tour_m(out: Path) -> float:
    """Length on the ellipsoid of every written sortie: home, its waypoints, home."""
    total = 0.0
    for path in sorted(out.glob("mission*.waypoints")):
        flown = read_waypoints_file(path)
        points = [flown.home[:2], *(w[:2] for w in flown.waypoints), flown.home[:2]]
        lats, lons = zip(*points, strict=True)
        total += GEOD.line_length(lons, lats)
    return total


@pytest.fixture(scope="module")
def metre_plan(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _plan_and_write(SITE, tmp_path_factory.mktemp("metre"))


def _copy_in_unit(path: Path, crs: str, metres_per_unit: float) -> Path:
    with rasterio.open(SITE) as src:
        profile = src.profile
        z = src.read(1).astype(np.float64)
    valid = z != profile["nodata"]
    stored = np.where(valid, z / metres_per_unit, profile["nodata"])
    profile.update(crs=rasterio.crs.CRS.from_user_input(crs))
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(stored.astype(profile["dtype"]), 1)
    return path


def _assert_every_claimed_view_holds(dem: Path, out: Path, data: dict[str, Any]) -> None:
    raster = load_raster(dem)
    where = {name: (lat, lon) for name, lat, lon in _targets(TARGETS)}
    (waypoints,) = sorted(out.glob("mission*.waypoints"))
    eyes = read_waypoints_file(waypoints).waypoints
    assert len(eyes) == len(data["stops"])
    for stop, eye in zip(data["stops"], eyes, strict=True):
        for name in stop["sees"]:
            ok, why = sees(raster, where[name], eye, fov_deg=30.0)
            assert ok, f"stop {stop['order']} claims {name}: {why}"


@pytest.mark.parametrize(
    ("crs", "metres_per_unit", "words"),
    [
        # The demo's pixels times 3.28084, as a converter to international feet writes them.
        ("EPSG:32632+8228", 1.0 / 3.28084, "DEM heights in feet, converted to metres"),
        ("EPSG:32632+6360", 1200.0 / 3937.0, "DEM heights in US survey feet, converted to metres"),
    ],
)
def test_feet_dem_gives_the_metre_plan(
    tmp_path: Path,
    metre_plan: dict[str, Any],
    crs: str,
    metres_per_unit: float,
    words: str,
) -> None:
    dem = _copy_in_unit(tmp_path / "site_ft.tif", crs, metres_per_unit)
    out = tmp_path / "out"
    data = _plan_and_write(dem, out)
    # The same flight plane, to within the rounding of float32 feet, and the same tour to
    # within what the time-limited stages (refinement, the bound's tour) may leave apart on
    # a busy machine (0.06 m was seen).
    assert data["altitude_amsl_m"] == pytest.approx(metre_plan["altitude_amsl_m"], abs=0.011)
    assert data["terrain_max_m"] == pytest.approx(metre_plan["terrain_max_m"], abs=0.01)
    assert data["tour_length_m"] == pytest.approx(metre_plan["tour_length_m"], rel=5e-3)
    # Checked on the metre DEM by the independent line-of-sight test.
    _assert_every_claimed_view_holds(SITE, out, data)
    problems = check_mission(
        SITE, sorted(out.glob("mission*.waypoints")), _targets(TARGETS), 30.0, 10.0
    )
    assert problems == []
    assert words in summary_text(data)
    saved = json.loads((out / "summary.json").read_text())["dem"]
    assert saved["vertical_unit_to_m"] == pytest.approx(metres_per_unit, rel=1e-6)


def test_web_mercator_dem_is_planned_with_true_lengths(
    tmp_path: Path, metre_plan: dict[str, Any]
) -> None:
    dem = tmp_path / "site_3857.tif"
    with rasterio.open(SITE) as src:
        transform, width, height = rasterio.warp.calculate_default_transform(
            src.crs, "EPSG:3857", src.width, src.height, *src.bounds
        )
        profile = src.profile
        profile.update(crs="EPSG:3857", transform=transform, width=width, height=height)
        with rasterio.open(dem, "w", **profile) as dst:
            rasterio.warp.reproject(
                rasterio.band(src, 1),
                rasterio.band(dst, 1),
                resampling=rasterio.warp.Resampling.bilinear,
                src_nodata=src.nodata,
                dst_nodata=src.nodata,
            )
    out = tmp_path / "out"
    data = _plan_and_write(dem, out)
    assert data["dem"]["crs"] == "EPSG:32632"
    assert "(the DEM is in WGS 84 / Pseudo-Mercator)" in summary_text(data)
    # Mercator stretches lengths by 1.49 at 47.7 N; the plan's must be ground lengths.
    assert data["tour_length_m"] == pytest.approx(_geodesic_tour_m(out), rel=2e-3)
    # The warped terrain is resampled, so the tour may differ a little from the metre one.
    # Lengths are true (above); the tour itself differs a little from the metre plan's, as the
    # warped raster is resampled and stops are moved for the position margin.
    assert data["tour_length_m"] == pytest.approx(metre_plan["tour_length_m"], rel=0.03)
    problems = check_mission(
        dem, sorted(out.glob("mission*.waypoints")), _targets(TARGETS), 30.0, 10.0
    )
    assert problems == []


def test_band_2_of_a_two_band_dem_is_planned(tmp_path: Path, metre_plan: dict[str, Any]) -> None:
    """Band 1 is the terrain raised 50 m (a decoy), band 2 the terrain: --band 2 reads it."""
    dem = tmp_path / "two_bands.tif"
    with rasterio.open(SITE) as src:
        profile = src.profile
        z = src.read(1)
    profile.update(count=2)
    with rasterio.open(dem, "w", **profile) as dst:
        dst.write(np.where(z == profile["nodata"], z, z + 50.0), 1)
        dst.write(z, 2)
    out = tmp_path / "out"
    args = ["plan", "--dem", str(dem), "--targets", str(TARGETS), "--out", str(out)]
    result = CliRunner().invoke(
        main, [*args, "--band", "2", "--solver", "approx", "--no-map", "--json"]
    )
    assert result.exit_code == 0, result.output
    data = json.loads((out / "summary.json").read_text())
    assert data["dem"]["band"] == 2
    assert data["altitude_amsl_m"] == metre_plan["altitude_amsl_m"]
    # The decoy band would raise the plane; the tours agree to what the time-limited stages
    # leave apart.
    assert data["tour_length_m"] == pytest.approx(metre_plan["tour_length_m"], rel=5e-3)
    problems = check_mission(SITE, out / "mission.waypoints", _targets(TARGETS), 30.0, 10.0)
    assert problems == []


def test_state_plane_feet_dem_plans_with_true_lengths(tmp_path: Path, write_dem: WriteDem) -> None:
    """NAD83 / California zone 5 (ftUS), 1 ft pixels, heights in metres (no vertical CRS)."""
    lon0, lat0 = -118.25, 34.05
    to_sp = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:2229", always_xy=True)
    x0, y0 = to_sp.transform(lon0, lat0)
    size = 900
    cols, rows = np.meshgrid(np.arange(size), np.arange(size))
    rng = np.random.default_rng(4)
    z = np.full((size, size), 120.0)
    # Eight round hills 3-12 m high, 60 ft wide (one standard deviation).
    centres = rng.uniform(100.0, 800.0, (8, 2))
    for (cx, cy), hill_m in zip(centres, rng.uniform(3.0, 12.0, 8), strict=True):
        z += hill_m * np.exp(-((cols - cx) ** 2 + (rows - cy) ** 2) / (2.0 * 60.0**2))
    dem = write_dem(z, name="sp.tif", crs="EPSG:2229", origin=(x0, y0), res=1.0)
    to_geo = pyproj.Transformer.from_crs("EPSG:2229", "EPSG:4326", always_xy=True)
    picks = rng.uniform(300, 600, (6, 2))
    lon, lat = to_geo.transform(x0 + picks[:, 0], y0 - picks[:, 1])
    csv = tmp_path / "targets.csv"
    lines = [f"T{k},{b:.9f},{a:.9f}" for k, (a, b) in enumerate(zip(lon, lat, strict=True))]
    csv.write_text("name,lat,lon\n" + "\n".join(lines) + "\n")
    out = tmp_path / "out"
    data = _plan_and_write(dem, out, targets=csv)
    assert data["dem"]["crs"] == "EPSG:32611"
    assert data["tour_length_m"] == pytest.approx(_geodesic_tour_m(out), rel=2e-3)
    problems = check_mission(dem, sorted(out.glob("mission*.waypoints")), _targets(csv), 30.0, 10.0)
    assert problems == []


def test_a_tour_read_off_the_bound_that_fails_a_check_is_not_flown(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The tour read off the bound is checked as written like any other; when a check
    refuses it (a stop on the edge of what it sees once rounded), the refined tour is flown,
    not the plan refused."""
    read: list[int] = []

    def refuse(*args: Any, **kwargs: Any) -> Any:
        read.append(1)
        raise PlanError("stop 5 no longer sees its target once written")

    monkeypatch.setattr(improve, "sorties_and_missions", refuse)
    settings = PlanSettings(solve=SolveSettings(time_limit_s=2.0))
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    assert read, "no tour was read off the bound: the test no longer reaches the check"
    assert result.certificate is not None
    assert result.refinement is not None
    assert result.tour.length == pytest.approx(result.refinement.after_m)
