"""Seeded random targets on a real raster, for the height-band benchmark.

``python benchmarks/band_sites.py DEM COUNT SEED OUT.csv [--window M]`` writes COUNT targets
(name,lat,lon) at random valid cells of a square window of M metres (default 3000) around
the raster's centre, and a Home at the window's centre.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np
import pyproj
import rasterio


def write_targets(dem: Path, count: int, seed: int, out: Path, window_m: float = 3000.0) -> None:
    """Write ``count`` seeded targets on valid cells around the raster's centre."""
    rng = np.random.default_rng(seed)
    with rasterio.open(dem) as src:
        z = src.read(1, masked=True)
        valid = ~np.ma.getmaskarray(z)
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt())
        to_ll = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        rows, cols = z.shape
        if crs.is_geographic:
            lat0 = src.xy(rows // 2, cols // 2)[1]
            cell_m = abs(src.transform.a) * 111_320.0 * math.cos(math.radians(lat0))
        else:
            cell_m = abs(src.transform.a)
        half = int(window_m / cell_m / 2)
        r0, c0 = rows // 2, cols // 2
        points: list[tuple[float, float]] = []
        while len(points) < count:
            r = int(rng.integers(max(r0 - half, 2), min(r0 + half, rows - 2)))
            c = int(rng.integers(max(c0 - half, 2), min(c0 + half, cols - 2)))
            if not valid[r - 2 : r + 3, c - 2 : c + 3].all():
                continue
            x, y = src.xy(r, c)
            lon, lat = to_ll.transform(x, y)
            points.append((lat, lon))
        hx, hy = src.xy(r0, c0)
        hlon, hlat = to_ll.transform(hx, hy)
    with out.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["name", "lat", "lon"])
        w.writerow(["Home", f"{hlat:.8f}", f"{hlon:.8f}"])
        for i, (lat, lon) in enumerate(points, start=1):
            w.writerow([f"T{i}", f"{lat:.8f}", f"{lon:.8f}"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("dem", type=Path)
    parser.add_argument("count", type=int)
    parser.add_argument("seed", type=int)
    parser.add_argument("out", type=Path)
    parser.add_argument("--window", type=float, default=3000.0)
    a = parser.parse_args()
    write_targets(a.dem, a.count, a.seed, a.out, a.window)


if __name__ == "__main__":
    main()
