"""Visibility regions against terrains whose answer is known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import WriteDem, grid_xy
from hypothesis import given, settings
from hypothesis import strategies as st

from urpt_gcs.errors import SettingsError
from urpt_gcs.site.dem import open_dem
from urpt_gcs.site.reading import read_terrain
from urpt_gcs.visibility.regions import (
    Camera,
    azimuths,
    line_of_sight,
    ray_reach,
    visibility_regions,
)

ORIGIN = (500_000.0, 5_200_000.0)
RES = 0.5
SHAPE = (400, 400)  # 200 m x 200 m
CENTER = (ORIGIN[0] + 100.0, ORIGIN[1] - 100.0)


def _terrain(write_dem: WriteDem, z: np.ndarray):
    path = write_dem(z, res=RES, origin=ORIGIN)
    info = open_dem(path)
    return read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 200.0, ORIGIN[0] + 200.0, ORIGIN[1])
    )


def test_flat_ground_gives_the_cone_disc(write_dem: WriteDem) -> None:
    terrain = _terrain(write_dem, np.full(SHAPE, 100.0))
    camera = Camera(altitude_m=150.0, fov_deg=30.0)
    (region,) = visibility_regions(terrain, np.array([CENTER]), np.array([100.0]), camera, 36)
    radius = 50.0 * math.tan(math.radians(30.0))
    assert np.allclose(region.reach_m, radius, atol=RES)
    # The interpolated polygon of 36 rays is the inscribed 36-gon of that disc.
    inscribed = 0.5 * 36 * radius**2 * math.sin(2 * math.pi / 36)
    assert region.polygon.area == pytest.approx(inscribed, rel=0.02)


@pytest.mark.parametrize("fov", [20.0, 30.0, 40.0])
def test_wall_cuts_the_disc_where_it_hides_the_target(write_dem: WriteDem, fov: float) -> None:
    """Target at x=0 on flat ground; a wall of height hw occupies 4 <= x <= 9 m."""
    x, _ = grid_xy(SHAPE, RES, ORIGIN)
    z = np.full(SHAPE, 100.0)
    wall_near, wall_far, wall_h = 4.0, 9.0, 30.0
    rel = x - CENTER[0]
    z[(rel >= wall_near) & (rel <= wall_far)] = 100.0 + wall_h
    terrain = _terrain(write_dem, z)
    altitude = 150.0
    camera = Camera(altitude_m=altitude, fov_deg=fov)
    az = azimuths(72)
    reach = ray_reach(terrain, np.array([CENTER]), np.array([100.0]), camera, az)[0]
    h = altitude - 100.0
    cone = h * math.tan(math.radians(fov))
    for theta, got in zip(az, reach, strict=True):
        c = math.cos(theta)
        # Independent closed form: the wall's near top edge at horizontal distance
        # edge / cos(theta) blocks every point beyond h * edge / (wall_h * cos). The raster
        # places that edge to within one cell of where the wall was drawn.
        if c <= 1e-9:
            assert got == pytest.approx(cone, abs=1e-6), math.degrees(theta)
            continue
        low = min(cone, h * (wall_near - RES) / (wall_h * c))
        high = min(cone, h * (wall_near + RES) / (wall_h * c))
        assert low - 1e-6 <= got <= high + 1e-6, math.degrees(theta)
    # Towards the wall the region is cut well inside the cone; away from it, it is not.
    assert reach[0] < 0.5 * cone
    assert reach[36] == pytest.approx(cone, abs=RES)


def test_terrain_above_the_plane_beyond_the_drone_does_not_hide_the_target(
    write_dem: WriteDem,
) -> None:
    """A mountain above the flight plane beyond the cone leaves the region a full disc;
    a horizon-angle method would cut it."""
    x, _ = grid_xy(SHAPE, RES, ORIGIN)
    z = np.full(SHAPE, 100.0)
    z[x - CENTER[0] > 40.0] = 300.0  # a cliff 40 m east, 150 m above the 150 m plane
    terrain = _terrain(write_dem, z)
    camera = Camera(altitude_m=150.0, fov_deg=30.0)
    (region,) = visibility_regions(terrain, np.array([CENTER]), np.array([100.0]), camera, 36)
    cone = 50.0 * math.tan(math.radians(30.0))
    assert np.allclose(region.reach_m, cone, atol=RES)


def test_nodata_stops_the_ray(write_dem: WriteDem) -> None:
    x, _ = grid_xy(SHAPE, RES, ORIGIN)
    z = np.full(SHAPE, 100.0)
    z[x - CENTER[0] > 10.0] = -10000.0
    terrain = _terrain(write_dem, z)
    camera = Camera(altitude_m=150.0, fov_deg=30.0)
    reach = ray_reach(terrain, np.array([CENTER]), np.array([100.0]), camera, np.array([0.0]))
    assert reach[0, 0] <= 10.0 + RES


def test_line_of_sight_over_and_into_a_wall(write_dem: WriteDem) -> None:
    x, _ = grid_xy(SHAPE, RES, ORIGIN)
    z = np.full(SHAPE, 100.0)
    z[(x - CENTER[0] >= 4.0) & (x - CENTER[0] <= 9.0)] = 130.0
    terrain = _terrain(write_dem, z)
    target = np.array([[CENTER[0], CENTER[1], 100.0]])
    # Over the wall's top edge at (4 m, 130 m) the line from the target has slope 7.5.
    steep = np.array([[CENTER[0] + 5.0, CENTER[1], 150.0]])  # slope 10: clears
    shallow = np.array([[CENTER[0] + 10.0, CENTER[1], 150.0]])  # slope 5: blocked
    assert line_of_sight(terrain, steep, target).tolist() == [True]
    assert line_of_sight(terrain, shallow, target).tolist() == [False]


@settings(max_examples=25, deadline=None)
@given(
    bumps=st.lists(
        st.tuples(st.floats(-80, 80), st.floats(-80, 80), st.floats(0, 45), st.floats(2, 20)),
        min_size=1,
        max_size=6,
    ),
    fov=st.floats(10.0, 60.0),
)
def test_region_is_star_shaped_and_inside_the_cone(bumps, fov, tmp_path_factory) -> None:
    """Every point between the target and a ray's reach sees the target (star-shaped), and
    no reach exceeds the cone."""
    import rasterio
    from rasterio.transform import from_origin

    x, y = grid_xy((200, 200), 1.0, ORIGIN)
    z = np.full((200, 200), 100.0)
    for bx, by, bh, bw in bumps:
        z += bh * np.exp(
            -((x - ORIGIN[0] - 100 - bx) ** 2 + (y - ORIGIN[1] + 100 - by) ** 2) / (2 * bw**2)
        )
    path = tmp_path_factory.mktemp("star") / "dem.tif"
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        height=200,
        width=200,
        count=1,
        dtype="float32",
        crs="EPSG:32632",
        nodata=-10000.0,
        transform=from_origin(ORIGIN[0], ORIGIN[1], 1.0, 1.0),
    ) as dst:
        dst.write(z.astype("float32"), 1)
    info = open_dem(path)
    terrain = read_terrain(
        info, info.horizontal_crs, (ORIGIN[0], ORIGIN[1] - 200.0, ORIGIN[0] + 200.0, ORIGIN[1])
    )
    center = np.array([[ORIGIN[0] + 100.0, ORIGIN[1] - 100.0]])
    ground = terrain.sample(center[:, 0], center[:, 1])
    camera = Camera(altitude_m=float(z.max()) + 20.0, fov_deg=fov)
    az = azimuths(12)
    reach = ray_reach(terrain, center, ground, camera, az)[0]
    cone = float(camera.cone_radius_m(ground)[0])
    assert np.all(reach <= cone + 1e-9)
    fractions = np.array([0.25, 0.5, 0.75, 0.95])
    s = reach[:, None] * fractions[None, :] - 0.5  # stay a little inside the grazing ray
    s = np.maximum(s, 0.0).ravel()
    theta = np.repeat(az, len(fractions))
    eye = np.column_stack(
        [
            center[0, 0] + s * np.cos(theta),
            center[0, 1] + s * np.sin(theta),
            np.full(len(s), camera.altitude_m),
        ]
    )
    tgt = np.repeat(np.array([[center[0, 0], center[0, 1], ground[0]]]), len(s), axis=0)
    assert line_of_sight(terrain, eye, tgt).all()


def test_settings_out_of_range() -> None:
    with pytest.raises(SettingsError, match=r"^fov_deg "):
        Camera(altitude_m=100.0, fov_deg=90.0)
    with pytest.raises(SettingsError, match=r"^fov_deg "):
        Camera(altitude_m=100.0, fov_deg=0.0)
    with pytest.raises(SettingsError, match=r"^samples "):
        azimuths(2)


def _sampled_reach(terrain, targets_xy, ground_m, camera, azimuth_rad):
    """The ray rule written out with numpy over every sample at once: every half cell, every
    crossing of a line through pixel centres and one sample right at the start."""
    inv = ~terrain.transform
    cos_a, sin_a = np.cos(azimuth_rad), np.sin(azimuth_rad)
    cone = camera.cone_radius_m(ground_m)
    longest = float(cone.max())
    half = terrain.cell_m / 2.0
    uniform = np.arange(1, math.ceil(longest / half) + 1) * half
    col0, row0 = terrain.pixel_coords(targets_xy[:, 0], targets_xy[:, 1])
    n = math.ceil(longest / terrain.cell_m) + 2
    parts = [np.broadcast_to(uniform, (len(targets_xy), len(azimuth_rad), len(uniform)))]
    for start, rate in (
        (col0, inv.a * cos_a + inv.b * sin_a),
        (row0, inv.d * cos_a + inv.e * sin_a),
    ):
        start = start[:, None, None]
        rate = np.broadcast_to(rate[None, :, None], (len(targets_xy), len(azimuth_rad), 1))
        first = np.where(rate > 0, np.floor(start) + 1.0, np.ceil(start) - 1.0)
        lines = first + np.sign(rate) * np.arange(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            parts.append(np.where(np.abs(rate) > 1e-12, (lines - start) / rate, np.inf))
    parts.append(np.full((len(targets_xy), len(azimuth_rad), 1), 1e-3 * terrain.cell_m))
    shape = (len(targets_xy), len(azimuth_rad))
    s = np.concatenate([np.broadcast_to(q, (*shape, q.shape[-1])) for q in parts], axis=-1)
    s = np.where((s > 0.0) & (s < cone[:, None, None]), s, np.inf)
    with np.errstate(invalid="ignore"):
        z = terrain.sample(
            targets_xy[:, 0, None, None] + cos_a[None, :, None] * s,
            targets_xy[:, 1, None, None] + sin_a[None, :, None] * s,
        )
    h = (camera.altitude_m - ground_m)[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = (z - ground_m[:, None, None]) / s
        limit = np.where(slope > 0.0, np.maximum(s, h / slope), np.inf)
    limit = np.where(np.isnan(z), s, limit)
    limit = np.where(np.isfinite(s), limit, np.inf)
    return np.minimum(limit.min(axis=2), cone[:, None])


@pytest.mark.parametrize("seed", range(6))
def test_ray_walk_takes_every_sample_that_matters(seed: int) -> None:
    """The compiled walk, which stops early, finds the same reach as taking the minimum over
    every sample of every ray, on rough terrain and a rotated grid, with one thread or several.
    (Right on a line through centres next to nodata, which neighbour a sample falls in is
    down to rounding, so the terrain here has none; nodata has its own test above.)"""
    from rasterio.transform import Affine

    from urpt_gcs.site.terrain import Terrain

    rng = np.random.default_rng(seed)
    z = 100.0 + rng.gamma(0.6, 4.0, (90, 110))
    angle = rng.uniform(0.0, 30.0) if seed % 2 else 0.0
    transform = Affine.translation(*ORIGIN) @ Affine.rotation(angle) @ Affine.scale(0.7, -0.7)
    import pyproj

    terrain = Terrain(
        elevation_m=z.astype(np.float32),
        transform=transform,
        crs=pyproj.CRS.from_epsg(32632),
        source="random",
        read_window_px=(0, 0, 110, 90),
        source_shape_px=(90, 110),
    )
    cols = rng.uniform(15.0, 95.0, 300)
    rows = rng.uniform(15.0, 75.0, 300)
    xs, ys = transform @ (cols + 0.5, rows + 0.5)
    targets = np.column_stack([xs, ys])
    ground = np.nan_to_num(terrain.sample(xs, ys), nan=100.0)
    camera = Camera(altitude_m=130.0, fov_deg=float(rng.uniform(15.0, 45.0)))
    az = azimuths(int(rng.integers(5, 40)))
    want = _sampled_reach(terrain, targets, ground, camera, az)
    got = ray_reach(terrain, targets, ground, camera, az)
    # The walk steps in pixel coordinates, the reference in metres: the same up to rounding,
    # which the slope right at the start (a difference of nearby heights) magnifies.
    np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-4)
    assert (want < camera.cone_radius_m(ground)[:, None]).mean() > 0.2  # the terrain matters
    assert np.array_equal(ray_reach(terrain, targets, ground, camera, az, workers=3), got)
