"""Terrain: the elevations of a DEM window in a metric projected CRS, and their bilinear surface.

A :class:`Terrain` is what :mod:`urpt_gcs.site.reading` returns from a DEM opened by
:mod:`urpt_gcs.site.dem`; the visibility and flight stages only sample it. NaN marks no data:
any bilinear sample touching it is NaN, "unknown ground" to every caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyproj
from affine import Affine
from numba import njit

from urpt_gcs.arrays import FloatArray

__all__ = ["ElevationArray", "Terrain", "bilinear_at"]

# Elevations as stored: float32 where that holds the source's values exactly, else float64.
ElevationArray = npt.NDArray[np.float32] | npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Terrain:
    """Elevations of a raster window georeferenced in a projected, metric CRS.

    ``transform`` maps (col, row) of a pixel corner to (x, y) in ``crs``; it is north-up for a
    projected source and a fitted affine map for a geographic one. NaN marks no data.
    ``read_window_px`` is the window read from the source raster (col_off, row_off, width,
    height) and ``source_shape_px`` the source's (height, width), so what was read can be
    reported.

    A terrain read by :func:`~urpt_gcs.site.reading.read_mosaic` is sparse: only the source's
    blocks that some window touches are read, and every other cell is NaN, unknown ground like
    nodata. ``blocks_read`` then says which source blocks (``block_px`` = (height, width) each,
    counted from the block holding the window's first cell) hold data, so that
    :func:`~urpt_gcs.site.reading.fill_along` can add the blocks a leg crosses later.
    """

    elevation_m: ElevationArray
    transform: Affine
    crs: pyproj.CRS
    source: str
    read_window_px: tuple[int, int, int, int]
    source_shape_px: tuple[int, int]
    block_px: tuple[int, int] = (0, 0)
    blocks_read: npt.NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        if self.elevation_m.ndim != 2 or self.elevation_m.dtype not in (np.float32, np.float64):
            raise ValueError("Terrain.elevation_m must be a 2-D float32 or float64 array")
        if abs(self.transform.determinant) < 1e-12:
            raise ValueError("Terrain.transform must be invertible")

    @property
    def cell_m(self) -> float:
        """The shorter side of a pixel, in metres."""
        t = self.transform
        return float(min(math.hypot(t.a, t.d), math.hypot(t.b, t.e)))

    def pixel_coords(self, x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (col, row) of points, with pixel centres at whole numbers."""
        inv = ~self.transform
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        col = inv.a * xa + inv.b * ya + inv.c - 0.5
        row = inv.d * xa + inv.e * ya + inv.f - 0.5
        return col, row

    def sample(self, x: npt.ArrayLike, y: npt.ArrayLike) -> FloatArray:
        """Bilinear elevation at points (x, y); NaN outside the grid or next to nodata.

        Pixel values sit at pixel centres. Between the outermost centres and the grid edge
        the edge value is used.
        """
        col, row = self.pixel_coords(x, y)
        rows, cols = self.elevation_m.shape
        inside = (col >= -0.5) & (col <= cols - 0.5) & (row >= -0.5) & (row <= rows - 0.5)
        col = np.clip(np.where(inside, col, 0.0), 0.0, cols - 1.0)
        row = np.clip(np.where(inside, row, 0.0), 0.0, rows - 1.0)
        c0 = np.minimum(np.floor(col).astype(np.intp), max(cols - 2, 0))
        r0 = np.minimum(np.floor(row).astype(np.intp), max(rows - 2, 0))
        c1 = np.minimum(c0 + 1, cols - 1)
        r1 = np.minimum(r0 + 1, rows - 1)
        fc = col - c0
        fr = row - r0
        z = self.elevation_m
        top = z[r0, c0] * (1.0 - fc) + z[r0, c1] * fc
        bottom = z[r1, c0] * (1.0 - fc) + z[r1, c1] * fc
        out = top * (1.0 - fr) + bottom * fr
        return np.where(inside, out, np.nan)


@njit(cache=True, nogil=True)
def bilinear_at(z, col, row):  # type: ignore[no-untyped-def]
    """The surface at fractional (col, row) of ``z`` (pixel centres at whole numbers), as
    :meth:`Terrain.sample` gives it: the edge value beyond the outermost centres, NaN outside
    the grid or when any of the four corners is nodata. Compiled, for kernels and single
    points alike."""
    rows, cols = z.shape
    if not (-0.5 <= col <= cols - 0.5 and -0.5 <= row <= rows - 0.5):
        return math.nan
    col = min(max(col, 0.0), cols - 1.0)
    row = min(max(row, 0.0), rows - 1.0)
    c0 = min(math.floor(col), max(cols - 2, 0))
    r0 = min(math.floor(row), max(rows - 2, 0))
    c1, r1 = min(c0 + 1, cols - 1), min(r0 + 1, rows - 1)
    fc, fr = col - c0, row - r0
    top = z[r0, c0] * (1.0 - fc) + z[r0, c1] * fc
    bottom = z[r1, c0] * (1.0 - fc) + z[r1, c1] * fc
    return top * (1.0 - fr) + bottom * fr
