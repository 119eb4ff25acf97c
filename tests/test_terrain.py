"""Reading DEMs: only the window a plan needs, any nodata masked, any CRS made metric."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from conftest import REAL_DEMS, WriteDem
from rasterio.transform import from_origin
from rasterio.windows import Window

from urpt_gcs.errors import DemError
from urpt_gcs.planner import PlanSettings, plan
from urpt_gcs.solvers import SolveSettings
from urpt_gcs.terrain import open_dem, planning_crs, read_terrain

ORIGIN = (500_000.0, 5_200_000.0)


def test_large_tile_is_read_only_around_the_targets(tmp_path: Path) -> None:
    """A 5000 x 5000 px Pix4D-like tile with targets in one corner: a small window is read."""
    path = tmp_path / "big.tif"
    size, res = 5000, 0.05
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=size,
        height=size,
        count=1,
        dtype="float32",
        crs="EPSG:32632",
        nodata=-10000.0,
        tiled=True,
        blockxsize=512,
        blockysize=512,
        compress="deflate",
        transform=from_origin(ORIGIN[0], ORIGIN[1], res, res),
    ) as dst:
        cols = np.arange(512)
        for r0 in range(0, size, 512):
            rows = np.arange(r0, min(r0 + 512, size))
            block = 400.0 + 0.001 * rows[:, None] + 0.0 * cols[None, :]
            for c0 in range(0, size, 512):
                w = min(512, size - c0)
                dst.write(block[:, :w].astype("float32"), 1, window=Window(c0, r0, w, len(rows)))
    to_geo = pyproj.Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)
    rows = ["name,lat,lon"]
    for name, dx, dy in (("A", 20.0, 20.0), ("B", 26.0, 22.0), ("Home", 22.0, 28.0)):
        lon, lat = to_geo.transform(ORIGIN[0] + dx, ORIGIN[1] - dy)
        rows.append(f"{name},{lat:.9f},{lon:.9f}")
    csv = tmp_path / "t.csv"
    csv.write_text("\n".join(rows) + "\n")
    result = plan(path, csv, PlanSettings(clearance_m=10.0, solve=SolveSettings(time_limit_s=0.5)))
    _, _, width, height = result.terrain.read_window_px
    assert result.terrain.source_shape_px == (size, size)
    # The cone of a 10 m flight over flat ground is under 6 m: the window is a few hundred px.
    assert width * height < 0.01 * size * size
    assert result.terrain.elevation_m.nbytes < 4_000_000


@pytest.mark.parametrize(
    ("nodata", "dtype"),
    [
        (np.nan, "float32"),
        (-9999.0, "float64"),
        (-10000.0, "float32"),
        (0.0, "float32"),
        (-32768.0, "int16"),
    ],
)
def test_nodata_of_any_kind_is_masked(write_dem: WriteDem, nodata: float, dtype: str) -> None:
    z = np.full((100, 100), 120.0)
    z[40:60, 40:60] = nodata
    path = write_dem(z, nodata=nodata, dtype=dtype, origin=ORIGIN, res=1.0)
    info = open_dem(path)
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 100.0, ORIGIN[0] + 100.0, ORIGIN[1])
    )
    assert np.isnan(terrain.elevation_m[40:60, 40:60]).all()
    assert np.nanmin(terrain.elevation_m) == 120.0
    # A sample next to a nodata cell is unknown, never an interpolation towards the fill value.
    assert np.isnan(terrain.sample(ORIGIN[0] + 39.9, ORIGIN[1] - 50.0))
    assert terrain.sample(ORIGIN[0] + 20.5, ORIGIN[1] - 20.5) == pytest.approx(120.0)


def test_undeclared_fill_values_are_masked(write_dem: WriteDem) -> None:
    z = np.full((50, 50), 50.0)
    z[:5] = -3.4028235e38
    path = write_dem(z, nodata=None, origin=ORIGIN, res=1.0)
    info = open_dem(path)
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 50.0, ORIGIN[0] + 50.0, ORIGIN[1])
    )
    assert np.isnan(terrain.elevation_m[:5]).all()
    assert np.nanmax(terrain.elevation_m) == 50.0


def test_compound_crs_without_epsg_plans_in_its_horizontal_part() -> None:
    info = open_dem(REAL_DEMS / "codem_aoi_dsm_utm16n_egm2008.tif")
    assert info.crs.to_epsg() is None and info.crs.is_compound
    assert not info.needs_warp
    assert info.horizontal_crs.to_epsg() == 32616


@pytest.mark.parametrize("name", ["pysheds_dem_wgs84.tif", "dsm2dtm_drone_dsm_wgs84.tif"])
def test_geographic_dem_is_georeferenced_in_utm_without_resampling(name: str) -> None:
    path = REAL_DEMS / name
    info = open_dem(path)
    assert info.needs_warp
    with rasterio.open(path) as src:
        west, south, east, north = src.bounds
        full = src.read(1, masked=True).astype(np.float64).filled(np.nan)
        transform = src.transform
    lon_c, lat_c = (west + east) / 2, (south + north) / 2
    crs = planning_crs(info, (lon_c, lat_c, lon_c, lat_c))
    assert crs.to_epsg() == (32614 if "pysheds" in name else 32643)
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    # A window of about a quarter of the raster around its centre.
    dlon, dlat = (east - west) / 8, (north - south) / 8
    xs, ys = to_utm.transform([lon_c - dlon, lon_c + dlon], [lat_c - dlat, lat_c + dlat])
    terrain = read_terrain(info, crs, (min(xs), min(ys), max(xs), max(ys)))
    # Pixel centres of the source, located exactly with pyproj, carry their own values.
    rng = np.random.default_rng(0)
    col0, row0, width, height = terrain.read_window_px
    cols = rng.integers(col0 + 2, col0 + width - 2, 50)
    rows = rng.integers(row0 + 2, row0 + height - 2, 50)
    lon, lat = transform @ (cols + 0.5, rows + 0.5)
    x, y = to_utm.transform(lon, lat)
    got = terrain.sample(np.asarray(x), np.asarray(y))
    want = full[rows, cols]
    ok = np.isfinite(want) & np.isfinite(got)
    assert ok.sum() > 10
    # The fitted affine map places a source pixel to within a small fraction of a cell.
    spacing = terrain.cell_m
    col_f, row_f = terrain.pixel_coords(np.asarray(x), np.asarray(y))
    err = np.hypot(col_f - (cols - col0), row_f - (rows - row0))
    assert float(err.max()) < 0.05, spacing
    slope_tolerance = 0.1 * np.nanmax(np.abs(np.diff(full, axis=0)))
    assert np.allclose(got[ok], want[ok], atol=max(slope_tolerance, 1e-6))


def test_rotated_raster_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "rot.tif"
    rotated = rasterio.Affine.rotation(10) @ from_origin(ORIGIN[0], ORIGIN[1], 1.0, 1.0)
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=10,
        height=10,
        count=1,
        dtype="float32",
        crs="EPSG:32632",
        transform=rotated,
    ) as dst:
        dst.write(np.zeros((10, 10), "float32"), 1)
    with pytest.raises(DemError, match="north-up"):
        open_dem(path)


def test_truncated_geotiff_is_refused(tmp_path: Path, write_dem: WriteDem) -> None:
    good = write_dem(np.full((300, 300), 5.0), name="good.tif")
    data = good.read_bytes()
    bad = tmp_path / "truncated.tif"
    bad.write_bytes(data[: len(data) // 3])
    with pytest.raises(DemError, match=r"truncated\.tif"):
        info = open_dem(bad)
        read_terrain(
            info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 150, ORIGIN[0] + 150, ORIGIN[1])
        )
