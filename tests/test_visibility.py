"""Visibility regions against terrains whose answer is known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import WriteDem, grid_xy
from hypothesis import given, settings
from hypothesis import strategies as st

from urpt_gcs.errors import SettingsError
from urpt_gcs.terrain import open_dem, read_terrain
from urpt_gcs.visibility import Camera, azimuths, line_of_sight, ray_reach, visibility_regions

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
    with pytest.raises(SettingsError, match="--fov"):
        Camera(altitude_m=100.0, fov_deg=90.0)
    with pytest.raises(SettingsError, match="--fov"):
        Camera(altitude_m=100.0, fov_deg=0.0)
    with pytest.raises(SettingsError, match="--samples"):
        azimuths(2)
