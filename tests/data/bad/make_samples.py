"""Regenerate the raster and archive samples of the bad-input catalogue (run from the repo).

    .venv/bin/python tests/data/bad/make_samples.py

Text samples are written by hand; these are binary (or too long to write by hand), so they
are made here.
"""

from __future__ import annotations

import io
import struct
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
    for key in ("crs", "transform"):
        if base[key] is None:
            del base[key]
    with rasterio.open(path, "w", **base) as dst:
        dst.write(z.astype(base["dtype"]), 1)
    return path.read_bytes()


def _set_geokeys(name: str, keys: dict[int, int]) -> None:
    """Set short-valued GeoTIFF keys of a little-endian TIFF written by GDAL, as a writer that
    GDAL would correct might have stored them. The key directory is rewritten at the end of the
    file and its tag pointed there."""
    path = HERE / name
    data = bytearray(path.read_bytes())
    (ifd,) = struct.unpack_from("<I", data, 4)
    (count,) = struct.unpack_from("<H", data, ifd)
    for i in range(count):
        entry = ifd + 2 + 12 * i
        tag, _, n, offset = struct.unpack_from("<HHII", data, entry)
        if tag == 34735:  # GeoKeyDirectoryTag
            break
    old = struct.unpack_from(f"<{n}H", data, offset)
    entries = {old[i]: list(old[i + 1 : i + 4]) for i in range(4, n, 4)}
    entries.update({key: [0, 1, value] for key, value in keys.items()})
    directory = [*old[:3], len(entries)]
    for key in sorted(entries):
        directory += [key, *entries[key]]
    data += b"\0" * (len(data) % 2)
    struct.pack_into("<HHII", data, entry, 34735, 3, len(directory), len(data))
    data += struct.pack(f"<{len(directory)}H", *directory)
    path.write_bytes(data)


def main() -> None:
    flat = np.full((100, 100), 420.0)
    _tif("dem_without_crs.tif", flat, crs=None)
    # As a scanned or exported picture comes: neither CRS nor geotransform.
    _tif("dem_not_georeferenced.tif", flat, crs=None, transform=None, compress="deflate")
    _tif("dem_without_geotransform.tif", flat, transform=None, compress="deflate")
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
    # Flat ground at 100 m in 10 m cells with a wall one pixel wide rising to 165 m, for
    # thin_wall.csv: West and East lie 60 m either side of it.
    wall = np.full((40, 40), 100.0)
    wall[:, 20] = 165.0
    _tif("dem_thin_wall.tif", wall, transform=from_origin(*DEMO_ORIGIN, 10.0, 10.0))
    _tif(
        "dem_complex.tif",
        np.full((100, 100), 420.0) + 1j * np.full((100, 100), 0.5),
        dtype="complex64",
        compress="deflate",
    )
    two = np.stack([np.full((100, 100), 0.9), np.full((100, 100), 420.0)])
    with rasterio.open(
        HERE / "dem_multiband.tif",
        "w",
        driver="GTiff",
        height=100,
        width=100,
        count=2,
        dtype="float32",
        crs="EPSG:32632",
        transform=from_origin(*DEMO_ORIGIN, 5.0, 5.0),
        compress="deflate",
    ) as dst:
        dst.write(two.astype("float32"))
    # A slope with a wrong offset: every value below -1000 m, none of them the fill value.
    _tif(
        "dem_below_minus_1000.tif",
        -1400.0 - 0.5 * np.indices((100, 100))[0],
        nodata=-32768.0,
        compress="deflate",
    )
    # Vertical CRS "user-defined" with VerticalUnitsGeoKey 9102, the EPSG code of the degree.
    _tif("dem_vertical_unit_not_a_length.tif", flat, crs="EPSG:32632+5773", compress="deflate")
    _set_geokeys("dem_vertical_unit_not_a_length.tif", {4096: 32767, 4099: 9102})
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as kmz:
        kmz.writestr("images/readme.txt", "no KML in here\n")
    (HERE / "kmz_without_kml.kmz").write_bytes(buffer.getvalue())
    # Not bad input: 300 targets plan; the planning tests fly them.
    _demo_targets(HERE.parent / "targets" / "demo_300_targets.csv", 300)


def _demo_targets(path: Path, n: int) -> None:
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
    path.write_text("name,lat,lon\n" + "".join(lines))


if __name__ == "__main__":
    main()
