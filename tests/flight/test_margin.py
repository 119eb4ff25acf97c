"""Stops keep their targets in the picture from the whole tolerance disc, not 8 points of it.

On flat ground the picture's edge is the only limit, and the disc's worst point lies in the
direction between two of the sampled ring's points: a stop placed there by a sampled check
keeps the samples inside while the disc leaves the cone or the frame by up to
``(1 - cos 22.5) r``. Margins here are measured with the test's own arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
import pyproj
from affine import Affine

from urpt_gcs.flight.margin import Site, robust_tour
from urpt_gcs.flight.refinement import refine_tour
from urpt_gcs.site.camera import Frame
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.regions import Camera

X0, Y0, CELL, N = 500_000.0, 5_200_000.0, 5.0, 200
ALTITUDE_M = 100.0
TOL_M = 1.5
# Between two of the ring's 8 points (every 45 degrees).
BETWEEN = math.radians(22.5)
# Sensor 13.2 x 8.8 mm behind 8.8 mm: at 100 m over flat ground, 75 m across, 50 m along.
FRAME = Frame(13.2, 8.8, 8.8, 5472, 3648)
HALF_ACROSS_M, HALF_ALONG_M = 75.0, 50.0
CONE_M = ALTITUDE_M * math.tan(math.radians(30.0))


def _flat() -> Terrain:
    return Terrain(
        elevation_m=np.zeros((N, N)),
        transform=Affine(CELL, 0.0, X0, 0.0, -CELL, Y0 + N * CELL),
        crs=pyproj.CRS.from_epsg(32632),
        source="test",
        read_window_px=(0, 0, N, N),
        source_shape_px=(N, N),
    )


def _site(camera: Camera, targets: np.ndarray) -> Site:
    return Site(_flat(), targets, np.zeros(len(targets)), camera, tolerance_m=TOL_M)


def _tour(stops: np.ndarray, headings: np.ndarray | None = None) -> Tour:
    n = len(stops)
    return Tour(
        order=tuple(range(n)),
        length=0.0,
        lower_bound=0.0,
        proven_optimal=False,
        solver="test",
        solve_s=0.0,
        points_xy=np.asarray(stops, dtype=np.float64),
        sees=np.eye(n, dtype=bool),
        headings_deg=headings,
    )


def _cone_margin(stop: np.ndarray, target: np.ndarray) -> float:
    return CONE_M - float(np.hypot(*(target - stop))) - TOL_M


def _frame_margin(stop: np.ndarray, target: np.ndarray, heading_deg: float) -> float:
    """Least distance from the disc to the frame's sides (heading clockwise from north)."""
    dx, dy = target - stop
    psi = math.radians(heading_deg)
    along = dx * math.sin(psi) + dy * math.cos(psi)
    across = dx * math.cos(psi) - dy * math.sin(psi)
    return min(HALF_ACROSS_M - abs(across), HALF_ALONG_M - abs(along)) - TOL_M


def test_a_stop_whose_disc_leaves_the_cone_between_the_ring_points_is_moved_in() -> None:
    target = np.array([[X0 + 500.0, Y0 + 500.0]])
    # 5 % of the tolerance too far out, towards a direction no ring point takes.
    away = np.array([math.cos(BETWEEN), math.sin(BETWEEN)])
    stop = target[0] + (CONE_M - 0.95 * TOL_M) * away
    assert _cone_margin(stop, target[0]) < 0.0
    moved, warnings = robust_tour(
        _site(Camera(ALTITUDE_M, 30.0), target), _tour(stop[None]), None, ["T"]
    )
    assert warnings == []
    assert moved.points_xy is not None
    assert not np.allclose(moved.points_xy[0], stop)
    assert _cone_margin(moved.points_xy[0], target[0]) >= 0.0


def test_a_frame_stop_whose_disc_leaves_the_frame_between_the_ring_points_is_moved_in() -> None:
    heading = 22.5
    psi = math.radians(heading)
    across = np.array([math.cos(psi), -math.sin(psi)])
    stop = np.array([X0 + 500.0, Y0 + 500.0])
    # The target 5 % of the tolerance short of the disc's room across the heading.
    target = (stop + (HALF_ACROSS_M - 0.95 * TOL_M) * across)[None, :]
    assert _frame_margin(stop, target[0], heading) < 0.0
    camera = Camera.framed(ALTITUDE_M, FRAME)
    site = _site(camera, target)
    moved, warnings = robust_tour(site, _tour(stop[None], np.array([heading])), None, ["T"])
    assert warnings == []
    assert moved.points_xy is not None and moved.headings_deg is not None
    assert moved.headings_deg[0] == heading
    assert _frame_margin(moved.points_xy[0], target[0], heading) >= 0.0


def test_refined_frame_stops_keep_the_whole_disc_inside_the_frame() -> None:
    """Refinement pulls each stop towards the line between its neighbours, onto the edge of
    what it sees: from there the whole disc must stay inside the frame."""
    rng = np.random.default_rng(7)
    targets = np.array([X0, Y0]) + np.column_stack(
        [np.linspace(150.0, 850.0, 6), 500.0 + rng.uniform(-200.0, 200.0, 6)]
    )
    headings = np.array([11.0, 33.0, 57.0, 79.0, 101.0, 146.0])
    site = _site(Camera.framed(ALTITUDE_M, FRAME), targets)
    # Each stop over its target, home far to the south: every stop is drawn towards the
    # line between its neighbours, out to the frame's edge.
    home = (X0 + 500.0, Y0 + 20.0)
    refined, done = refine_tour(site, _tour(targets.copy(), headings), home, 30.0)
    assert done.after_m < done.before_m
    assert refined.points_xy is not None and refined.headings_deg is not None
    margins = [
        _frame_margin(refined.points_xy[k], targets[t], float(refined.headings_deg[k]))
        for k, t in zip(*np.nonzero(refined.sees), strict=True)
    ]
    assert len(margins) == len(targets)
    assert min(margins) >= -1e-9
    # The stops did reach the edge: the disc touches the frame somewhere.
    assert min(margins) < 0.1


def test_refined_cone_stops_keep_the_whole_disc_inside_the_cone() -> None:
    rng = np.random.default_rng(3)
    targets = np.array([X0, Y0]) + np.column_stack(
        [np.linspace(150.0, 850.0, 6), 500.0 + rng.uniform(-150.0, 150.0, 6)]
    )
    site = _site(Camera(ALTITUDE_M, 30.0), targets)
    home = (X0 + 500.0, Y0 + 20.0)
    refined, done = refine_tour(site, _tour(targets.copy()), home, 30.0)
    assert done.after_m < done.before_m
    assert refined.points_xy is not None
    margins = [
        _cone_margin(refined.points_xy[k], targets[t])
        for k, t in zip(*np.nonzero(refined.sees), strict=True)
    ]
    assert min(margins) >= -1e-9
    assert min(margins) < 0.1
