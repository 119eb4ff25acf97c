"""Tests for urpt_gcs.problem.instance and urpt_gcs.visibility.cover: sparse cover sets, the two
distance forms, the memory estimate, the pairs seen on the terrain."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from affine import Affine

from urpt_gcs.memory import MEMORY_BUDGET_ENV, MemoryBudgetError
from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix, require_instance_memory
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.cover import cover_pairs, cover_sets
from urpt_gcs.visibility.regions import Camera


def _half_metre_grid(z: np.ndarray) -> Terrain:
    """``z`` on 0.5 m cells, its north-west corner at (0, rows / 2) in UTM 32N."""
    rows, cols = z.shape
    return Terrain(
        elevation_m=z,
        transform=Affine(0.5, 0.0, 0.0, 0.0, -0.5, rows / 2.0),
        crs=pyproj.CRS.from_epsg(32632),
        source="random",
        read_window_px=(0, 0, cols, rows),
        source_shape_px=(rows, cols),
    )


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
    # Linear in the viewpoints and in the pairs that see: 20 000 viewpoints once needed a
    # 3 GiB distance matrix; 370 000 (10 000 targets at 36 samples) seeing 30 targets each
    # take under 200 MB.
    require_instance_memory(20_000, 300_000)
    require_instance_memory(370_000, 11_100_000)
    with pytest.raises(
        MemoryBudgetError, match=r"4000000 viewpoints \(80000000 .* 1\.37 GiB, .* --samples"
    ):
        require_instance_memory(4_000_000, 80_000_000)


def test_cover_sets_on_threads_equal_the_serial_ones() -> None:
    """Sharing the line-of-sight tests among threads changes no answer."""
    rng = np.random.default_rng(5)
    z = 100.0 + 8.0 * rng.random((300, 300))
    z[100:110, :] = 140.0
    z[200:205, 50:60] = np.nan
    terrain = _half_metre_grid(z)
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
    vp, tg = cover_pairs(terrain, viewpoints, targets, ground, camera, workers=4)
    pairs = np.column_stack([vp, tg])[np.lexsort((tg, vp))]
    np.testing.assert_array_equal(np.argwhere(serial), pairs)


def test_covers_round_trip_dense_pairs_and_rows() -> None:
    rng = np.random.default_rng(3)
    dense = rng.random((40, 9)) < 0.3
    dense[rng.integers(0, 40, 9), np.arange(9)] = True
    covers = Covers.from_dense(dense)
    assert np.array_equal(covers.dense(), dense)
    vp, tg = covers.pairs()
    assert np.array_equal(np.column_stack([vp, tg]), np.argwhere(dense))
    shuffled = rng.permutation(len(vp))
    again = Covers.from_pairs(np.r_[vp[shuffled], vp], np.r_[tg[shuffled], tg], 40, 9)
    assert np.array_equal(again.ptr, covers.ptr) and np.array_equal(again.target, covers.target)
    rows = [5, 0, 5, 39]
    assert np.array_equal(covers.dense(rows), dense[rows])
    assert np.array_equal(covers.seen(rows), dense[rows].any(axis=0))
    assert np.array_equal(covers.per_target(), dense.sum(axis=0))
    assert np.array_equal(covers.per_viewpoint(), dense.sum(axis=1))
    for t in range(9):
        assert np.array_equal(covers.viewpoints_of(t), np.flatnonzero(dense[:, t]))


def _explicit_and_plane(seed: int, depot: bool) -> tuple[Instance, Instance]:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 500, (30, 2))
    vp = np.r_[np.arange(30), rng.integers(0, 30, 20)]
    tg = np.r_[np.arange(30) % 8, rng.integers(0, 8, 20)]
    home = (250.0, -40.0) if depot else None
    plane = Instance.from_cover_pairs(vp, tg, xy, 8, depot_xy=home)
    explicit = Instance(
        covers=plane.covers,
        distance=euclidean_matrix(xy),
        depot_distance=plane.depot_distance,
        points_xy=xy,
        depot_xy=home,
    )
    return explicit, plane


@pytest.mark.parametrize("depot", [False, True])
def test_explicit_and_plane_instances_give_the_same_lengths(depot: bool) -> None:
    explicit, plane = _explicit_and_plane(1, depot)
    assert plane.distance is None and plane.explicit is False
    rng = np.random.default_rng(0)
    for _ in range(20):
        order = rng.permutation(30)[: rng.integers(1, 30)]
        assert plane.tour_length(order) == pytest.approx(explicit.tour_length(order), rel=1e-12)
        assert plane.uncovered(order) == explicit.uncovered(order)
    assert np.array_equal(plane.matrix(), explicit.matrix())
    assert plane.nbytes() < explicit.nbytes()


@pytest.mark.parametrize("solver", ["exact", "heuristic", "ortools"])
@pytest.mark.parametrize("depot", [False, True])
def test_solvers_agree_on_explicit_and_plane_forms(solver: str, depot: bool) -> None:
    from urpt_gcs.solvers import SolveSettings, solve

    explicit, plane = _explicit_and_plane(2, depot)
    settings = SolveSettings(time_limit_s=2.0 if solver == "ortools" else 10.0, seed=0)
    a = solve(explicit, solver, settings)
    b = solve(plane, solver, settings)
    assert b.length == pytest.approx(a.length, rel=1e-9)
    assert b.length == pytest.approx(plane.tour_length(b.order), rel=1e-12)


def test_cover_pairs_in_chunks_are_every_pair_in_sight_and_refuse_over_budget(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Gathered a chunk of viewpoints at a time, the pairs are exactly those within the cone
    whose line of sight clears (tested pair by pair here); a budget too small for them is
    refused with the figure before the chunk that would pass it is kept."""
    import urpt_gcs.visibility.cover as gtsp
    from urpt_gcs.visibility.regions import line_of_sight

    rng = np.random.default_rng(8)
    z = 100.0 + 6.0 * rng.random((200, 200))
    z[90:95, :] = 135.0
    terrain = _half_metre_grid(z)
    targets = rng.uniform(10.0, 90.0, (25, 2))
    ground = terrain.sample(targets[:, 0], targets[:, 1])
    viewpoints = rng.uniform(0.0, 100.0, (700, 2))
    camera = Camera(altitude_m=150.0, fov_deg=25.0)
    cone = camera.cone_radius_m(ground)
    want = set()
    for i, (vx, vy) in enumerate(viewpoints):
        for t in range(len(targets)):
            if np.hypot(vx - targets[t, 0], vy - targets[t, 1]) <= cone[t]:
                eye = np.array([[vx, vy, camera.altitude_m]])
                tgt = np.array([[targets[t, 0], targets[t, 1], ground[t]]])
                if line_of_sight(terrain, eye, tgt)[0]:
                    want.add((i, t))
    monkeypatch.setattr(gtsp, "_PAIR_CHUNK_VIEWPOINTS", 64)
    vp, tg = cover_pairs(terrain, viewpoints, targets, ground, camera)
    assert len(want) > 500
    assert set(zip(vp.tolist(), tg.tolist(), strict=True)) == want
    assert len(vp) == len(want)
    gib = (700 * 48 + 16 * len(want) / 2) / 2**30
    monkeypatch.setenv(MEMORY_BUDGET_ENV, f"{gib:.12f}")
    with pytest.raises(MemoryBudgetError, match=r"700 viewpoints \(\d+ viewpoint-target pairs\)"):
        cover_pairs(terrain, viewpoints, targets, ground, camera)
