"""Sparse reads: only the blocks the cones touch, the rest unknown, legs filled in later."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from urpt_gcs.site.dem import open_dem
from urpt_gcs.site.reading import BlockCache, area_max, fill_along, read_mosaic, read_terrain
from urpt_gcs.visibility.segments import segment_profile

ORIGIN = (500_000.0, 5_200_000.0)
RES = 0.5


def _tiled(tmp_path: Path, size: int = 1024) -> Path:
    rows, cols = np.mgrid[0:size, 0:size]
    z = (300.0 + 0.01 * rows + 5.0 * np.sin(cols / 37.0)).astype("float32")
    z[500:520, 500:520] = -10000.0
    path = tmp_path / "tiled.tif"
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
        blockxsize=256,
        blockysize=256,
        compress="deflate",
        transform=from_origin(ORIGIN[0], ORIGIN[1], RES, RES),
    ) as dst:
        dst.write(z, 1)
    return path


def _box(col: float, row: float, half_px: float) -> list[float]:
    x, y = ORIGIN[0] + col * RES, ORIGIN[1] - row * RES
    h = half_px * RES
    return [x - h, y - h, x + h, y + h]


def test_mosaic_reads_touched_blocks_and_leaves_the_rest_unknown(tmp_path: Path) -> None:
    info = open_dem(_tiled(tmp_path))
    crs = info.horizontal_crs
    terrain = read_mosaic(info, crs, [_box(100, 100, 20), _box(900, 900, 20)])
    full = read_terrain(info, crs, (ORIGIN[0], ORIGIN[1] - 512.0, ORIGIN[0] + 512.0, ORIGIN[1]))
    assert terrain.elevation_m.dtype == np.float32
    assert terrain.blocks_read is not None and terrain.blocks_read.sum() == 2
    c0, r0, w, h = terrain.read_window_px
    mosaic = terrain.elevation_m.astype(np.float64)
    same = full.elevation_m[r0 : r0 + h, c0 : c0 + w]
    known = np.isfinite(mosaic)
    # What was read is the source exactly; what was not is unknown, never an elevation.
    np.testing.assert_array_equal(mosaic[known], same[known])
    assert np.isnan(terrain.sample(ORIGIN[0] + 500 * RES, ORIGIN[1] - 100 * RES))
    # The two corner blocks, as far as they lie inside the grid spanning both boxes.
    assert known.sum() == (256 - c0) * (256 - r0) + (c0 + w - 768) * (r0 + h - 768)

    a = np.array([[ORIGIN[0] + 100 * RES, ORIGIN[1] - 100 * RES]])
    b = np.array([[ORIGIN[0] + 900 * RES, ORIGIN[1] - 900 * RES]])
    seg = (np.column_stack([a, [400.0]]), np.column_stack([b, [400.0]]))
    assert segment_profile(terrain, *seg).unknown_fraction[0] > 0.5
    added = fill_along(info, terrain, a, b)
    assert added >= 2
    filled = segment_profile(terrain, *seg)
    exact = segment_profile(full, *seg)
    assert filled.excess_m[0] == exact.excess_m[0]
    assert filled.unknown_fraction[0] == exact.unknown_fraction[0]
    assert fill_along(info, terrain, a, b) == 0


def test_area_max_is_the_highest_valid_cell(tmp_path: Path) -> None:
    info = open_dem(_tiled(tmp_path))
    crs = info.horizontal_crs
    area = (ORIGIN[0] + 10.0, ORIGIN[1] - 400.0, ORIGIN[0] + 300.0, ORIGIN[1] - 20.0)
    want = float(np.nanmax(read_terrain(info, crs, area).elevation_m))
    got = area_max(info, crs, area)
    # read_terrain pads its window by two cells; area_max reads the area's cells only.
    assert want - 0.05 <= got <= want


@pytest.mark.parametrize("workers", [1, 3])
def test_growing_areas_and_the_mosaic_decompress_each_block_once(
    tmp_path: Path, workers: int
) -> None:
    """The altitude search's passes and the mosaic share one cache: the same maxima and cells
    as reading afresh, and no block is decompressed twice, whatever the threads."""
    info = open_dem(_tiled(tmp_path))
    crs = info.horizontal_crs
    cache = BlockCache(info)
    centre = (ORIGIN[0] + 230.0, ORIGIN[1] - 260.0)
    cones = [_box(300, 400, 40), _box(700, 650, 30)]
    for half_m in (15.0, 60.0, 130.0, 250.0):
        area = (centre[0] - half_m, centre[1] - half_m, centre[0] + half_m, centre[1] + half_m)
        assert area_max(info, crs, area, cache, cones, workers) == area_max(info, crs, area)
    assert cache.again == 0
    seen = cache.decompressed
    assert 0 < len(cache.cells) < seen
    fresh = read_mosaic(info, crs, cones)
    shared = read_mosaic(info, crs, cones, cache)
    np.testing.assert_array_equal(shared.elevation_m, fresh.elevation_m)
    assert cache.again == 0
    # Both cones lie inside the last area: their blocks come from the cache.
    assert cache.decompressed == seen
