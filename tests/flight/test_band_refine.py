"""Stops moved in three dimensions keep what they see and never fly slower."""

from __future__ import annotations

import math

import numpy as np
import pyproj
from affine import Affine

from urpt_gcs.flight.band import FlightBand
from urpt_gcs.flight.band_refine import BandStops, _legs_s, refine_band_stops
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.band import band_viewpoints
from urpt_gcs.visibility.regions import Camera

X0, Y0, CELL, N = 500_000.0, 5_200_000.0, 5.0, 300
BAND = FlightBand(30.0, 120.0)


def _terrain() -> Terrain:
    x = (np.arange(N) + 0.5) * CELL
    xx, yy = np.meshgrid(x, x)
    z = 180.0 * np.exp(-(((xx - 700.0) / 200.0) ** 2)) + 30.0 * np.cos(yy / 150.0)
    return Terrain(
        elevation_m=z,
        transform=Affine(CELL, 0.0, X0, 0.0, -CELL, Y0 + N * CELL),
        crs=pyproj.CRS.from_epsg(32632),
        source="test",
        read_window_px=(0, 0, N, N),
        source_shape_px=(N, N),
    )


def _sight(terrain: Terrain, eye: np.ndarray, target: np.ndarray) -> bool:
    length = float(np.hypot(*(eye[:2] - target[:2])))
    t = np.linspace(0.0, 1.0, max(int(length / 0.2), 2))[1:-1]
    p = target[None, :] + (eye - target)[None, :] * t[:, None]
    return bool(np.all(terrain.sample(p[:, 0], p[:, 1]) <= p[:, 2] + 1e-6))


def test_moved_stops_see_their_targets_from_within_the_tolerance_and_fly_faster() -> None:
    terrain = _terrain()
    camera = Camera(0.0, 35.0)
    rng = np.random.default_rng(4)
    targets = np.array([X0, Y0]) + rng.uniform(250.0, 1250.0, (8, 2))
    ground = terrain.sample(targets[:, 0], targets[:, 1])
    tol = 1.5
    names = [f"T{k}" for k in range(8)]
    views = band_viewpoints(terrain, camera, targets, ground, 30.0, 120.0, tol, 4000, names)
    # A deliberately poor tour: each target's own highest nadir, in file order.
    stops = np.array(
        [views.xyz[np.flatnonzero(views.owner == t)][-1] for t in range(8)], dtype=np.float64
    )
    sees = np.eye(8, dtype=bool)
    home = np.array([X0 + 750.0, Y0 + 750.0, 0.0])
    home[2] = float(terrain.sample(home[:1], home[1:2])[0]) + 40.0
    model = FlightModel.arducopter(cruise_m_s=5.0, hold_s=1.0)
    keep = BandStops(terrain, camera, BAND, targets, ground, sees, None, tol)
    moved = refine_band_stops(keep, stops, home, model)
    assert not np.allclose(moved, stops)

    def total(points: np.ndarray) -> float:
        path = np.vstack([home, points, home])
        return sum(
            float(_legs_s(keep, model, path[i - 1], path[i], path[i + 1])[0]) / 2.0
            for i in range(1, len(path) - 1)
        )

    assert total(moved) < total(stops)
    for t in range(8):
        target = np.array([*targets[t], ground[t]])
        for a in np.linspace(0.0, 2.0 * math.pi, 9)[:-1]:
            for dz in (-tol, 0.0, tol):
                eye = moved[t] + np.array([tol * math.cos(a), tol * math.sin(a), dz])
                reach = (eye[2] - target[2]) * math.tan(math.radians(35.0))
                assert float(np.hypot(*(eye[:2] - target[:2]))) <= reach + 1e-9
                assert _sight(terrain, eye, target)
                surface = float(terrain.sample(eye[:1], eye[1:2])[0])
                assert BAND.floor_m - 1e-6 <= eye[2] - surface <= BAND.ceiling_m + 1e-6
