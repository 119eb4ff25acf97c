"""Stops that still see their targets when the vehicle stops a little off its waypoint.

A copter does not photograph exactly at the waypoint: PX4 brakes past it and holds there (its
photos land 0.2-1.2 m beyond the stop), ArduCopter within about 0.2 m. The solver's stops
sit on the edge of what they see (region boundaries pulled in by one cell), so a photo a
metre off can miss a target the plan counts as seen. Each stop is therefore checked from
every point of a ring of the tolerance's radius around it, and one that fails is moved
towards the targets it must see until the whole ring sees them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator

import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.cover import cover_sets
from urpt_gcs.visibility.regions import Camera, line_of_sight

__all__ = ["RING_POINTS", "robust_tour"]

# Points on the ring around each stop, besides the stop itself.
RING_POINTS = 8
# How far a failing stop moves towards its targets on each try, as a share of the way.
_STEPS = np.linspace(0.1, 1.0, 10)
# Then points around it: at these multiples of the tolerance, in this many directions.
_SEARCH_RADII = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
_SEARCH_ANGLES = 16


def _ring(point: FloatArray, radius_m: float) -> FloatArray:
    angles = np.arange(RING_POINTS) * (2.0 * math.pi / RING_POINTS)
    ring = point + radius_m * np.column_stack([np.cos(angles), np.sin(angles)])
    return np.vstack([point[None, :], ring])


def _holding(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    points_xy: FloatArray,
    sees: npt.NDArray[np.bool_],
    tolerance_m: float,
    headings_deg: FloatArray | None = None,
) -> npt.NDArray[np.bool_]:
    """Which stops see every target they are counted for from all of their ring, tested
    in one call: the cone (or the frame at the stop's heading) from every ring point, then
    every line of sight."""
    stop, target = np.nonzero(sees)
    angles = np.arange(RING_POINTS) * (2.0 * math.pi / RING_POINTS)
    offsets = np.vstack(
        [[0.0, 0.0], tolerance_m * np.column_stack([np.cos(angles), np.sin(angles)])]
    )
    eye_xy = (points_xy[stop][:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    pair_stop = np.repeat(stop, len(offsets))
    pair_target = np.repeat(target, len(offsets))
    heading = None if headings_deg is None else np.repeat(headings_deg[stop], len(offsets))
    ok = camera.in_view(eye_xy, targets_xy[pair_target], ground_m[pair_target], heading)
    eye = np.column_stack([eye_xy[ok], np.full(int(ok.sum()), camera.altitude_m)])
    tgt = np.column_stack([targets_xy[pair_target[ok]], ground_m[pair_target[ok]]])
    ok[ok] = line_of_sight(terrain, eye, tgt)
    failed = np.zeros(len(points_xy), dtype=bool)
    failed[pair_stop[~ok]] = True
    return ~failed


def _tries(
    stops_xy: FloatArray, sees: npt.NDArray[np.bool_], targets_xy: FloatArray, tolerance_m: float
) -> Iterator[Callable[[npt.NDArray[np.intp]], FloatArray]]:
    """The places a failing stop is tried at, in order, each as a function of the stops still
    failing: on the way towards the mean of its targets, then on rings around it."""
    stop, target = np.nonzero(sees)
    counts = np.maximum(np.bincount(stop, minlength=len(stops_xy)), 1)
    aim = np.column_stack(
        [np.bincount(stop, targets_xy[target, i], len(stops_xy)) / counts for i in range(2)]
    )

    def towards(step: float) -> Callable[[npt.NDArray[np.intp]], FloatArray]:
        return lambda k: stops_xy[k] + step * (aim[k] - stops_xy[k])

    def shifted(shift: FloatArray) -> Callable[[npt.NDArray[np.intp]], FloatArray]:
        return lambda k: stops_xy[k] + shift

    for step in _STEPS:
        yield towards(float(step))
    for radius in tolerance_m * _SEARCH_RADII:
        for angle in np.arange(_SEARCH_ANGLES) * (2.0 * math.pi / _SEARCH_ANGLES):
            yield shifted(radius * np.array([math.cos(angle), math.sin(angle)]))


def robust_tour(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    tour: Tour,
    depot_xy: tuple[float, float] | None,
    tolerance_m: float,
    names: list[str],
) -> tuple[Tour, list[str]]:
    """The tour with every stop seeing its targets from anywhere within ``tolerance_m``.

    A stop that does not is moved: towards its targets, else to the nearest point around it
    that holds the margin; a stop counted for several targets that no single point near it
    sees with the margin is split into one stop per target, in place.

    Parameters
    ----------
    terrain, targets_xy, ground_m, camera
        The terrain, the targets and their ground heights, and the camera on the plane.
    tour
        The solver's tour; ``tour.sees`` says which targets each stop is counted for.
    depot_xy
        Home, where the tour starts and ends (None: a closed cycle).
    tolerance_m
        How far from its waypoint the vehicle may take the photo; 0 keeps the tour.
    names
        The targets' names, for the warnings.

    Returns
    -------
    tuple
        The tour (stops moved or split where needed, its length measured again) and a warning
        for every target that no stop could be made to see with the margin.
    """
    if tolerance_m <= 0.0 or tour.points_xy is None or len(tour.points_xy) == 0:
        return tour, []
    points: list[FloatArray] = []
    sees: list[npt.NDArray[np.bool_]] = []
    order: list[int] = []
    headings: list[float] = []
    warnings = []
    changed = False
    stop_headings = (
        np.zeros(len(tour.points_xy)) if tour.headings_deg is None else tour.headings_deg
    )
    framed = tour.headings_deg is not None

    def holds(point: FloatArray, must: npt.NDArray[np.intp], heading: float) -> bool:
        ring = _ring(point, tolerance_m)
        at = np.full(len(ring), heading) if framed else None
        seen = cover_sets(terrain, ring, targets_xy[must], ground_m[must], camera, 1, at)
        return bool(seen.all())

    def place(point: FloatArray, must: npt.NDArray[np.intp], heading: float) -> FloatArray | None:
        aim = targets_xy[must].mean(axis=0)
        for step in _STEPS:
            moved: FloatArray = point + step * (aim - point)
            if holds(moved, must, heading):
                return moved
        for radius in tolerance_m * _SEARCH_RADII:
            for angle in np.arange(_SEARCH_ANGLES) * (2.0 * math.pi / _SEARCH_ANGLES):
                around: FloatArray = point + radius * np.array([math.cos(angle), math.sin(angle)])
                if holds(around, must, heading):
                    return around
        return None

    stops_xy = np.asarray(tour.points_xy, dtype=np.float64)

    def holding(
        points_xy: FloatArray, rows: npt.NDArray[np.bool_], at: FloatArray
    ) -> npt.NDArray[np.bool_]:
        return _holding(
            terrain,
            targets_xy,
            ground_m,
            camera,
            points_xy,
            rows,
            tolerance_m,
            at if framed else None,
        )

    settled = holding(stops_xy, tour.sees, stop_headings)
    # Stops that fail are searched for all at once, try by try in the order `place` takes.
    spots = stops_xy.copy()
    for offset in _tries(stops_xy, tour.sees, targets_xy, tolerance_m):
        pending = np.flatnonzero(~settled)
        if pending.size == 0:
            break
        tried = offset(pending)
        ok = holding(tried, tour.sees[pending], stop_headings[pending])
        spots[pending[ok]] = tried[ok]
        settled[pending[ok]] = True
    for k, point in enumerate(stops_xy):
        must = np.flatnonzero(tour.sees[k])
        if must.size == 0 or (settled[k] and np.array_equal(spots[k], point)):
            points.append(point)
            sees.append(tour.sees[k])
            order.append(tour.order[k])
            headings.append(float(stop_headings[k]))
            continue
        changed = True
        if settled[k]:
            points.append(spots[k])
            sees.append(tour.sees[k])
            order.append(-1)
            headings.append(float(stop_headings[k]))
            continue
        # One stop per target, nearest first from where the tour comes from.
        came_from = points[-1] if points else np.asarray(depot_xy if depot_xy else point)
        for t in sorted(must, key=lambda t: float(np.hypot(*(targets_xy[t] - came_from)))):
            one = np.array([t])
            spot = place(point, one, float(stop_headings[k]))
            row = np.zeros(tour.sees.shape[1], dtype=bool)
            row[t] = True
            if spot is None:
                spot = point
                warnings.append(
                    f"target '{names[t]}' is seen from stop {k + 1} only within "
                    f"{tolerance_m:g} m of its waypoint: a vehicle that stops farther off may "
                    "miss it"
                )
            points.append(spot)
            sees.append(row)
            order.append(-1)
            headings.append(float(stop_headings[k]))
    if not changed:
        return tour, warnings
    xy = np.vstack(points)
    hops = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0
    if depot_xy is not None:
        depot = np.asarray(depot_xy)
        length = hops + float(np.hypot(*(xy[0] - depot)) + np.hypot(*(xy[-1] - depot)))
    else:
        length = hops + float(np.hypot(*(xy[-1] - xy[0])))
    moved_tour = dataclasses.replace(
        tour,
        order=tuple(order),
        points_xy=xy,
        sees=np.vstack(sees),
        headings_deg=np.asarray(headings, dtype=np.float64) if framed else None,
        length=length,
        lower_bound=min(tour.lower_bound, length),
        # Optimal over the candidates says nothing more once stops moved, unless no longer.
        proven_optimal=tour.proven_optimal and length <= tour.length,
        notes=(
            *tour.notes,
            f"stops moved to see their targets from anywhere within {tolerance_m:g} m",
        ),
    )
    return moved_tour, warnings
