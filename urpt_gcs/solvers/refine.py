"""Continuous refinement: with the order of the regions fixed, move every stop within its region.

A tour is a sequence of *touches*: region ``seq[k]`` is entered at ``points[k]`` (several
touches may share a point). One sweep moves each touch, in turn, to the point of its region
that minimises the two legs to its neighbours (``|a - p| + |p - b|``, convex in ``p``), and
keeps a move only when it shortens the tour and the ``accept`` check (for a planning site:
line of sight, camera cone, leg clearance) passes. Sweeps repeat until they gain nothing, so
the result is never longer than the tour it started from.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba as nb
import numpy as np
import shapely
from shapely.geometry import LineString, Point

from urpt_gcs.gtsp import IntArray
from urpt_gcs.solvers.regions import RegionSet
from urpt_gcs.terrain import FloatArray

# Sweeps stop once one gains less than this fraction of the tour.
_SWEEP_GAIN = 1e-10
_MAX_SWEEPS = 2000
# Points tried along a polygon's boundary before the local search.
_POLYGON_SAMPLES = 64

Accept = Callable[[int, FloatArray], bool]


@nb.njit(cache=True)
def _legs(ax: float, ay: float, px: float, py: float, bx: float, by: float) -> float:
    return math.hypot(px - ax, py - ay) + math.hypot(bx - px, by - py)


@nb.njit(cache=True)
def best_on_disc(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, r: float
) -> tuple[float, float]:
    """The point of the disc ``(c, r)`` nearest to minimising ``|a - p| + |p - b|``."""
    dx, dy = bx - ax, by - ay
    ll = dx * dx + dy * dy
    t = 0.0 if ll == 0.0 else ((cx - ax) * dx + (cy - ay) * dy) / ll
    t = min(max(t, 0.0), 1.0)
    qx, qy = ax + t * dx, ay + t * dy
    if math.hypot(qx - cx, qy - cy) <= r:
        return qx, qy
    # The optimum is on the circle, on the arc between the directions to a and to b.
    ta = math.atan2(ay - cy, ax - cx)
    tb = math.atan2(by - cy, bx - cx)
    span = (tb - ta + math.pi) % (2.0 * math.pi) - math.pi
    lo, hi = ta, ta + span
    if hi < lo:
        lo, hi = hi, lo
    n = 16
    best_k, best_v = 0, math.inf
    for k in range(n + 1):
        th = lo + (hi - lo) * k / n
        v = _legs(ax, ay, cx + r * math.cos(th), cy + r * math.sin(th), bx, by)
        if v < best_v:
            best_k, best_v = k, v
    a = lo + (hi - lo) * max(best_k - 1, 0) / n
    b = lo + (hi - lo) * min(best_k + 1, n) / n
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    x1 = b - g * (b - a)
    x2 = a + g * (b - a)
    f1 = _legs(ax, ay, cx + r * math.cos(x1), cy + r * math.sin(x1), bx, by)
    f2 = _legs(ax, ay, cx + r * math.cos(x2), cy + r * math.sin(x2), bx, by)
    for _ in range(60):
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = _legs(ax, ay, cx + r * math.cos(x1), cy + r * math.sin(x1), bx, by)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = _legs(ax, ay, cx + r * math.cos(x2), cy + r * math.sin(x2), bx, by)
    th = 0.5 * (a + b)
    return cx + r * math.cos(th), cy + r * math.sin(th)


@nb.njit(cache=True)
def _sweep_discs(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    depot: FloatArray,
    has_depot: bool,
    max_sweeps: int,
    min_gain: float,
) -> int:
    n = seq.size
    sweeps = 0
    for _ in range(max_sweeps):
        gain = 0.0
        total = 0.0
        for k in range(n):
            if k > 0:
                ax, ay = pts[k - 1, 0], pts[k - 1, 1]
            elif has_depot:
                ax, ay = depot[0], depot[1]
            else:
                ax, ay = pts[n - 1, 0], pts[n - 1, 1]
            if k < n - 1:
                bx, by = pts[k + 1, 0], pts[k + 1, 1]
            elif has_depot:
                bx, by = depot[0], depot[1]
            else:
                bx, by = pts[0, 0], pts[0, 1]
            i = seq[k]
            # Kept a hair inside, so that rounding never leaves a stop outside its disc.
            r = discs[i, 2] * (1.0 - 1e-9)
            old = _legs(ax, ay, pts[k, 0], pts[k, 1], bx, by)
            px, py = best_on_disc(ax, ay, bx, by, discs[i, 0], discs[i, 1], r)
            new = _legs(ax, ay, px, py, bx, by)
            if new < old:
                gain += old - new
                pts[k, 0] = px
                pts[k, 1] = py
            total += math.hypot(pts[k, 0] - ax, pts[k, 1] - ay)
        sweeps += 1
        if gain <= min_gain * total:
            break
    return sweeps


def closed_length(points_xy: FloatArray, depot_xy: tuple[float, float] | None) -> float:
    """Length of the closed polyline through ``points_xy`` (from the depot and back)."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    if depot_xy is not None:
        pts = np.vstack([np.asarray(depot_xy, dtype=np.float64)[None, :], pts])
    if len(pts) < 2:
        return 0.0
    return float(np.hypot(*np.diff(np.vstack([pts, pts[:1]]), axis=0).T).sum())


def _best_in_polygon(
    poly: shapely.Polygon, a: FloatArray, b: FloatArray, current: FloatArray
) -> FloatArray:
    """A point of ``poly`` near the least ``|a - p| + |p - b|``: on the segment where it
    crosses the polygon, else the best of a scan of the boundary refined by bisection."""
    seg = LineString([a, b]) if np.any(a != b) else Point(a)
    hit = poly.intersection(seg)
    if not hit.is_empty:
        near = shapely.ops.nearest_points(hit, Point(current))[0]
        return np.asarray(near.coords[0], dtype=np.float64)
    ring = poly.exterior
    length = ring.length
    at = np.linspace(0.0, length, _POLYGON_SAMPLES, endpoint=False)

    def cost(s: FloatArray) -> FloatArray:
        xy = shapely.get_coordinates(shapely.line_interpolate_point(ring, s % length))
        out: FloatArray = np.hypot(*(xy - a).T) + np.hypot(*(xy - b).T)
        return out

    values = cost(at)
    k = int(values.argmin())
    lo, hi = at[k] - length / _POLYGON_SAMPLES, at[k] + length / _POLYGON_SAMPLES
    for _ in range(30):
        trial = np.linspace(lo, hi, 5)
        j = int(cost(trial).argmin())
        lo, hi = trial[max(j - 1, 0)], trial[min(j + 1, 4)]
    s = np.asarray([0.5 * (lo + hi)])
    out: FloatArray = shapely.get_coordinates(shapely.line_interpolate_point(ring, s % length))[0]
    return out


def refine_touches(
    regions: RegionSet,
    seq: IntArray,
    points_xy: FloatArray,
    accept: Accept | None = None,
    max_sweeps: int = _MAX_SWEEPS,
) -> FloatArray:
    """Move every touch within its region, the order fixed; never lengthens the tour.

    Parameters
    ----------
    regions
        The regions and the depot.
    seq
        Region of each touch, in tour order.
    points_xy
        Where each touch is now (each inside its region).
    accept
        For a move of touch ``k`` to a point, whether it may be made (it is called only for
        moves that shorten the tour); None accepts every move inside the region.
    max_sweeps
        At most this many sweeps.

    Returns
    -------
    numpy.ndarray
        The touches' new points, each in its region.
    """
    pts = np.array(points_xy, dtype=np.float64).reshape(-1, 2)
    idx = np.asarray(seq, dtype=np.int64)
    if len(pts) == 0:
        return pts
    has_depot = regions.depot_xy is not None
    depot = np.asarray(regions.depot_xy if has_depot else (0.0, 0.0), dtype=np.float64)
    if regions.discs is not None and accept is None:
        _sweep_discs(idx, pts, regions.discs, depot, has_depot, max_sweeps, _SWEEP_GAIN)
        return pts
    n = len(pts)
    for _ in range(max_sweeps):
        gain = 0.0
        for k in range(n):
            a = pts[k - 1] if k > 0 or not has_depot else depot
            b = pts[k + 1] if k < n - 1 else (depot if has_depot else pts[0])
            old = float(np.hypot(*(pts[k] - a)) + np.hypot(*(pts[k] - b)))
            if regions.discs is not None:
                cx, cy, r = regions.discs[idx[k]]
                px, py = best_on_disc(a[0], a[1], b[0], b[1], cx, cy, r * (1.0 - 1e-9))
                p = np.asarray([px, py], dtype=np.float64)
            else:
                assert regions.polygons is not None
                p = _best_in_polygon(regions.polygons[idx[k]], a, b, pts[k])
            new = float(np.hypot(*(p - a)) + np.hypot(*(p - b)))
            if new < old and (accept is None or accept(k, p)):
                gain += old - new
                pts[k] = p
        if gain <= _SWEEP_GAIN * max(closed_length(pts, regions.depot_xy), 1e-300):
            break
    return pts
