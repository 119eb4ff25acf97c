"""The paper's approximation and bounds on the paper's own kind of terrain."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from support.independent import load_raster, sees

from urpt_gcs.bench.paper import paper_instance, random_targets, tin_terrain
from urpt_gcs.solvers import SOLVERS, SolveSettings, solve
from urpt_gcs.solvers.approx import paper_path


def _as_geotiff(terrain, path: Path) -> Path:
    z = terrain.elevation_m
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=z.shape[1],
        height=z.shape[0],
        count=1,
        dtype="float64",
        crs="EPSG:3857",
        transform=terrain.transform,
    ) as dst:
        dst.write(z, 1)
    return path


@pytest.mark.parametrize(
    ("seed", "m", "fov"), [(0, 4, 20.0), (1, 6, 30.0), (2, 8, 40.0), (3, 6, 20.0)]
)
def test_approx_sees_every_target_and_respects_the_bounds(
    tmp_path: Path, seed: int, m: int, fov: float
) -> None:
    terrain = tin_terrain(seed)
    targets = random_targets(seed, m)
    inst = paper_instance(terrain, targets, fov, 20)
    approx = solve(inst, "approx")
    optimum = solve(inst, "exact")
    _, bounds = paper_path(inst)
    # Independently: every target is in the cone and in sight of some stop of the tour.
    raster = load_raster(_as_geotiff(terrain, tmp_path / "tin.tif"))
    to_geo = pyproj.Transformer.from_crs("EPSG:3857", "EPSG:4326", always_xy=True)
    lon_t, lat_t = to_geo.transform(targets[:, 0], targets[:, 1])
    lon_s, lat_s = to_geo.transform(approx.points_xy[:, 0], approx.points_xy[:, 1])
    for k in range(m):
        assert any(
            sees(raster, (lat_t[k], lon_t[k]), (lat_s[j], lon_s[j], 125.0), fov)[0]
            for j in range(len(lon_s))
        ), f"target {k} unseen"
    # The flown tour shortcuts the paper's path, which the theorem bounds.
    assert approx.length <= bounds.path_length_m + 1e-6
    assert bounds.path_length_m <= bounds.factor * optimum.length
    assert approx.lower_bound <= optimum.length + 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_lower_bound_optimum_heuristic_order(seed: int) -> None:
    terrain = tin_terrain(10 + seed)
    inst = paper_instance(terrain, random_targets(10 + seed, 6), 30.0, 20)
    exact = solve(inst, "exact")
    name = "heuristic" if "heuristic" in SOLVERS else "ortools"
    heuristic = solve(inst, name, SolveSettings(time_limit_s=0.5, seed=seed))
    assert exact.lower_bound <= exact.length + 1e-9
    assert exact.length <= heuristic.length + 1e-9
    for tour in (exact, heuristic):
        assert inst.uncovered(list(tour.order)) == []
    assert np.all(exact.sees.any(axis=0))


@pytest.mark.parametrize("seed", range(3))
def test_disjoint_discs_are_the_greedy_choice_pairwise_apart_and_maximal(seed: int) -> None:
    """The discs the packing bound counts are the ones greedy in index order takes (written
    out pair by pair here), no two within twice the radius, and no other disc fits."""
    from urpt_gcs.bound.geometric import greedy_disjoint

    rng = np.random.default_rng(seed)
    pts = rng.uniform(0.0, 500.0, (600, 2))
    radius = 12.0
    want: list[int] = []
    for i, c in enumerate(pts):
        if all(np.hypot(*(c - pts[j])) > 2.0 * radius for j in want):
            want.append(i)
    got = greedy_disjoint(pts, radius)
    assert got == want
    chosen = pts[got]
    gaps = np.hypot(*(chosen[:, None, :] - chosen[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() > 2.0 * radius
    others = np.delete(pts, got, axis=0)
    assert (
        np.hypot(*(others[:, None, :] - chosen[None, :, :]).transpose(2, 0, 1)).min(axis=1)
        <= 2 * radius
    ).all()
