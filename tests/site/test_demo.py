"""The demo site: a usable Pix4D-like DSM, and targets some of which walls partly hide."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import defusedxml.ElementTree as DET
import numpy as np
import pytest
import rasterio
from numpy.typing import NDArray
from pyproj import Transformer

from urpt_gcs.site.demo import DemoSite, make_demo_site

KML = "{http://www.opengis.net/kml/2.2}"
CLEARANCE_M = 30.0  # flight plane above the highest valid cell
HALF_ANGLE_DEG = 30.0
AZIMUTHS = 36
HIDDEN_REACH = 0.7  # "partly hidden": reach below this share of the cone radius ...
HIDDEN_AZIMUTHS = 3  # ... on at least this many azimuths


@dataclass(frozen=True)
class Raster:
    dem: NDArray[np.float64]  # nodata as NaN
    x0: float
    y0: float
    res: float


@dataclass(frozen=True)
class Placemark:
    name: str
    x: float
    y: float
    coords_text: str


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> DemoSite:
    return make_demo_site(tmp_path_factory.mktemp("demo"))


@pytest.fixture(scope="module")
def raster(site: DemoSite) -> Raster:
    with rasterio.open(site.dsm_path) as src:
        dem = src.read(1).astype(np.float64)
        dem[dem == src.nodata] = np.nan
        return Raster(dem, src.transform.c, src.transform.f, src.transform.a)


@pytest.fixture(scope="module")
def placemarks(site: DemoSite) -> tuple[list[Placemark], list[Placemark]]:
    """Targets in the "Targets" folder, and the other placemarks of the document."""
    to_utm = Transformer.from_crs(4326, site.epsg, always_xy=True)
    document = DET.parse(site.targets_path).getroot().find(f"{KML}Document")

    def read(elements: list[object]) -> list[Placemark]:
        out = []
        for pm in elements:
            text = pm.find(f"{KML}Point/{KML}coordinates").text.strip()  # type: ignore[attr-defined]
            lon, lat, _ = (float(v) for v in text.split(","))
            x, y = to_utm.transform(lon, lat)
            out.append(Placemark(pm.find(f"{KML}name").text, x, y, text))  # type: ignore[attr-defined]
        return out

    (folder,) = [
        f for f in document.findall(f"{KML}Folder") if f.findtext(f"{KML}name") == "Targets"
    ]
    return read(folder.findall(f"{KML}Placemark")), read(document.findall(f"{KML}Placemark"))


def bilinear(r: Raster, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    col, row = (x - r.x0) / r.res - 0.5, (r.y0 - y) / r.res - 0.5
    c0 = np.clip(np.floor(col).astype(int), 0, r.dem.shape[1] - 2)
    r0 = np.clip(np.floor(row).astype(int), 0, r.dem.shape[0] - 2)
    fc, fr = col - c0, row - r0
    d = r.dem
    top = d[r0, c0] * (1 - fc) + d[r0, c0 + 1] * fc
    bottom = d[r0 + 1, c0] * (1 - fc) + d[r0 + 1, c0 + 1] * fc
    return top * (1 - fr) + bottom * fr  # type: ignore[no-any-return]


def visible_reach(
    r: Raster, x: float, y: float, flight_m: float
) -> tuple[NDArray[np.float64], float]:
    """Per azimuth, the horizontal distance at which the first camera position is blocked.

    The camera positions lie on the flight plane inside the cone of half-angle 30° above the
    target; a position is blocked if the DSM rises above the straight line to it (sampled
    every 0.25 m or finer; nodata never blocks). Returns the reaches and the cone radius.
    """
    z = float(bilinear(r, np.array(x), np.array(y)))
    radius = (flight_m - z) * math.tan(math.radians(HALF_ANGLE_DEG))
    theta = np.radians(np.arange(AZIMUTHS) * 360.0 / AZIMUTHS)[:, None, None]
    s = np.arange(0.0, radius, 0.5)[None, :, None]
    steps = math.ceil(math.hypot(radius, flight_m - z) / 0.25) + 1
    t = np.linspace(0.0, 1.0, steps)[None, None, :]
    terrain = bilinear(r, x + t * s * np.cos(theta), y + t * s * np.sin(theta))
    blocked = np.any(terrain > z + t * (flight_m - z) + 1e-3, axis=2)  # (azimuth, s)
    first = np.argmax(blocked, axis=1)
    reach = np.where(blocked.any(axis=1), s[0, first, 0], radius)
    return reach, radius


def test_raster_is_pix4d_like(site: DemoSite, raster: Raster) -> None:
    with rasterio.open(site.dsm_path) as src:
        assert src.dtypes == ("float32",)
        assert src.nodata == -10000.0
        assert src.crs.is_projected and src.crs.linear_units == "metre"
        assert src.crs.to_epsg() == site.epsg
        assert src.res[0] <= 0.5 and src.res[1] <= 0.5
        assert 900 <= src.width <= 1100 and 900 <= src.height <= 1100
        assert src.block_shapes == [(256, 256)]
        assert src.profile["compress"] == "deflate"
        assert (src.read(1) == -10000.0).any()  # exactly the nodata value, not NaN
    assert site.dsm_path.stat().st_size < 3_000_000
    dem = raster.dem
    nodata = np.isnan(dem)
    assert nodata[0].all() and nodata[-1].all() and nodata[:, 0].all() and nodata[:, -1].all()
    assert not nodata[150:-150, 150:-150].any()
    assert 0.05 < nodata.mean() < 0.35
    valid = dem[~nodata]
    assert valid.min() > 390.0 and valid.max() < 480.0
    assert site.max_elevation_m == pytest.approx(valid.max())


def test_kml_has_targets_and_home(
    site: DemoSite, placemarks: tuple[list[Placemark], list[Placemark]]
) -> None:
    targets, others = placemarks
    assert len(targets) >= 12
    assert len({t.name for t in targets}) == len(targets)
    assert [p.name for p in others] == ["Home"]
    for pm, expected in zip([*targets, *others], [*site.targets, site.home], strict=True):
        assert pm.name == expected.name
        assert all(len(v.split(".")[1]) >= 8 for v in pm.coords_text.split(",")[:2])
        assert math.hypot(pm.x - expected.x_m, pm.y - expected.y_m) < 0.01


def test_points_are_well_inside_the_valid_area(
    raster: Raster, placemarks: tuple[list[Placemark], list[Placemark]]
) -> None:
    rows, cols = np.nonzero(np.isnan(raster.dem))
    nodata_x = raster.x0 + (cols + 0.5) * raster.res
    nodata_y = raster.y0 - (rows + 0.5) * raster.res
    for pm in [*placemarks[0], *placemarks[1]]:
        assert not np.isnan(bilinear(raster, np.array(pm.x), np.array(pm.y))), pm.name
        gap_m = np.hypot(nodata_x - pm.x, nodata_y - pm.y).min()
        assert gap_m >= CLEARANCE_M, f"{pm.name} is {gap_m:.1f} m from nodata"


def test_home_is_on_flat_open_ground(site: DemoSite, raster: Raster) -> None:
    angles = np.linspace(0.0, 2.0 * math.pi, 64)
    ring = np.concatenate([[0.0], np.full(64, 10.0)])
    xs = site.home.x_m + ring * np.concatenate([[1.0], np.cos(angles)])
    ys = site.home.y_m + ring * np.concatenate([[0.0], np.sin(angles)])
    heights = bilinear(raster, xs, ys)
    assert np.ptp(heights) < 1.0


def test_several_targets_are_partly_hidden(site: DemoSite, raster: Raster) -> None:
    flight_m = float(np.nanmax(raster.dem)) + CLEARANCE_M
    hidden = set()
    for target in site.targets:
        reach, radius = visible_reach(raster, target.x_m, target.y_m, flight_m)
        assert (reach > 0.0).all(), f"{target.name}: the nadir point itself is blocked"
        if (reach < HIDDEN_REACH * radius).sum() >= HIDDEN_AZIMUTHS:
            hidden.add(target.name)
    assert len(hidden) >= 4
    assert {t.name for t in site.targets if t.hidden_by} <= hidden


def test_same_seed_same_files(tmp_path: Path, site: DemoSite, raster: Raster) -> None:
    again = make_demo_site(tmp_path / "again", seed=7)
    with rasterio.open(again.dsm_path) as src:
        np.testing.assert_array_equal(src.read(1), np.nan_to_num(raster.dem, nan=-10000.0))
    assert again.targets_path.read_bytes() == site.targets_path.read_bytes()
    other = make_demo_site(tmp_path / "other", seed=8)
    with rasterio.open(other.dsm_path) as src:
        assert not np.array_equal(src.read(1), np.nan_to_num(raster.dem, nan=-10000.0))
