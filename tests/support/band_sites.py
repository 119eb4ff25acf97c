"""Sites for plans inside a height band: a generated ridge and valley, and seeded random
targets on a real raster (the logic of ``benchmarks/band_sites.py``, kept here so the tests
need nothing outside ``tests``)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyproj
import rasterio

__all__ = [
    "RIDGE_CELL_M",
    "RIDGE_ORIGIN",
    "RIDGE_TARGETS_XY",
    "cell_targets_csv",
    "ridge_surface",
    "ridge_targets_csv",
    "seeded_targets_csv",
]

# The generated site: 1.5 km square at 2 m, north-up in UTM 32N (the write_dem fixture's).
RIDGE_CELL_M = 2.0
RIDGE_SIZE = 750
RIDGE_ORIGIN = (500_000.0, 5_200_000.0)
RIDGE_CRS = "EPSG:32632"
# (name, east, south) in metres from the north-west corner: home on the western flat, targets
# in the valley, on both slopes of the ridge, on its crest and on the eastern flat.
RIDGE_TARGETS_XY = (
    ("Home", 100.0, 750.0),
    ("Valley N", 300.0, 400.0),
    ("Valley S", 310.0, 1100.0),
    ("West slope N", 620.0, 500.0),
    ("West slope S", 650.0, 1000.0),
    ("Crest", 800.0, 750.0),
    ("East slope N", 960.0, 420.0),
    ("East slope S", 980.0, 1100.0),
    ("East flat", 1300.0, 750.0),
)


def ridge_surface() -> np.ndarray:
    """Heights (row 0 north) of a north-south ridge 250 m above a 400 m plain, its sides up
    to 50 degrees, with a 50 m deep valley west of it and a gentle swell along it."""
    centres = (np.arange(RIDGE_SIZE) + 0.5) * RIDGE_CELL_M
    east, south = np.meshgrid(centres, centres)
    return (
        400.0
        + 250.0 * np.exp(-(((east - 800.0) / 180.0) ** 2))
        - 50.0 * np.exp(-(((east - 300.0) / 100.0) ** 2))
        + 20.0 * np.sin(south / 200.0)
    )


def ridge_targets_csv(out: Path) -> list[tuple[str, float, float]]:
    """Write the ridge site's targets (name,lat,lon with a Home) and return the targets."""
    to_ll = pyproj.Transformer.from_crs(RIDGE_CRS, "EPSG:4326", always_xy=True)
    rows = []
    for name, east, south in RIDGE_TARGETS_XY:
        lon, lat = to_ll.transform(RIDGE_ORIGIN[0] + east, RIDGE_ORIGIN[1] - south)
        rows.append((name, float(lat), float(lon)))
    _write(out, rows)
    return [r for r in rows if r[0] != "Home"]


def seeded_targets_csv(
    dem: Path,
    count: int,
    seed: int,
    out: Path,
    window_m: float = 3000.0,
    home_lowest: bool = False,
) -> list[tuple[str, float, float]]:
    """Write ``count`` seeded targets on valid cells of a square window of ``window_m``
    around the raster's centre, and a Home at the centre; return the targets.

    With ``home_lowest`` Home is instead the window's lowest valid cell, so every target is
    uphill of it: a vehicle whose simulator knows no terrain (ArduPilot's SITL holds the
    ground flat at home's altitude) can reach every waypoint a band plan writes there."""
    rng = np.random.default_rng(seed)
    with rasterio.open(dem) as src:
        z = src.read(1, masked=True)
        valid = ~np.ma.getmaskarray(z) & np.isfinite(np.ma.getdata(z))
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
        points: list[tuple[str, float, float]] = []
        while len(points) < count:
            r = int(rng.integers(max(r0 - half, 2), min(r0 + half, rows - 2)))
            c = int(rng.integers(max(c0 - half, 2), min(c0 + half, cols - 2)))
            if not valid[r - 2 : r + 3, c - 2 : c + 3].all():
                continue
            lon, lat = to_ll.transform(*src.xy(r, c))
            points.append((f"T{len(points) + 1}", float(lat), float(lon)))
        hr, hc = r0, c0
        if home_lowest:
            r_lo, c_lo = max(r0 - half, 2), max(c0 - half, 2)
            window = np.ma.getdata(z)[
                r_lo : min(r0 + half, rows - 2), c_lo : min(c0 + half, cols - 2)
            ]
            usable = np.zeros(window.shape, dtype=bool)
            for i, j in np.argwhere(np.isfinite(window)):
                r, c = r_lo + int(i), c_lo + int(j)
                usable[i, j] = bool(valid[r - 2 : r + 3, c - 2 : c + 3].all())
            i, j = np.unravel_index(np.where(usable, window, np.inf).argmin(), window.shape)
            hr, hc = r_lo + int(i), c_lo + int(j)
        hlon, hlat = to_ll.transform(*src.xy(hr, hc))
    _write(out, [("Home", float(hlat), float(hlon)), *points])
    return points


def cell_targets_csv(
    dem: Path, home_cell: tuple[int, int], cells: Sequence[tuple[int, int]], out: Path
) -> list[tuple[str, float, float]]:
    """Write a Home at the centre of raster cell ``home_cell`` (row, column) and targets
    ``T1``... at the centres of ``cells``; return the targets."""
    with rasterio.open(dem) as src:
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt())
        to_ll = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        rows = []
        for k, (r, c) in enumerate([home_cell, *cells]):
            lon, lat = to_ll.transform(*src.xy(r, c))
            rows.append(("Home" if k == 0 else f"T{k}", float(lat), float(lon)))
    _write(out, rows)
    return rows[1:]


def _write(out: Path, rows: list[tuple[str, float, float]]) -> None:
    with out.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["name", "lat", "lon"])
        for name, lat, lon in rows:
            w.writerow([name, f"{lat:.9f}", f"{lon:.9f}"])
