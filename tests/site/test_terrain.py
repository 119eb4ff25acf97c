"""Reading DEMs: only the window a plan needs, any nodata masked, any CRS made metric."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from conftest import DEMO, REAL_DEMS, WriteDem, needs_shared
from rasterio.transform import from_origin
from rasterio.windows import Window

from urpt_gcs.errors import DemError
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.site.dem import (
    check_elevations,
    crs_label,
    open_dem,
    planning_crs,
    scale_error,
    vertical_unit,
)
from urpt_gcs.site.reading import read_terrain
from urpt_gcs.solvers import SolveSettings

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


@needs_shared(REAL_DEMS)
def test_compound_crs_without_epsg_plans_in_its_horizontal_part() -> None:
    info = open_dem(REAL_DEMS / "codem_aoi_dsm_utm16n_egm2008.tif")
    assert info.crs.to_epsg() is None and info.crs.is_compound
    assert not info.needs_warp
    assert info.horizontal_crs.to_epsg() == 32616


@needs_shared(REAL_DEMS)
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


# Exact definitions: the international foot is 0.3048 m, the US survey foot 1200/3937 m.
FOOT_M = 0.3048
US_SURVEY_FOOT_M = 1200.0 / 3937.0
UTM32_WKT1 = pyproj.CRS.from_epsg(32632).to_wkt("WKT1_GDAL")


def _compound_wkt(unit: str) -> str:
    return f'COMPD_CS["test",{UTM32_WKT1},VERT_CS["h",VERT_DATUM["d",2005],{unit},AXIS["Up",UP]]]'


@pytest.mark.parametrize(
    ("crs", "name", "to_m", "declared"),
    [
        ("EPSG:32632", "metre", 1.0, False),
        ("EPSG:32632+3855", "metre", 1.0, True),
        ("EPSG:32632+8228", "foot", FOOT_M, True),
        ("EPSG:32632+6360", "US survey foot", US_SURVEY_FOOT_M, True),
        ("EPSG:2229+6360", "US survey foot", US_SURVEY_FOOT_M, True),
        ("EPSG:4979", "metre", 1.0, True),
        (_compound_wkt('UNIT["furlong",201.168]'), "furlong", 201.168, True),
        # A datum shift bound to the CRS (how GDAL reads +towgs84): the axes are the source's.
        ("+proj=utm +zone=32 +ellps=intl +towgs84=1,2,3 +vunits=ft", "foot", FOOT_M, True),
    ],
)
def test_vertical_unit_is_read_from_the_crs(
    crs: str, name: str, to_m: float, declared: bool
) -> None:
    unit = vertical_unit(pyproj.CRS(crs), "dem.tif")
    assert unit.name == name
    assert unit.to_m == pytest.approx(to_m, rel=1e-12)
    assert unit.declared is declared


@pytest.mark.parametrize(
    ("unit", "words"),
    [
        ('UNIT["unknown",1]', "an unknown unit"),
        ('UNIT["degree",0.0174532925199433]', "'degree', not a length"),
    ],
)
def test_vertical_unit_that_is_not_a_known_length_is_refused(unit: str, words: str) -> None:
    with pytest.raises(DemError, match=r"DEM 'x\.tif' declares its heights in") as caught:
        vertical_unit(pyproj.CRS(_compound_wkt(unit)), "x.tif")
    message = str(caught.value)
    assert words in message and "-a_srs EPSG:32632+" in message
    assert "\n" not in message


@pytest.mark.parametrize(
    ("crs", "unit_m"), [("EPSG:32632+8228", FOOT_M), ("EPSG:32632+6360", US_SURVEY_FOOT_M)]
)
def test_heights_in_feet_are_converted_to_metres(
    write_dem: WriteDem, crs: str, unit_m: float
) -> None:
    rng = np.random.default_rng(1)
    # 7500 m and -900 m are valid ground; in feet both lie outside [-1000, 9000].
    metres = rng.uniform(100.0, 200.0, (40, 40))
    metres[0, 0], metres[0, 1] = 7500.0, -900.0
    metres[5, 5] = -10000.0  # stays nodata: the fill value is compared before conversion
    stored = np.where(metres == -10000.0, -10000.0, metres / unit_m)
    path = write_dem(stored, crs=crs, origin=ORIGIN, res=1.0, dtype="float64")
    info = open_dem(path)
    assert info.vertical_unit.declared and info.vertical_unit.converted
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 40.0, ORIGIN[0] + 40.0, ORIGIN[1])
    )
    want = np.where(metres == -10000.0, np.nan, metres)
    # read_terrain pads the window; the whole 40 x 40 raster is inside it.
    assert terrain.read_window_px == (0, 0, 40, 40)
    np.testing.assert_allclose(terrain.elevation_m, want, rtol=1e-12, equal_nan=True)


def test_dem_without_vertical_crs_stays_in_metres(write_dem: WriteDem) -> None:
    path = write_dem(np.full((20, 20), 420.0), origin=ORIGIN, res=1.0)
    info = open_dem(path)
    assert not info.vertical_unit.declared and not info.vertical_unit.converted
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 20.0, ORIGIN[0] + 20.0, ORIGIN[1])
    )
    assert np.nanmax(terrain.elevation_m) == 420.0


def _area(crs: pyproj.CRS, lon: float, lat: float, half_m: float) -> tuple[float, ...]:
    x, y = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(lon, lat)
    return (x - half_m, y - half_m, x + half_m, y + half_m)


def test_scale_error_tells_web_mercator_from_utm() -> None:
    at_site = (9.42, 47.70, 9.43, 47.71)
    # UTM's scale 0.9996 on its central meridian: off by 0.04 %, below the 0.1 % limit.
    assert scale_error(pyproj.CRS.from_epsg(32632), at_site) == pytest.approx(3.9e-4, abs=2e-5)
    # Mercator's scale is 1 / cos(latitude) (on the sphere; the ellipsoid adds ~0.2 %).
    mercator = scale_error(pyproj.CRS.from_epsg(3857), at_site)
    assert mercator == pytest.approx(1.0 / math.cos(math.radians(47.705)) - 1.0, rel=0.01)
    # Plate carree is exact along meridians and stretched along parallels: still refused.
    assert scale_error(pyproj.CRS.from_epsg(32662), at_site) > 0.4


def _web_mercator_dem(write_dem: WriteDem, lon: float, lat: float) -> Path:
    """A 200 x 200 px DEM in EPSG:3857, 1 unit per pixel, whose north-west corner is at
    (lon, lat); a ramp rising 1 m per pixel to the east."""
    x0, y0 = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(
        lon, lat
    )
    ramp = np.tile(np.arange(200.0), (200, 1)) + 300.0
    return write_dem(ramp, crs="EPSG:3857", origin=(x0, y0), res=1.0)


def test_web_mercator_dem_is_planned_in_utm_with_true_lengths(write_dem: WriteDem) -> None:
    lon, lat = 9.42, 47.70
    info = open_dem(_web_mercator_dem(write_dem, lon, lat))
    assert not info.needs_warp  # metric and projected, but not true to scale here
    crs = planning_crs(info, (lon, lat - 0.001, lon + 0.002, lat))
    assert crs.to_epsg() == 32632
    terrain = read_terrain(info, crs, _area(crs, lon + 0.001, lat - 0.0005, 40.0))
    # The source's 1-unit pixel spans cos(47.7 deg) m on the ground (times UTM's 0.9996):
    # the cell must be the true size, not the Mercator one.
    cos_lat = math.cos(math.radians(lat))
    assert terrain.cell_m == pytest.approx(0.9996 * cos_lat, rel=2e-3)
    # And the ramp rises 1 m per source pixel, i.e. 1 / (0.9996 cos lat) per UTM metre.
    x, y = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(
        lon + 0.001, lat - 0.0005
    )
    z = terrain.sample(np.array([x, x + 10.0]), np.array([y, y]))
    assert (z[1] - z[0]) / 10.0 == pytest.approx(1.0 / (0.9996 * cos_lat), rel=3e-3)


def test_utm_dem_beside_its_central_meridian_is_planned_natively() -> None:
    info = open_dem(DEMO / "site.tif")
    crs = planning_crs(info, (9.42, 47.68, 9.43, 47.69))
    assert crs == info.horizontal_crs


def test_web_mercator_dem_across_utm_zones_is_refused(write_dem: WriteDem) -> None:
    info = open_dem(_web_mercator_dem(write_dem, 5.999, 47.7))
    with pytest.raises(DemError, match=r"Pseudo-Mercator, whose scale at the site is off by 4"):
        planning_crs(info, (5.999, 47.699, 6.001, 47.7))


@pytest.mark.parametrize(
    ("bounds", "zones"),
    [
        ((5.999, 47.699, 6.001, 47.7), "UTM zones 31N and 32N"),
        ((-179.999, 47.699, 179.999, 47.7), "the antimeridian (UTM zones 60N and 1N)"),
    ],
)
def test_points_across_zones_are_refused_naming_their_own_zones(
    write_dem: WriteDem, bounds: tuple[float, float, float, float], zones: str
) -> None:
    info = open_dem(_web_mercator_dem(write_dem, 5.999, 47.7))
    with pytest.raises(DemError, match=re.escape(f"straddle {zones}:")):
        planning_crs(info, bounds)


def _renamed(code: str, name: str) -> pyproj.CRS:
    """A CRS of its own name and no authority code, as a surveyor's site grid."""
    document = pyproj.CRS(code).to_json_dict()
    document["name"] = name
    document.pop("id")
    return pyproj.CRS.from_json_dict(document)


@pytest.mark.parametrize(
    ("crs", "label"),
    [
        ("EPSG:32632", "WGS 84 / UTM zone 32N"),
        (
            "+proj=tmerc +lat_0=47 +lon_0=9.4 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m",
            "a custom Transverse Mercator CRS",
        ),
        ("+proj=longlat +ellps=GRS80", "a custom geographic CRS"),
        (_renamed("EPSG:2056", "Site grid"), "Site grid"),
    ],
)
def test_a_crs_is_named_in_one_short_line_never_as_its_wkt(
    crs: str | pyproj.CRS, label: str
) -> None:
    assert crs_label(pyproj.CRS(crs)) == label
    code_first = crs_label(pyproj.CRS(crs), code_first=True)
    assert code_first == (crs if crs == "EPSG:32632" else label)


def test_state_plane_feet_dem_is_georeferenced_in_utm(write_dem: WriteDem) -> None:
    """NAD83 / California zone 5 (ftUS): warped like a geographic DEM, heights left in metres
    (no vertical CRS), each source pixel where pyproj puts it."""
    lon, lat = -118.25, 34.05
    to_sp = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:2229", always_xy=True)
    x0, y0 = to_sp.transform(lon, lat)
    rng = np.random.default_rng(2)
    z = rng.uniform(50.0, 80.0, (120, 120))
    path = write_dem(z, crs="EPSG:2229", origin=(x0, y0), res=2.0)  # 2 ftUS pixels
    info = open_dem(path)
    assert info.needs_warp and not info.vertical_unit.converted
    crs = planning_crs(info, (lon, lat - 0.0005, lon + 0.0005, lat))
    assert crs.to_epsg() == 32611
    terrain = read_terrain(info, crs, _area(crs, lon + 0.0004, lat - 0.0004, 25.0))
    assert terrain.cell_m == pytest.approx(2.0 * US_SURVEY_FOOT_M, rel=2e-3)
    to_utm = pyproj.Transformer.from_crs("EPSG:2229", crs, always_xy=True)
    col0, row0, width, height = terrain.read_window_px
    cols = rng.integers(col0 + 2, col0 + width - 2, 40)
    rows = rng.integers(row0 + 2, row0 + height - 2, 40)
    x, y = to_utm.transform(x0 + 2.0 * (cols + 0.5), y0 - 2.0 * (rows + 0.5))
    np.testing.assert_allclose(terrain.sample(x, y), z[rows, cols], atol=0.05 * 30.0)
    col_f, row_f = terrain.pixel_coords(np.asarray(x), np.asarray(y))
    assert float(np.hypot(col_f - (cols - col0), row_f - (rows - row0)).max()) < 0.05


def _write_bands(path: Path, bands: list[np.ndarray], dtype: str = "float32") -> Path:
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=bands[0].shape[1],
        height=bands[0].shape[0],
        count=len(bands),
        dtype=dtype,
        crs="EPSG:32632",
        nodata=-10000.0,
        transform=from_origin(ORIGIN[0], ORIGIN[1], 1.0, 1.0),
    ) as dst:
        for k, band in enumerate(bands, start=1):
            dst.write(band.astype(dtype), k)
    return path


def test_multiband_dem_needs_a_band_and_reads_that_band(tmp_path: Path) -> None:
    confidence = np.full((30, 30), 0.9)
    height = np.full((30, 30), 250.0)
    path = _write_bands(tmp_path / "two.tif", [confidence, height])
    with pytest.raises(DemError, match=r"two\.tif' has 2 bands: .* --band N \(1 to 2\)"):
        open_dem(path)
    with pytest.raises(DemError, match=r"no band 3: give --band 1 to 2"):
        open_dem(path, band=3)
    info = open_dem(path, band=2)
    assert info.band == 2
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 30.0, ORIGIN[0] + 30.0, ORIGIN[1])
    )
    assert np.nanmin(terrain.elevation_m) == np.nanmax(terrain.elevation_m) == 250.0


def test_single_band_dem_takes_band_1_or_no_band(tmp_path: Path) -> None:
    path = _write_bands(tmp_path / "one.tif", [np.full((10, 10), 5.0)])
    assert open_dem(path).band == open_dem(path, band=1).band == 1
    with pytest.raises(DemError, match=r"has 1 band, so there is no band 2"):
        open_dem(path, band=2)


def test_complex_dem_is_refused(tmp_path: Path) -> None:
    z = np.full((10, 10), 100.0) + 1j * np.full((10, 10), 3.0)
    path = _write_bands(tmp_path / "complex.tif", [z], dtype="complex64")
    with pytest.raises(DemError, match=r"complex\.tif' band 1 holds complex numbers"):
        open_dem(path)


def test_dem_below_the_valid_range_says_so(write_dem: WriteDem) -> None:
    path = write_dem(np.full((20, 20), -1500.0), nodata=-32768.0, origin=ORIGIN, res=1.0)
    with pytest.raises(DemError) as caught:
        check_elevations(open_dem(path))
    message = str(caught.value)
    assert "no elevation in the valid range [-1000, 9000] m" in message
    assert "-1500 to -1500 m" in message and "vertical unit" in message
    assert "every cell is nodata" not in message


def test_all_nodata_dem_says_so(write_dem: WriteDem) -> None:
    path = write_dem(np.full((20, 20), -10000.0), origin=ORIGIN, res=1.0)
    with pytest.raises(DemError, match="every cell is nodata"):
        check_elevations(open_dem(path))


def test_valid_range_applies_to_metres_not_to_stored_feet(write_dem: WriteDem) -> None:
    # 12 000 ft is 3658 m: valid ground, though the stored number is above 9000.
    path = write_dem(np.full((20, 20), 12_000.0), crs="EPSG:32632+8228", origin=ORIGIN, res=1.0)
    check_elevations(open_dem(path))
    # -4000 ft is -1219 m: below the range, reported in metres and in the unit it came from.
    path = write_dem(
        np.full((20, 20), -4000.0), name="low.tif", crs="EPSG:32632+8228", origin=ORIGIN, res=1.0
    )
    with pytest.raises(DemError, match=r"-1219\.2 to -1219\.2 m, converted from foot"):
        check_elevations(open_dem(path))


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("dem_not_georeferenced.tif", "no coordinate reference system"),
        ("dem_without_geotransform.tif", "no geotransform"),
    ],
)
def test_a_raster_without_georeferencing_is_refused_without_a_warning(
    name: str, words: str
) -> None:
    path = Path(__file__).resolve().parents[1] / "data" / "bad" / name
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DemError, match=words):
            open_dem(path)
