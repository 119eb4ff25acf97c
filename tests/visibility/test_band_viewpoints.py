"""Viewpoints inside the band, and the costs and bounds built on them, against independent
computations: dense sampling of the surface, and the paths the flight really follows."""

from __future__ import annotations

import math

import numpy as np
import pyproj
import pytest
from affine import Affine

from urpt_gcs.flight.band import FlightBand
from urpt_gcs.flight.follow import path_in_band
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.band import band_viewpoints, sees_from
from urpt_gcs.visibility.band_outer import band_outer
from urpt_gcs.visibility.outer import star_holds
from urpt_gcs.visibility.regions import Camera

CRS = pyproj.CRS.from_epsg(32632)
X0, Y0 = 500_000.0, 5_200_000.0
BAND = FlightBand(30.0, 120.0)
CELL = 5.0


def _terrain(seed: int = 3) -> Terrain:
    """Rolling hills with a ridge, 1.5 km square at 5 m."""
    rng = np.random.default_rng(seed)
    n = 300
    x = (np.arange(n) + 0.5) * CELL
    xx, yy = np.meshgrid(x, x)
    z = 200.0 * np.exp(-(((xx - 750.0) / 180.0) ** 2)) + 40.0 * np.sin(yy / 170.0)
    z += rng.normal(0.0, 1.5, z.shape)
    return Terrain(
        elevation_m=z.astype(np.float64),
        transform=Affine(CELL, 0.0, X0, 0.0, -CELL, Y0 + n * CELL),
        crs=CRS,
        source="test",
        read_window_px=(0, 0, n, n),
        source_shape_px=(n, n),
    )


def _targets(terrain: Terrain, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    xy = np.column_stack(
        [X0 + rng.uniform(300.0, 1200.0, count), Y0 + rng.uniform(300.0, 1200.0, count)]
    )
    return xy, terrain.sample(xy[:, 0], xy[:, 1])


def _dense_sight(terrain: Terrain, eye: np.ndarray, target: np.ndarray) -> bool:
    """Line of sight by sampling every 0.2 m (misses nothing this smooth surface hides)."""
    length = float(np.hypot(*(eye[:2] - target[:2])))
    t = np.linspace(0.0, 1.0, max(int(length / 0.2), 2))[1:-1]
    p = target[None, :] + (eye - target)[None, :] * t[:, None]
    return bool(np.all(terrain.sample(p[:, 0], p[:, 1]) <= p[:, 2] + 1e-6))


def test_a_pair_that_sees_from_the_tolerance_sees_from_every_point_within_it() -> None:
    terrain = _terrain()
    camera = Camera(0.0, 30.0)
    targets, ground = _targets(terrain, 12, 1)
    views = band_viewpoints(
        terrain, camera, targets, ground, 30.0, 120.0, 2.0, 4000, [f"T{k}" for k in range(12)]
    )
    vp, tg = views.pairs
    assert len(vp) >= 12
    rng = np.random.default_rng(0)
    picked = rng.choice(len(vp), size=min(60, len(vp)), replace=False)
    for k in picked:
        eye, t = views.xyz[vp[k]], int(tg[k])
        target = np.array([*targets[t], ground[t]])
        for _ in range(10):
            a, r = rng.uniform(0, 2 * math.pi), 2.0 * math.sqrt(rng.uniform())
            moved = eye + np.array([r * math.cos(a), r * math.sin(a), rng.uniform(-2.0, 2.0)])
            d = float(np.hypot(*(moved[:2] - target[:2])))
            assert d <= (moved[2] - target[2]) * math.tan(math.radians(30.0)) + 1e-9
            assert _dense_sight(terrain, moved, target)
            surface = float(terrain.sample(moved[:1], moved[1:2])[0])
            assert BAND.floor_m - 1e-6 <= moved[2] - surface <= BAND.ceiling_m + 1e-6


def test_a_hidden_target_is_not_claimed() -> None:
    terrain = _terrain()
    camera = Camera(0.0, 60.0)
    # A target at the ridge's western foot, an eye low over the eastern slope: the ridge is
    # between them.
    target = np.array([[X0 + 520.0, Y0 + 750.0]])
    ground = terrain.sample(target[:, 0], target[:, 1])
    eye_xy = np.array([X0 + 980.0, Y0 + 750.0])
    eye = np.array([[*eye_xy, float(terrain.sample(eye_xy[:1], eye_xy[1:])[0]) + 30.0]])
    assert not _dense_sight(terrain, eye[0], np.array([*target[0], ground[0]]))
    assert not sees_from(terrain, camera, eye, target, ground, None, 0.0)[0]


def test_leg_cost_never_exceeds_the_path_the_flight_follows() -> None:
    terrain = _terrain()
    model = FlightModel.arducopter(cruise_m_s=5.0, hold_s=1.0)
    rng = np.random.default_rng(7)
    for _ in range(40):
        xy = np.array([X0, Y0]) + rng.uniform(100.0, 1400.0, (2, 2))
        s = terrain.sample(xy[:, 0], xy[:, 1])
        z = s + rng.uniform(40.0, 110.0, 2)
        a, b = np.array([*xy[0], z[0]]), np.array([*xy[1], z[1]])
        path, _ = path_in_band(terrain, np.vstack([a, b]), BAND)
        d = np.hypot(*np.diff(path[:, :2], axis=0).T)
        flown = float(model.leg3_s(d.sum(), 0.0, model.vertical_excess_s(d, np.diff(path[:, 2]))))
        # The highest and lowest surface under the leg, sampled densely.
        t = np.linspace(0.0, 1.0, 4000)
        line = xy[0][None, :] + (xy[1] - xy[0])[None, :] * t[:, None]
        under = terrain.sample(line[:, 0], line[:, 1])
        length = np.array([float(np.hypot(*(xy[1] - xy[0])))])
        extra = model.least_vertical_s(
            length,
            z[:1],
            z[1:],
            np.array([under.max() + BAND.floor_m]),
            np.array([under.min() + BAND.ceiling_m]),
        )
        estimate = float(model.leg3_s(length, 0.0, extra)[0])
        assert estimate <= flown + 1e-6


@pytest.mark.parametrize("seed", [1, 2])
def test_every_viewpoint_that_sees_a_target_lies_in_its_outer_disc(seed: int) -> None:
    terrain = _terrain(seed)
    camera = Camera(0.0, 35.0)
    targets, ground = _targets(terrain, 10, seed)
    views = band_viewpoints(
        terrain, camera, targets, ground, 30.0, 120.0, 0.0, 4000, [f"T{k}" for k in range(10)]
    )
    top = float(terrain.elevation_m.max())
    outer = band_outer(terrain, targets, ground, camera, BAND.ceiling_m, top, None)
    vp, tg = views.pairs
    for v, t in zip(vp.tolist(), tg.tolist(), strict=True):
        assert star_holds(outer.regions.outer[t], tuple(views.xyz[v, :2]))
    d = np.hypot(*(views.xyz[vp, :2] - targets[tg]).T)
    assert np.all(d <= outer.radius_m[tg] + 1e-9)
    # The fixed point tightens the plane-high disc, and more in some sectors than others.
    first = (top + BAND.ceiling_m - ground) * camera.tan_fov
    reach = np.array([s.reach_m for s in outer.regions.outer])
    assert np.all(reach.max(axis=1) <= first + 1e-9) and np.any(reach.max(axis=1) < 0.9 * first)
    assert np.any(reach.min(axis=1) < 0.9 * reach.max(axis=1))
