"""Stops that still see their targets when the vehicle stops a little off its waypoint.

A copter does not photograph exactly at the waypoint: PX4 brakes past it and holds there (its
photos land 0.2-1.2 m beyond the stop), ArduCopter within about 0.2 m. The solver's stops
sit on the edge of what they see (region boundaries pulled in by one cell), so a photo a
metre off can miss a target the plan counts as seen. Each stop is therefore checked against
the disc of the tolerance's radius around it on the flight plane (:func:`sees_around`): every
target it must see stays in the picture from the whole disc, held exactly (the disc lies
inside the cone's circle, or the frame's rectangle, iff the stop lies inside it shrunk by the
radius), and in sight over the terrain from the stop, from the disc's point farthest from
the target and from ``RING_POINTS`` points of its rim (a line of sight cannot be checked
from every point of a disc: these are samples). The picture is held, and the line of sight
checked from the position itself, as the mission writes the stop too: its position, heading
and height. A stop that fails is moved towards the targets it must see until it passes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import sparse

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.regions import Camera, line_of_sight

__all__ = ["RING_POINTS", "Site", "robust_tour", "sees_around"]

# Points on the rim of the disc around each stop that lines of sight are checked from,
# besides the stop itself (what is in the picture is held over the whole disc).
RING_POINTS = 8
# How far a failing stop moves towards its targets on each try, as a share of the way.
_STEPS = np.linspace(0.1, 1.0, 10)
# Then points around it: at these multiples of the tolerance, in this many directions.
_SEARCH_RADII = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
_SEARCH_ANGLES = 16

Written = Callable[[FloatArray], FloatArray]
WrittenHeading = Callable[[FloatArray, FloatArray], FloatArray]
Fill = Callable[[FloatArray, FloatArray], object]


@dataclass(frozen=True, slots=True)
class Site:
    """What a stop is checked against: the terrain, the targets and the camera, the position
    tolerance, and how the mission writes a stop."""

    terrain: Terrain
    targets_xy: FloatArray
    ground_m: FloatArray
    camera: Camera
    tolerance_m: float = 0.0
    min_clearance_m: float = 0.0
    # The position the mission writes for a point (the 1e-7 degree grid); None: as is.
    written: Written | None = None
    # Reads the terrain along legs where a sparse mosaic holds none yet.
    fill: Fill | None = None
    workers: int | None = 1
    # The plane's height as the mission writes it (None: the camera's), and the heading it
    # writes for a stop at a point and grid heading (None: as is).
    written_eye_m: float | None = None
    written_heading: WrittenHeading | None = None


def sees_around(
    site: Site,
    cand: FloatArray,
    sees: BoolArray | sparse.csr_array,
    heading: FloatArray | None,
    also: Callable[[IntArray], BoolArray] | None = None,
) -> BoolArray:
    """Whether each candidate stop sees every target of its row of ``sees`` from anywhere
    within ``site.tolerance_m`` of it, and from its position as written.

    Each target must be in the picture (the cone, or the frame at the stop's heading) from
    every point of the disc of ``site.tolerance_m`` around the stop, and of the same disc
    around its position as written, from the height and at the heading as written (both
    exact: :meth:`~urpt_gcs.visibility.regions.Camera.view_margin_m`); and in sight over the
    terrain from the stop, from its position as written, from the disc's point farthest from
    the target and from ``RING_POINTS`` points of the disc's rim. With ``also``, the stop
    must pass that check too (given the indices of the stops still standing once the
    targets are in the picture, before any line of sight is walked: lines of sight cost the
    most).
    """
    cam = site.camera
    radius = max(site.tolerance_m, 0.0)
    # Rows may be sparse: at thousands of targets a dense row per candidate is mostly zeros.
    stop, target = sees.nonzero()
    tx, tg = site.targets_xy[target], site.ground_m[target]
    at = None if heading is None else heading[stop]
    failed = np.zeros(len(cand), dtype=bool)
    failed[stop[~cam.in_view(cand[stop], tx, tg, at, radius)]] = True
    # Lines of sight from the stop and as written first, from the disc's rim after.
    eyes = [np.column_stack([cand[stop], np.full(len(stop), cam.altitude_m)])]
    pairs = [np.arange(len(stop))]
    if site.written is not None:
        xy = site.written(cand[stop])
        eye_m = cam.altitude_m if site.written_eye_m is None else site.written_eye_m
        as_written = dataclasses.replace(cam, altitude_m=eye_m)
        if at is not None and site.written_heading is not None:
            at = site.written_heading(cand[stop], at)
        failed[stop[~as_written.in_view(xy, tx, tg, at, radius)]] = True
        eyes[0] = np.vstack([eyes[0], np.column_stack([xy, np.full(len(stop), eye_m)])])
        pairs[0] = np.concatenate([pairs[0], pairs[0]])
    if also is not None and not failed.all():
        standing = np.flatnonzero(~failed)
        failed[standing] = ~also(standing)
    if radius > 0.0:
        # The disc's point farthest from the target (straight away from it: the certified
        # bound's stars, shrunk by the tolerance, count on that point seeing), then the rim's.
        away = cand[stop] - tx
        length = np.hypot(away[:, 0], away[:, 1])
        unit = np.tile([1.0, 0.0], (len(stop), 1))  # over the target: any way
        some = length > 0.0
        unit[some] = away[some] / length[some, None]
        far = np.column_stack([cand[stop] + radius * unit, np.full(len(stop), cam.altitude_m)])
        eyes.append(far)
        pairs.append(np.arange(len(stop)))
        angles = np.arange(RING_POINTS) * (2.0 * math.pi / RING_POINTS)
        rim = radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(RING_POINTS)])
        eyes.append((eyes[0][: len(stop), None, :] + rim[None, :, :]).reshape(-1, 3))
        pairs.append(np.repeat(np.arange(len(stop)), RING_POINTS))
    t3 = np.column_stack([tx, tg])
    for eye, pair in zip(eyes, pairs, strict=True):
        walk = ~failed[stop[pair]]
        if walk.any():
            clear = line_of_sight(site.terrain, eye[walk], t3[pair[walk]], site.workers)
            failed[stop[pair[walk]][~clear]] = True
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
    site: Site,
    tour: Tour,
    depot_xy: tuple[float, float] | None,
    names: list[str],
) -> tuple[Tour, list[str]]:
    """The tour with every stop seeing its targets from anywhere within the tolerance.

    A stop that does not (:func:`sees_around`) is moved: towards its targets, else to the
    nearest point around it that holds the margin; a stop counted for several targets that no
    single point near it sees with the margin is split into one stop per target, in place.

    Parameters
    ----------
    site
        The terrain, the targets and their ground heights, the camera on the plane, the
        tolerance (how far from its waypoint the vehicle may take the photo; 0 keeps the
        tour) and how the mission writes a stop.
    tour
        The solver's tour; ``tour.sees`` says which targets each stop is counted for.
    depot_xy
        Home, where the tour starts and ends (None: a closed cycle).
    names
        The targets' names, for the warnings.

    Returns
    -------
    tuple
        The tour (stops moved or split where needed, its length measured again) and a warning
        for every target that no stop could be made to see with the margin.
    """
    tolerance_m, targets_xy = site.tolerance_m, site.targets_xy
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

    def holding(
        points_xy: FloatArray, rows: npt.NDArray[np.bool_], at: FloatArray
    ) -> npt.NDArray[np.bool_]:
        return sees_around(site, points_xy, rows, at if framed else None)

    def holds(point: FloatArray, must: npt.NDArray[np.intp], heading: float) -> bool:
        row = np.zeros((1, len(targets_xy)), dtype=bool)
        row[0, must] = True
        return bool(holding(point[None, :], row, np.array([heading]))[0])

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
