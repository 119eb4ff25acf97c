"""Reading a DEM's pixels into a :class:`~urpt_gcs.site.terrain.Terrain`.

Only a window is ever read: :func:`read_terrain` takes the area of interest in the planning
CRS. A raster whose CRS is not the planning CRS keeps its own pixels (no resampling, so its
bilinear surface is exactly the source's) and gets the affine map from its pixels to the
planning CRS that fits the true projection over the window, to a small fraction of a cell
(checked on read).

:func:`read_mosaic` reads only the source blocks that camera cones touch, :func:`fill_along`
adds the blocks a leg crosses later, and :func:`area_max` finds the highest ground of an area
block by block; a :class:`BlockCache` keeps any block from being decompressed twice.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import numpy.typing as npt
import pyproj
import rasterio
import rasterio.errors
import rasterio.io
import rasterio.warp
import rasterio.windows
from affine import Affine

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.errors import DemError
from urpt_gcs.memory import require_memory
from urpt_gcs.site.dem import DemInfo, clean_elevations, first_line, open_raster
from urpt_gcs.site.terrain import ElevationArray, Terrain, bilinear_at

__all__ = [
    "BlockCache",
    "PixelBoxes",
    "area_max",
    "fill_along",
    "pixel_boxes",
    "read_mosaic",
    "read_terrain",
    "sample_points",
]


def read_terrain(
    info: DemInfo, crs: pyproj.CRS, area: tuple[float, float, float, float]
) -> Terrain:
    """Read the part of the DEM covering ``area`` = (xmin, ymin, xmax, ymax) in ``crs``.

    Parameters
    ----------
    info
        The raster, from :func:`open_dem`.
    crs
        The planning CRS, from :func:`planning_crs`.
    area
        Box to cover, in ``crs``. Parts outside the raster are simply absent (NaN when
        sampled).

    Returns
    -------
    Terrain
        The elevations of the window in metres; nodata as NaN.
    """
    try:
        if info.needs_warp or crs != info.horizontal_crs:
            return _read_warped(info, crs, area)
        return _read_native(info, area)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc


def _window_for(
    info: DemInfo, src_crs_area: tuple[float, float, float, float], pad_px: int
) -> rasterio.windows.Window:
    xmin, ymin, xmax, ymax = src_crs_area
    inv = ~info.transform
    c_a, r_a = inv @ (xmin, ymax)
    c_b, r_b = inv @ (xmax, ymin)
    c0 = max(math.floor(min(c_a, c_b)) - pad_px, 0)
    c1 = min(math.ceil(max(c_a, c_b)) + pad_px, info.width_px)
    r0 = max(math.floor(min(r_a, r_b)) - pad_px, 0)
    r1 = min(math.ceil(max(r_a, r_b)) + pad_px, info.height_px)
    return rasterio.windows.Window(c0, r0, max(c1 - c0, 0), max(r1 - r0, 0))


def _read_window(
    info: DemInfo, area: tuple[float, float, float, float]
) -> tuple[rasterio.windows.Window, FloatArray]:
    """The window of the raster covering ``area`` (in the raster's CRS) and its elevations."""
    window = _window_for(info, area, pad_px=2)
    if window.width == 0 or window.height == 0:
        raise DemError(
            f"DEM '{info.path}' does not cover the targets' area: check that the targets "
            "belong to this site"
        )
    # The cells as read, as float64 elevations, and the nodata mask.
    per_cell = np.dtype(info.dtype).itemsize + 8 + 1
    require_memory(
        float(window.width) * float(window.height) * per_cell,
        f"DEM '{info.path}': the window of {int(window.width)} x {int(window.height)} cells "
        "around the targets",
        "plan targets that lie closer together, or lower --altitude/--clearance",
    )
    with open_raster(info.path) as src:
        band = src.read(info.band, window=window, masked=True)
    return window, clean_elevations(
        np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m
    )


def _window_px(window: rasterio.windows.Window) -> tuple[int, int, int, int]:
    return (int(window.col_off), int(window.row_off), int(window.width), int(window.height))


def _read_native(info: DemInfo, area: tuple[float, float, float, float]) -> Terrain:
    window, z = _read_window(info, area)
    return Terrain(
        elevation_m=z,
        transform=rasterio.windows.transform(window, info.transform),
        crs=info.horizontal_crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
    )


def _read_warped(
    info: DemInfo, crs: pyproj.CRS, area: tuple[float, float, float, float]
) -> Terrain:
    src_area = rasterio.warp.transform_bounds(crs, info.horizontal_crs, *area, densify_pts=21)
    window, z = _read_window(info, src_area)
    transform, error_m = _fit_affine(info, crs, window)
    terrain = Terrain(
        elevation_m=z,
        transform=transform,
        crs=crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
    )
    if error_m > max(0.05 * terrain.cell_m, 0.005):
        raise DemError(
            f"DEM '{info.path}' is in {info.horizontal_crs.name} and the targets spread too far "
            f"to plan in one flat map ({error_m:.2f} m distortion): reproject the DEM to "
            "the local UTM zone (gdalwarp -t_srs) or plan fewer targets at a time"
        )
    return terrain


def _fit_affine(
    info: DemInfo, crs: pyproj.CRS, window: rasterio.windows.Window
) -> tuple[Affine, float]:
    """Least-squares affine map from window pixels to ``crs``, and its worst error in metres."""
    cols = np.linspace(0.0, float(window.width), 7)
    rows = np.linspace(0.0, float(window.height), 7)
    cc, rr = (a.ravel() for a in np.meshgrid(cols, rows))
    t = info.transform
    sx = t.a * (cc + window.col_off) + t.b * (rr + window.row_off) + t.c
    sy = t.d * (cc + window.col_off) + t.e * (rr + window.row_off) + t.f
    to_crs = pyproj.Transformer.from_crs(info.horizontal_crs, crs, always_xy=True)
    x, y = to_crs.transform(sx, sy)
    design = np.column_stack([cc, rr, np.ones_like(cc)])
    (a, b, c), *_ = np.linalg.lstsq(design, np.asarray(x), rcond=None)
    (d, e, f), *_ = np.linalg.lstsq(design, np.asarray(y), rcond=None)
    fitted = design @ np.array([[a, d], [b, e], [c, f]])
    error = float(np.max(np.hypot(fitted[:, 0] - x, fitted[:, 1] - y)))
    return Affine(float(a), float(b), float(c), float(d), float(e), float(f)), error


# Boxes in source pixels: (col0, row0, col1, row1), ends exclusive.
PixelBoxes = npt.NDArray[np.int64]


def _storage_dtype(info: DemInfo) -> type[np.floating[Any]]:
    """float32 when it holds every source value exactly in metres, else float64."""
    exact32 = np.dtype(info.dtype) in (
        np.dtype(t) for t in ("float32", "int16", "uint16", "int8", "uint8")
    )
    return np.float32 if exact32 and not info.vertical_unit.converted else np.float64


def _block_shape(src: rasterio.io.DatasetReader, band: int) -> tuple[int, int]:
    bh, bw = src.block_shapes[band - 1]
    # A striped raster (one row per block) is read in squares of our own: a strip is cached
    # by GDAL once decompressed, and squares keep the count of read cells near the windows.
    if bh < 64 or bw < 64:
        return 256, 256
    return int(bh), int(bw)


def pixel_boxes(
    info: DemInfo, crs: pyproj.CRS, boxes: npt.ArrayLike, pad_px: int = 2
) -> PixelBoxes:
    """Source-pixel boxes, clipped to the raster, covering boxes (xmin, ymin, xmax, ymax) in
    ``crs`` with ``pad_px`` cells more on every side."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    xs = b[:, [0, 2, 0, 2]]
    ys = b[:, [1, 1, 3, 3]]
    if info.needs_warp or crs != info.horizontal_crs:
        to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
        xs, ys = (np.asarray(v).reshape(-1, 4) for v in to_src.transform(xs, ys))
    inv = ~info.transform
    cols = inv.a * xs + inv.b * ys + inv.c
    rows = inv.d * xs + inv.e * ys + inv.f
    out = np.column_stack(
        [
            np.floor(cols.min(axis=1)) - pad_px,
            np.floor(rows.min(axis=1)) - pad_px,
            np.ceil(cols.max(axis=1)) + pad_px,
            np.ceil(rows.max(axis=1)) + pad_px,
        ]
    )
    limits = np.array([info.width_px, info.height_px, info.width_px, info.height_px])
    clipped: PixelBoxes = np.clip(out, 0, limits).astype(np.int64)
    return clipped


class BlockCache:
    """What the altitude search has learnt of a DEM's blocks, so that none is decompressed twice.

    For every block read it keeps the block's maximum and its row and column maxima (enough
    for the exact maximum of a box that cuts the block on one axis only), and the cells of
    a block a box cuts on both axes or that lies in a camera cone; :func:`read_mosaic` takes
    the cone blocks from here instead of reading them again. Mutable, owned by one plan.
    """

    def __init__(self, info: DemInfo) -> None:
        self.info = info
        self.block_px: tuple[int, int] | None = None
        self.maxima: dict[tuple[int, int], tuple[float, FloatArray, FloatArray]] = {}
        self.cells: dict[tuple[int, int], ElevationArray] = {}
        self.decompressed = 0
        self.again = 0

    def block_window(self, j: int, i: int) -> tuple[int, int, int, int]:
        """Block (row j, column i)'s source cells (col0, row0, col1, row1), clipped."""
        assert self.block_px is not None
        bh, bw = self.block_px
        return (
            i * bw,
            j * bh,
            min((i + 1) * bw, self.info.width_px),
            min((j + 1) * bh, self.info.height_px),
        )


def _block_cells(
    info: DemInfo, src: rasterio.io.DatasetReader, window: tuple[int, int, int, int]
) -> ElevationArray:
    c0, r0, c1, r1 = window
    band = src.read(
        info.band, window=rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0), masked=True
    )
    z = clean_elevations(np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m)
    return z.astype(_storage_dtype(info), copy=False)


def _top(z: npt.NDArray[np.floating[Any]], axis: int | None = None) -> Any:
    """Maximum over valid cells; -inf where there are none."""
    return np.where(np.isfinite(z), z, -np.inf).max(axis=axis, initial=-np.inf)


def area_max(
    info: DemInfo,
    crs: pyproj.CRS,
    area: tuple[float, float, float, float],
    cache: BlockCache | None = None,
    keep: npt.ArrayLike | None = None,
    workers: int | None = 1,
) -> float:
    """The highest valid elevation (metres) in ``area``; NaN when the area holds none.

    Blocks are decompressed by ``workers`` threads (None: one per core), each with its own
    handle on the file, and with a ``cache`` each only once over successive calls: a block
    already read contributes its recorded maxima. The cells of blocks that boxes ``keep``
    (xmin, ymin, xmax, ymax in ``crs``) touch are kept in the cache for :func:`read_mosaic`;
    other blocks' cells are dropped once their maxima are known, unless the area cuts them on
    both axes (a later, wider area needs their exact maximum).
    """
    cache = BlockCache(info) if cache is None else cache
    box = [int(v) for v in pixel_boxes(info, crs, [area])[0]]
    keep_px = np.zeros((0, 4), dtype=np.int64) if keep is None else pixel_boxes(info, crs, keep)
    top = -math.inf
    try:
        if cache.block_px is None:
            with open_raster(info.path) as src:
                cache.block_px = _block_shape(src, info.band)
        bh, bw = cache.block_px
        # (key, block window, cut on columns, cut on rows, cells kept) per block in the area.
        blocks = []
        for j in range(box[1] // bh, -(-box[3] // bh)):
            for i in range(box[0] // bw, -(-box[2] // bw)):
                c0, r0, c1, r1 = cache.block_window(j, i)
                a, b = max(c0, box[0]), max(r0, box[1])
                c, d = min(c1, box[2]), min(r1, box[3])
                if c <= a or d <= b:
                    continue
                cut_cols, cut_rows = (a, c) != (c0, c1), (b, d) != (r0, r1)
                kept = bool(
                    (
                        (keep_px[:, 0] < c1)
                        & (keep_px[:, 2] > c0)
                        & (keep_px[:, 1] < r1)
                        & (keep_px[:, 3] > r0)
                    ).any()
                )
                blocks.append(((j, i), (c0, r0, c1, r1), cut_cols, cut_rows, kept))
        # A block first seen uncut on an axis is cut on both only when the area shrinks,
        # which the altitude search never does.
        todo = [
            (key, window, kept or (cut_cols and cut_rows))
            for key, window, cut_cols, cut_rows, kept in blocks
            if key not in cache.maxima or (cache.cells.get(key) is None and cut_cols and cut_rows)
        ]
        for key, maxima, z in _decompress(info, todo, workers):
            cache.again += key in cache.maxima
            cache.decompressed += 1
            cache.maxima[key] = maxima
            if z is not None:
                cache.cells[key] = z
        for key, (c0, r0, c1, r1), cut_cols, cut_rows, kept in blocks:
            a, b = max(c0, box[0]), max(r0, box[1])
            c, d = min(c1, box[2]), min(r1, box[3])
            whole, col_top, row_top = cache.maxima[key]
            z = cache.cells.get(key)
            if cut_cols and cut_rows:
                assert z is not None
                here = float(_top(z[b - r0 : d - r0, a - c0 : c - c0]))
            elif cut_cols:
                here = float(col_top[a - c0 : c - c0].max())
            elif cut_rows:
                here = float(row_top[b - r0 : d - r0].max())
            else:
                here = whole
            top = max(top, here)
            if not (kept or (cut_cols and cut_rows)):
                cache.cells.pop(key, None)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    return top if math.isfinite(top) else math.nan


_Maxima = tuple[float, FloatArray, FloatArray]


def _decompress(
    info: DemInfo,
    todo: list[tuple[tuple[int, int], tuple[int, int, int, int], bool]],
    workers: int | None,
) -> list[tuple[tuple[int, int], _Maxima, ElevationArray | None]]:
    """Each block of ``todo`` (key, window, whether its cells are kept) decompressed: its
    maxima, and its cells where kept. The blocks are shared among threads in runs, each
    run read through a handle of its own (GDAL releases the interpreter while it
    decompresses); a block's cells not kept are dropped as soon as its maxima are known."""

    def run(part: list[tuple[tuple[int, int], tuple[int, int, int, int], bool]]) -> list[Any]:
        done = []
        with open_raster(info.path) as src:
            for key, window, kept in part:
                z = _block_cells(info, src, window)
                done.append((key, (float(_top(z)), _top(z, 0), _top(z, 1)), z if kept else None))
        return done

    if not todo:
        return []
    parts = _in_threads(lambda part: run([todo[k] for k in part.tolist()]), len(todo), workers)
    return [item for got in parts for item in got]


def read_mosaic(
    info: DemInfo, crs: pyproj.CRS, boxes: npt.ArrayLike, cache: BlockCache | None = None
) -> Terrain:
    """Read only the source blocks that boxes (xmin, ymin, xmax, ymax) in ``crs`` touch.

    The result spans the boxes' union; cells of blocks no box touches are NaN (unknown
    ground), never an elevation. Each block is read once, however many boxes touch it, and
    only one block's float64 copy is alive at a time; a block whose cells ``cache`` holds
    (kept by :func:`area_max`) is taken from it and not read again.

    Raises
    ------
    DemError
        When the boxes miss the raster, or the file cannot be read.
    MemoryBudgetError
        When the union's grid would not fit the memory budget.
    """
    px = pixel_boxes(info, crs, boxes)
    px = px[(px[:, 2] > px[:, 0]) & (px[:, 3] > px[:, 1])]
    if len(px) == 0:
        raise DemError(
            f"DEM '{info.path}' does not cover the targets' area: check that the targets "
            "belong to this site"
        )
    c0, r0 = int(px[:, 0].min()), int(px[:, 1].min())
    c1, r1 = int(px[:, 2].max()), int(px[:, 3].max())
    dtype = _storage_dtype(info)
    require_memory(
        float(c1 - c0) * float(r1 - r0) * np.dtype(dtype).itemsize,
        f"DEM '{info.path}': the grid of {c1 - c0} x {r1 - r0} cells spanning the targets' "
        "camera cones",
        "plan targets that lie closer together, or lower --altitude/--clearance",
    )
    window = rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0)
    try:
        with open_raster(info.path) as src:
            bh, bw = _block_shape(src, info.band)
            if cache is not None and cache.block_px not in (None, (bh, bw)):
                raise ValueError("read_mosaic: the cache was filled with other blocks")
            mask = np.zeros(
                ((r1 - 1) // bh - r0 // bh + 1, (c1 - 1) // bw - c0 // bw + 1), dtype=np.bool_
            )
            for a, b, c, d in (px - np.array([c0 // bw * bw, r0 // bh * bh] * 2)).tolist():
                mask[b // bh : (d - 1) // bh + 1, a // bw : (c - 1) // bw + 1] = True
            z = np.full((r1 - r0, c1 - c0), np.nan, dtype=dtype)
            _read_blocks(info, src, z, window, (bh, bw), mask, cache)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    if info.needs_warp or crs != info.horizontal_crs:
        transform, error_m = _fit_affine(info, crs, window)
    else:
        transform, error_m = rasterio.windows.transform(window, info.transform), 0.0
    terrain = Terrain(
        elevation_m=z,
        transform=transform,
        crs=crs if info.needs_warp or crs != info.horizontal_crs else info.horizontal_crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
        block_px=(bh, bw),
        blocks_read=mask,
    )
    if error_m > max(0.05 * terrain.cell_m, 0.005):
        raise DemError(
            f"DEM '{info.path}' is in {info.horizontal_crs.name} and the targets spread too far "
            f"to plan in one flat map ({error_m:.2f} m distortion): reproject the DEM to "
            "the local UTM zone (gdalwarp -t_srs) or plan fewer targets at a time"
        )
    return terrain


def _read_blocks(
    info: DemInfo,
    src: rasterio.io.DatasetReader,
    z: ElevationArray,
    window: rasterio.windows.Window,
    block_px: tuple[int, int],
    todo: npt.NDArray[np.bool_],
    cache: BlockCache | None = None,
) -> None:
    """Read the blocks ``todo`` marks into the grid ``z`` of ``window``, one at a time,
    taking (and dropping) from ``cache`` those whose cells it holds."""
    bh, bw = block_px
    c0, r0 = int(window.col_off), int(window.row_off)
    c1, r1 = c0 + int(window.width), r0 + int(window.height)
    first_r, first_c = r0 // bh * bh, c0 // bw * bw
    for j, i in np.argwhere(todo).tolist():
        br, bc = first_r + j * bh, first_c + i * bw
        a, b = max(bc, c0), max(br, r0)
        c, d = min(bc + bw, c1), min(br + bh, r1)
        if c <= a or d <= b:
            continue
        key = (br // bh, bc // bw)
        held = None if cache is None else cache.cells.pop(key, None)
        if held is not None:
            z[b - r0 : d - r0, a - c0 : c - c0] = held[b - br : d - br, a - bc : c - bc]
            continue
        if cache is not None:
            cache.again += key in cache.maxima
            cache.decompressed += 1
        band = src.read(info.band, window=rasterio.windows.Window(a, b, c - a, d - b), masked=True)
        z[b - r0 : d - r0, a - c0 : c - c0] = clean_elevations(
            np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m
        )


def fill_along(info: DemInfo, terrain: Terrain, start_xy: FloatArray, end_xy: FloatArray) -> int:
    """Read into a mosaic from :func:`read_mosaic`, in place, the blocks that straight
    segments (within its grid) cross and it does not hold yet; return how many.

    Known ground only grows: every result computed on the terrain before stays valid.
    """
    if terrain.blocks_read is None:
        return 0
    a = np.asarray(start_xy, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(end_xy, dtype=np.float64).reshape(-1, 2)
    ca, ra = terrain.pixel_coords(a[:, 0], a[:, 1])
    cb, rb = terrain.pixel_coords(b[:, 0], b[:, 1])
    # Samples at most _STEP_PX apart, each widened by half a step and the bilinear support,
    # so every cell a segment's surface depends on lies in some sample's box.
    steps = np.maximum(np.ceil(np.hypot(cb - ca, rb - ra) / _STEP_PX), 1).astype(np.int64)
    k = np.repeat(np.arange(len(a)), steps + 1)
    # 0, 1/n, ..., 1 along each segment of n steps, all segments at once.
    first = np.cumsum(steps + 1) - (steps + 1)
    j = np.arange(k.size) - first[k]
    t = j * (1.0 / steps[k])
    t[j == steps[k]] = 1.0
    cols = ca[k] + t * (cb - ca)[k]
    rows = ra[k] + t * (rb - ra)[k]
    keep = np.isfinite(cols) & np.isfinite(rows)
    cols, rows = cols[keep], rows[keep]
    bh, bw = terrain.block_px
    c0, r0, width, height = terrain.read_window_px
    phase_c, phase_r = c0 - c0 // bw * bw, r0 - r0 // bh * bh
    todo = np.zeros_like(terrain.blocks_read)
    jmax, imax = todo.shape[0] - 1, todo.shape[1] - 1
    reach = _STEP_PX / 2.0 + 2.0
    for dc in (-reach, reach):
        for dr in (-reach, reach):
            cc = np.clip(cols + dc, 0, width - 1) + phase_c
            rr = np.clip(rows + dr, 0, height - 1) + phase_r
            i = np.clip((cc // bw).astype(np.intp), 0, imax)
            j = np.clip((rr // bh).astype(np.intp), 0, jmax)
            todo[j, i] = True
    todo &= ~terrain.blocks_read
    count = int(todo.sum())
    if count:
        window = rasterio.windows.Window(c0, r0, width, height)
        try:
            with open_raster(info.path) as src:
                _read_blocks(info, src, terrain.elevation_m, window, (bh, bw), todo)
        except rasterio.errors.RasterioError as exc:
            raise DemError(
                f"DEM '{info.path}' could not be read ({first_line(exc)}): "
                "the file may be truncated; export it again"
            ) from exc
        terrain.blocks_read[todo] = True
    return count


_STEP_PX = 32.0


def sample_points(
    info: DemInfo, crs: pyproj.CRS, xy: FloatArray, workers: int | None = 1
) -> FloatArray:
    """Bilinear ground elevation (metres) at points in ``crs``, each from the few cells
    around it; NaN off the raster or next to nodata. ``workers`` threads (None: one per
    core) share the points, each reading through a handle of its own."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    sx, sy = pts[:, 0], pts[:, 1]
    if info.needs_warp or crs != info.horizontal_crs:
        to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
        sx, sy = (np.asarray(v, dtype=np.float64) for v in to_src.transform(sx, sy))
    inv = ~info.transform
    cols = inv.a * sx + inv.b * sy + inv.c
    rows = inv.d * sx + inv.e * sy + inv.f
    out = np.full(len(pts), np.nan)

    def run(part: IntArray) -> None:
        with open_raster(info.path) as src:
            for k in part.tolist():
                if not (np.isfinite(cols[k]) and np.isfinite(rows[k])):
                    continue
                c0 = max(math.floor(cols[k]) - 2, 0)
                r0 = max(math.floor(rows[k]) - 2, 0)
                c1 = min(math.floor(cols[k]) + 3, info.width_px)
                r1 = min(math.floor(rows[k]) + 3, info.height_px)
                if c1 <= c0 or r1 <= r0:
                    continue
                window = rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0)
                band = src.read(info.band, window=window, masked=True)
                z = clean_elevations(
                    np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m
                )
                out[k] = bilinear_at(z, cols[k] - c0 - 0.5, rows[k] - r0 - 0.5)

    try:
        _in_threads(run, len(pts), workers)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    return out


# Below this many items per thread, reading them in threads costs more than it saves.
_LEAST_PER_THREAD = 16


def _in_threads(run: Callable[[IntArray], Any], count: int, workers: int | None) -> list[Any]:
    """``run`` over the indices ``0 .. count``, shared among up to ``workers`` threads
    (None: one per core) as interleaved parts; their results in part order."""
    cores = max(1, os.cpu_count() or 1) if workers is None else max(1, workers)
    threads = min(cores, max(count // _LEAST_PER_THREAD, 1))
    index = np.arange(count, dtype=np.int64)
    if threads <= 1:
        return [run(index)]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(run, [index[k::threads] for k in range(threads)]))
