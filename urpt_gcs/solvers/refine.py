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

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.problem.regions import RegionSet

__all__ = [
    "Accept",
    "best_on_disc",
    "closed_length",
    "refine_touches",
]

# Sweeps stop once one gains less than this fraction of the tour.
_SWEEP_GAIN = 1e-10
_MAX_SWEEPS = 2000
# Points tried along a polygon's boundary before the local search.
_POLYGON_SAMPLES = 64

Accept = Callable[[int, FloatArray], bool]


@nb.njit(cache=True, nogil=True)
def _legs(ax: float, ay: float, px: float, py: float, bx: float, by: float) -> float:
    return math.hypot(px - ax, py - ay) + math.hypot(bx - px, by - py)


@nb.njit(cache=True, nogil=True)
def _slope(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, r: float, th: float
) -> tuple[float, float]:
    """First and second derivative of ``|a - p| + |p - b|`` in ``th``, ``p`` at angle ``th``
    on the circle ``(c, r)`` (``a`` and ``b`` off it)."""
    cos, sin = math.cos(th), math.sin(th)
    ux, uy = cx + r * cos - ax, cy + r * sin - ay
    vx, vy = cx + r * cos - bx, cy + r * sin - by
    tx, ty = -r * sin, r * cos
    # (Positive: at an end of the arc a stop can sit on a or b to rounding.)
    gu, gv = max(math.hypot(ux, uy), 1e-300), max(math.hypot(vx, vy), 1e-300)
    du = (ux * tx + uy * ty) / gu
    dv = (vx * tx + vy * ty) / gv
    # p'' = -(p - c): (|p'|^2 + (p - a) . p'') / g - g'^2 / g for each leg.
    ddu = (r * r - r * (ux * cos + uy * sin)) / gu - du * du / gu
    ddv = (r * r - r * (vx * cos + vy * sin)) / gv - dv * dv / gv
    return du + dv, ddu + ddv


@nb.njit(cache=True, nogil=True)
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
    # The optimum is on the circle, on the arc between the directions to a and to b (both
    # outside the disc here); Newton's method on the slope, kept inside a shrinking bracket.
    ta = math.atan2(ay - cy, ax - cx)
    tb = math.atan2(by - cy, bx - cx)
    span = (tb - ta + math.pi) % (2.0 * math.pi) - math.pi
    lo, hi = ta, ta + span
    if hi < lo:
        lo, hi = hi, lo
    if _slope(ax, ay, bx, by, cx, cy, r, lo)[0] >= 0.0 or (
        _slope(ax, ay, bx, by, cx, cy, r, hi)[0] <= 0.0
    ):
        f_lo = _legs(ax, ay, cx + r * math.cos(lo), cy + r * math.sin(lo), bx, by)
        f_hi = _legs(ax, ay, cx + r * math.cos(hi), cy + r * math.sin(hi), bx, by)
        th = lo if f_lo <= f_hi else hi
        return cx + r * math.cos(th), cy + r * math.sin(th)
    # From the bisector of the directions to a and to b (the answer when both are as far).
    ua, ub = math.hypot(ax - cx, ay - cy), math.hypot(bx - cx, by - cy)
    th = math.atan2((ay - cy) / ua + (by - cy) / ub, (ax - cx) / ua + (bx - cx) / ub)
    th += 2.0 * math.pi * round((0.5 * (lo + hi) - th) / (2.0 * math.pi))
    if not lo < th < hi:
        th = 0.5 * (lo + hi)
    for _ in range(100):
        g, h = _slope(ax, ay, bx, by, cx, cy, r, th)
        if g > 0.0:
            hi = th
        elif g < 0.0:
            lo = th
        else:
            break
        new = th - g / h if h > 0.0 else 0.5 * (lo + hi)
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        done = abs(new - th) <= 1e-14 * (1.0 + abs(th))
        th = new
        if done:
            break
    return cx + r * math.cos(th), cy + r * math.sin(th)


@nb.njit(cache=True, nogil=True)
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
