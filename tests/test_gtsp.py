"""Tests for urpt_gcs.gtsp: the dense parts of an instance."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from affine import Affine

from urpt_gcs.gtsp import cover_sets, euclidean_matrix, require_instance_memory
from urpt_gcs.inputs import MEMORY_BUDGET_ENV, MemoryBudgetError
from urpt_gcs.terrain import Terrain
from urpt_gcs.visibility import Camera


@pytest.mark.parametrize("n", [0, 1, 7, 3000])
def test_euclidean_matrix_in_blocks_equals_the_dense_formula(n: int) -> None:
    xy = np.random.default_rng(n).uniform(-1e4, 1e4, (n, 2))
    diff = xy[:, None, :] - xy[None, :, :]
    dense = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    assert np.array_equal(euclidean_matrix(xy), dense)


def test_instance_memory_is_refused_naming_viewpoints_and_fix(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "1")
    require_instance_memory(10_000, 300)
    with pytest.raises(MemoryBudgetError, match=r"20000 viewpoints .* 3\.00 GiB, .* --samples"):
        require_instance_memory(20_000, 300)


def test_cover_sets_on_threads_equal_the_serial_ones() -> None:
    """Sharing the line-of-sight tests among threads changes no answer."""
    rng = np.random.default_rng(5)
    z = 100.0 + 8.0 * rng.random((300, 300))
    z[100:110, :] = 140.0
    z[200:205, 50:60] = np.nan
    terrain = Terrain(
        elevation_m=z,
        transform=Affine(0.5, 0.0, 0.0, 0.0, -0.5, 150.0),
        crs=pyproj.CRS.from_epsg(32632),
        source="random",
        read_window_px=(0, 0, 300, 300),
        source_shape_px=(300, 300),
    )
    targets = rng.uniform(10.0, 140.0, (60, 2))
    ground = terrain.sample(targets[:, 0], targets[:, 1])
    keep = np.isfinite(ground)
    targets, ground = targets[keep], ground[keep]
    viewpoints = rng.uniform(0.0, 150.0, (3000, 2))
    camera = Camera(altitude_m=160.0, fov_deg=30.0)
    serial = cover_sets(terrain, viewpoints, targets, ground, camera, workers=1)
    threaded = cover_sets(terrain, viewpoints, targets, ground, camera, workers=4)
    assert serial.sum() > 100
    np.testing.assert_array_equal(serial, threaded)
