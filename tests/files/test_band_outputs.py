"""A plan inside a height band writes every output right, as third-party readers see it."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from conftest import DEMO
from PIL import Image
from pymavlink import mavwp
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from rasterio.transform import from_origin

from urpt_gcs.files.products import write_products
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.solvers import SolveSettings

KML = {"k": "http://www.opengis.net/kml/2.2"}
RES = 2.0
SIZE = 500
ORIGIN = (500_000.0, 5_200_000.0)
# Targets on both flanks of a narrow ridge, so that legs over it need waypoints of their own.
PLACES = {
    "Home": (150, -850),
    "T1": (300, -200),
    "T2": (380, -300),
    "T3": (700, -450),
    "T4": (620, -600),
    "T5": (820, -750),
    "T6": (250, -700),
}


@pytest.fixture(scope="module")
def band_plan(tmp_path_factory: pytest.TempPathFactory) -> tuple[Plan, Path]:
    root = tmp_path_factory.mktemp("band")
    rows, cols = np.indices((SIZE, SIZE))
    x = ORIGIN[0] + (cols + 0.5) * RES
    y = ORIGIN[1] - (rows + 0.5) * RES
    # A Gaussian ridge 150 m high running north-south, on a gentle slope.
    z = 400.0 + 150.0 * np.exp(-((x - ORIGIN[0] - 500.0) ** 2) / (2 * 50.0**2))
    z += 0.02 * (y - ORIGIN[1] + 1000.0)
    dem = root / "ridge.tif"
    profile = {
        "driver": "GTiff",
        "height": SIZE,
        "width": SIZE,
        "count": 1,
        "dtype": "float32",
        "transform": from_origin(*ORIGIN, RES, RES),
        "nodata": -10000.0,
        "crs": "EPSG:32632",
    }
    with rasterio.open(dem, "w", **profile) as out:
        out.write(z.astype("float32"), 1)
    to_geo = pyproj.Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)
    lines = ["name,lat,lon"]
    for name, (dx, dy) in PLACES.items():
        lon, lat = to_geo.transform(ORIGIN[0] + dx, ORIGIN[1] + dy)
        lines.append(f"{name},{lat:.8f},{lon:.8f}")
    targets = root / "targets.csv"
    targets.write_text("\n".join(lines) + "\n")
    settings = PlanSettings(
        agl_band_m=(30.0, 120.0), solve=SolveSettings(time_limit_s=2), bound_time_s=1.0
    )
    result = plan(dem, targets, settings)
    out = root / "out"
    write_products(result, out)
    return result, out


def _stems(result: Plan) -> list[str]:
    n = len(result.missions)
    return ["mission"] if n == 1 else [f"mission_{k}" for k in range(1, n + 1)]


def test_the_band_plan_follows_the_terrain(band_plan: tuple[Plan, Path]) -> None:
    result, _ = band_plan
    assert result.band_flight is not None
    assert result.band_flight.inserted > 0
    assert result.regions == ()


def test_kml_paths_and_stops_are_absolute(band_plan: tuple[Plan, Path]) -> None:
    result, out = band_plan
    flight = result.band_flight
    assert flight is not None
    root = ET.parse(out / "plan.kml").getroot()
    assert root.find(".//k:Polygon", KML) is None  # no regions in a band
    lines = root.findall(".//k:LineString", KML)
    assert len(lines) == len(flight.paths_xyz)
    for line, path in zip(lines, flight.paths_xyz, strict=True):
        assert line.findtext("k:altitudeMode", namespaces=KML) == "absolute"
        coords = [
            tuple(float(v) for v in c.split(","))
            for c in line.findtext("k:coordinates", namespaces=KML).split()
        ]
        assert len(coords) == len(path)
        np.testing.assert_allclose([c[2] for c in coords], path[:, 2], atol=0.01)
    stops = np.vstack([p[s >= 0] for p, s in zip(flight.paths_xyz, flight.path_stop, strict=True)])
    points = []
    for mark in root.iterfind(".//k:Placemark", KML):
        if mark.findtext("k:styleUrl", namespaces=KML).startswith("#sortie-"):
            point = mark.find("k:Point", KML)
            if point is not None:
                assert point.findtext("k:altitudeMode", namespaces=KML) == "absolute"
                text = point.findtext("k:coordinates", namespaces=KML)
                points.append(float(text.split(",")[2]))
    np.testing.assert_allclose(points, stops[:, 2], atol=0.01)


def test_geojson_has_three_coordinates(band_plan: tuple[Plan, Path]) -> None:
    result, out = band_plan
    flight = result.band_flight
    assert flight is not None
    data = json.loads((out / "plan.geojson").read_text())
    kinds = [f["properties"]["kind"] for f in data["features"]]
    assert "region" not in kinds
    sorties = [f for f in data["features"] if f["properties"]["kind"] == "sortie"]
    for feature, path in zip(sorties, flight.paths_xyz, strict=True):
        coords = feature["geometry"]["coordinates"]
        assert all(len(c) == 3 for c in coords)
        np.testing.assert_allclose([c[2] for c in coords], path[:, 2], atol=0.01)
    for feature in data["features"]:
        if feature["properties"]["kind"] == "stop":
            assert len(feature["geometry"]["coordinates"]) == 3
            assert {"height_amsl_m", "height_above_surface_m"} <= feature["properties"].keys()


def _photo_after(commands: list[int]) -> list[bool]:
    """Per NAV_WAYPOINT, whether a photo command follows it before the next one."""
    flags: list[bool] = []
    for command in commands:
        if command == mavlink.MAV_CMD_NAV_WAYPOINT:
            flags.append(False)
        elif command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL and flags:
            flags[-1] = True
    return flags


def test_waypoints_carry_each_height(band_plan: tuple[Plan, Path]) -> None:
    result, out = band_plan
    flight = result.band_flight
    assert flight is not None
    for stem, mission, path, stop_of in zip(
        _stems(result), result.missions, flight.paths_xyz, flight.path_stop, strict=True
    ):
        loader = mavwp.MAVWPLoader()
        loader.load(str(out / f"{stem}.waypoints"))
        items = [loader.wp(i) for i in range(1, loader.count())]
        waypoints = [w for w in items if w.command == mavlink.MAV_CMD_NAV_WAYPOINT]
        above_home = path[1:, 2] - mission.home.amsl_m
        assert len(waypoints) == len(above_home)
        np.testing.assert_allclose([w.z for w in waypoints], above_home, atol=0.01)
        assert _photo_after([w.command for w in items]) == (stop_of[1:] >= 0).tolist()


def test_qgc_plan_carries_each_height(band_plan: tuple[Plan, Path]) -> None:
    result, out = band_plan
    flight = result.band_flight
    assert flight is not None
    for stem, mission, path, stop_of in zip(
        _stems(result), result.missions, flight.paths_xyz, flight.path_stop, strict=True
    ):
        data = json.loads((out / f"{stem}.plan").read_text())
        items = data["mission"]["items"]
        waypoints = [i for i in items if i["command"] == mavlink.MAV_CMD_NAV_WAYPOINT]
        above_home = path[1:, 2] - mission.home.amsl_m
        np.testing.assert_allclose([w["params"][6] for w in waypoints], above_home, atol=0.01)
        np.testing.assert_allclose([w["Altitude"] for w in waypoints], above_home, atol=0.01)
        assert _photo_after([i["command"] for i in items]) == (stop_of[1:] >= 0).tolist()


def test_summary_describes_the_band(band_plan: tuple[Plan, Path]) -> None:
    result, out = band_plan
    flight = result.band_flight
    assert flight is not None
    data = json.loads((out / "summary.json").read_text())
    band = data["band"]
    assert (band["floor_m"], band["ceiling_m"]) == (30.0, 120.0)
    assert band["inserted_waypoints"] == flight.inserted
    assert 30.0 - 1e-6 <= band["lowest_above_surface_m"] <= band["highest_above_surface_m"]
    assert band["highest_above_surface_m"] <= 120.0 + 1e-6
    assert band["time_bound_s"] > 0.0 and band["time_gap_pct"] >= 0.0
    assert band["horizontal_bound_m"] > 0.0 and band["estimate_s"] > 0.0
    assert data["altitude_amsl_m"] is None
    assert len(data["stops"]) == len(flight.stops_xyz)
    for stop, xyz in zip(data["stops"], flight.stops_xyz, strict=True):
        assert {"sortie", "lat_deg", "lon_deg", "sees"} <= stop.keys()
        assert stop["height_amsl_m"] == pytest.approx(xyz[2], abs=0.01)
        assert stop["height_above_home_m"] == pytest.approx(
            xyz[2] - result.mission.home.amsl_m, abs=0.01
        )
        assert 30.0 - 0.01 <= stop["height_above_surface_m"] <= 120.0 + 0.01


def test_map_opens(band_plan: tuple[Plan, Path]) -> None:
    _, out = band_plan
    with Image.open(out / "map.png") as image:
        width, height = image.size
    # The map and a row of profile panels below it.
    assert width >= 800 and height > width


def test_plane_outputs_still_parse(tmp_path: Path) -> None:
    result = plan(
        DEMO / "site.tif", DEMO / "targets.kml", PlanSettings(solve=SolveSettings(time_limit_s=0.5))
    )
    out = tmp_path / "out"
    data = write_products(result, out, with_map=False)
    altitude = result.camera.altitude_m
    root = ET.parse(out / "plan.kml").getroot()
    assert root.find(".//k:Polygon", KML) is not None
    for line in root.iterfind(".//k:LineString", KML):
        assert line.findtext("k:altitudeMode", namespaces=KML) == "absolute"
        alts = [
            float(c.split(",")[2]) for c in line.findtext("k:coordinates", namespaces=KML).split()
        ]
        np.testing.assert_allclose(alts, altitude, atol=0.01)
    geo = json.loads((out / "plan.geojson").read_text())
    sorties = [f for f in geo["features"] if f["properties"]["kind"] == "sortie"]
    assert all(len(c) == 3 for f in sorties for c in f["geometry"]["coordinates"])
    assert "band" not in data and data["altitude_amsl_m"] == round(altitude, 2)
    assert "height_amsl_m" not in data["stops"][0]
    loader = mavwp.MAVWPLoader()
    loader.load(str(out / "mission.waypoints"))
    heights = [
        loader.wp(i).z
        for i in range(1, loader.count())
        if loader.wp(i).command == mavlink.MAV_CMD_NAV_WAYPOINT
    ]
    np.testing.assert_allclose(heights, result.altitude_rel_m)
