"""Regenerate the raster and archive samples of the bad-input catalogue (run from the repo).

    .venv/bin/python tests/data/bad/make_samples.py

Text samples are written by hand; these are binary (or too long to write by hand), so they
are made here.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pyproj
import rasterio
from numpy.lib.stride_tricks import sliding_window_view
from rasterio.transform import from_origin

HERE = Path(__file__).resolve().parent
DEMO_SITE = HERE.parents[2] / "missions" / "demo" / "site.tif"
DEMO_ORIGIN = (531_500.0, 5_282_200.0)  # the demo site's north-west corner (EPSG:32632)


def _tif(name: str, z: np.ndarray, **profile: object) -> bytes:
    path = HERE / name
    base = {
        "driver": "GTiff",
        "height": z.shape[0],
        "width": z.shape[1],
        "count": 1,
        "dtype": "float32",
        "crs": "EPSG:32632",
        "nodata": -10000.0,
        "transform": from_origin(*DEMO_ORIGIN, 5.0, 5.0),
    }
    base.update(profile)
    if base["crs"] is None:
        del base["crs"]
    with rasterio.open(path, "w", **base) as dst:
        dst.write(z.astype(base["dtype"]), 1)
    return path.read_bytes()


def main() -> None:
    flat = np.full((100, 100), 420.0)
    _tif("dem_without_crs.tif", flat, crs=None)
    _tif("dem_all_nodata.tif", np.full((100, 100), -10000.0))
    _tif(
        "dem_rotated.tif",
        flat,
        transform=from_origin(*DEMO_ORIGIN, 5.0, 5.0) * rasterio.Affine.rotation(15),
    )
    good = _tif(
        "dem_truncated.tif",
        np.random.default_rng(0).uniform(400, 450, (300, 300)),
        tiled=True,
        blockxsize=64,
        blockysize=64,
    )
    (HERE / "dem_truncated.tif").write_bytes(good[:4096])  # header and tile index only
    (HERE / "dem_empty.tif").write_bytes(b"")
    # Geographic, 5.9-6.1 E: across the edge between UTM zones 31 and 32.
    _tif(
        "dem_geographic_across_utm_zones.tif",
        np.full((200, 200), 300.0),
        crs="EPSG:4326",
        transform=from_origin(5.9, 47.1, 0.001, 0.001),
    )
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as kmz:
        kmz.writestr("images/readme.txt", "no KML in here\n")
    (HERE / "kmz_without_kml.kmz").write_bytes(buffer.getvalue())
    _demo_targets("demo_300_targets.csv", 300)


def _demo_targets(name: str, n: int) -> None:
    """``n`` targets at random on the demo site, each amid valid cells (3 cells to nodata)."""
    with rasterio.open(DEMO_SITE) as src:
        valid = src.read_masks(1) > 0
        transform, crs = src.transform, src.crs
    inner = np.zeros_like(valid)
    inner[3:-3, 3:-3] = sliding_window_view(valid, (7, 7)).all(axis=(2, 3))
    rows, cols = np.nonzero(inner)
    pick = np.random.default_rng(1).choice(len(rows), n, replace=False)
    x, y = transform * (cols[pick] + 0.5, rows[pick] + 0.5)
    to_wgs84 = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon, lat = to_wgs84.transform(x, y)
    points = enumerate(zip(lat, lon, strict=True), start=1)
    lines = [f"T{i},{a:.9f},{o:.9f}\n" for i, (a, o) in points]
    (HERE / name).write_text("name,lat,lon\n" + "".join(lines))


if __name__ == "__main__":
    main()
