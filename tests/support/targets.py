"""Target lists for tests: the names and positions of a target file, and random targets on
valid ground of a raster."""

from __future__ import annotations

import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyproj
import rasterio

from support.independent import load_raster
from urpt_gcs.site.targets import read_targets

# The real rasters beside the checkout that plans are tried on: the raster, how many
# targets, and the width of the box they are kept to (None: the whole raster).
REAL_CASES = [
    ("odm_dsm_utm51n.tif", 10, None),
    ("codem_aoi_dsm_utm16n_egm2008.tif", 10, None),
    ("pysheds_dem_wgs84.tif", 8, 2000.0),
    ("dsm2dtm_drone_dsm_wgs84.tif", 6, None),
]


def write_kmz(path: Path, members: Mapping[str, bytes]) -> Path:
    """A KMZ (a zip) at ``path`` holding ``members`` (name in the archive -> bytes)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def kml_targets(path: Path) -> list[tuple[str, float, float]]:
    ts = read_targets(path)
    return [(t.name, t.lat_deg, t.lon_deg) for t in ts.targets]


def valid_targets(
    dem: Path, count: int, seed: int, box_m: float | None = None, margin_px: int = 12
) -> list[tuple[str, float, float]]:
    """Targets on valid ground: pixels whose neighbourhood is all data (test-side choice)."""
    raster = load_raster(dem)
    z = raster.z
    ok = np.isfinite(z)
    # A pixel qualifies if a (2*margin+1) square around it is all valid.
    pad = np.pad(ok, margin_px, constant_values=False).astype(np.int32)
    integral = pad.cumsum(0).cumsum(1)
    integral = np.pad(integral, ((1, 0), (1, 0)))
    k = 2 * margin_px + 1
    window = integral[k:, k:] - integral[:-k, k:] - integral[k:, :-k] + integral[:-k, :-k]
    good = window == k * k
    rows, cols = np.nonzero(good)
    with rasterio.open(dem) as src:
        transform, crs = src.transform, pyproj.CRS.from_wkt(src.crs.to_wkt())
    if crs.is_compound:
        crs = crs.sub_crs_list[0]
    to_geo = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    rng = np.random.default_rng(seed)
    if box_m is not None:
        # Keep to a box around a random qualifying pixel (for rasters of many kilometres).
        c = rng.integers(len(rows))
        cell_m = box_m / abs(transform.a) if crs.is_projected else box_m / 90.0
        near = (np.abs(rows - rows[c]) < cell_m) & (np.abs(cols - cols[c]) < cell_m)
        rows, cols = rows[near], cols[near]
    pick = rng.choice(len(rows), size=count, replace=False)
    out = []
    for n, i in enumerate(pick, start=1):
        x, y = transform @ (cols[i] + 0.5, rows[i] + 0.5)
        lon, lat = to_geo.transform(x, y)
        out.append((f"T{n}", float(lat), float(lon)))
    return out
