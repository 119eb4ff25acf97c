"""Convex supersets of outer stars and polygons: what the order search bounds over.

A region's superset is the convex hull of its outer star (exact for a disc), or of a piece of
it (a range of its sectors); for a region given as a polygon, the hull of its part in those
sectors. Hulls lose short edges where that moves them out only a little.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from scipy.spatial import ConvexHull, QhullError
from shapely.geometry import Polygon

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.regions import OuterStar

__all__ = ["fewer_vertices", "in_star", "is_disc", "shape_hull", "star_hull"]

# Sub-arcs per turn at least: each is covered by the triangle of its tangents, at most
# 1 / cos(pi / 256) - 1 = 7.5e-5 relative beyond the arc.
_SUBARCS = 256
# Hulls of more points than this are Qhull's (scipy), fewer the monotone chain's.
_QHULL_FROM = 64
# Such hulls lose short edges where that moves them out by at most this share of the star's
# widest reach (a finely walked star's hull has hundreds of vertices, and a node's solve
# takes time in proportion to its sets' vertices).
_SIMPLIFY = 1e-5


def star_hull(star: OuterStar, k0: int, count: int) -> FloatArray:
    """Counter-clockwise vertices of a convex polygon holding the star's sectors
    ``k0 .. k0 + count - 1`` (modulo the sector count) and its centre."""
    n = star.reach_m.size
    cx, cy = star.center_xy
    j = k0 + np.arange(count)  # unwrapped: runs do not break where the index wraps
    r = star.reach_m[j % n]
    j, r = j[r > 0.0], r[r > 0.0]
    # Runs of sectors next to each other with one reach are one arc (a finely walked star
    # repeats each coarse sector's reach), split into sub-arcs no wider than a _SUBARCS-th
    # of a turn.
    new = np.ones(len(j), dtype=bool)
    new[1:] = (np.diff(j) != 1) | (np.diff(r) != 0.0)
    starts = np.flatnonzero(new)
    run = np.diff(np.append(starts, len(j)))
    sub = np.maximum(1, -(-run * _SUBARCS // n))
    first = np.repeat(j[starts].astype(np.float64), sub)
    width = np.repeat(run / sub, sub)  # in sectors
    s = np.arange(int(sub.sum())) - np.repeat(np.cumsum(sub) - sub, sub)
    a = (2.0 * math.pi / n) * (first + s * width)
    b = a + (2.0 * math.pi / n) * width
    rr = np.repeat(r[starts], sub) * (1.0 + 1e-12)
    tip = rr / np.cos(0.5 * (b - a))
    m = 0.5 * (a + b)
    ang = np.concatenate([a, m, b])
    rad = np.concatenate([rr, tip, rr])
    pts = np.vstack([[cx, cy], np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)])])
    if len(pts) > _QHULL_FROM:
        try:
            hull = ConvexHull(pts)
        except QhullError:
            return _hull(pts)
        # Qhull gives a 2-d hull's vertices counter-clockwise.
        return fewer_vertices(pts[hull.vertices], _SIMPLIFY * float(rr.max()))
    return _hull(pts)


def fewer_vertices(poly: FloatArray, tol: float) -> FloatArray:
    """A convex polygon holding ``poly`` (convex, counter-clockwise) with fewer vertices:
    an edge is dropped and its neighbours extended to meet where that point lies at most
    ``tol`` beyond it, so the polygon grows by at most ``tol`` anywhere."""
    while len(poly) > 3:
        a = poly
        b = np.roll(poly, -1, axis=0)  # edge i runs a[i] -> b[i]
        before = a - np.roll(a, 1, axis=0)  # edge i - 1's direction
        after = np.roll(b, -1, axis=0) - b  # edge i + 1's direction
        # The line of edge i - 1 (a + t before) meets that of edge i + 1 (b + s after).
        den = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
        ab = b - a
        length = np.hypot(ab[:, 0], ab[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (ab[:, 0] * after[:, 1] - ab[:, 1] * after[:, 0]) / den
            w = a + t[:, None] * before
            # How far w lies beyond edge i (to its right: the polygon runs counter-clockwise).
            beyond = (ab[:, 0] * (a[:, 1] - w[:, 1]) - ab[:, 1] * (a[:, 0] - w[:, 0])) / length
        # The neighbours turn left by less than half a turn and meet ahead of a: beyond edge i.
        ok = (den > 0.0) & (t >= 0.0) & np.isfinite(beyond) & (beyond <= tol)
        score = np.where(ok, beyond, np.inf)
        # Edges dropped in one pass are never next to each other.
        drop = ok & (score < np.roll(score, 1)) & (score <= np.roll(score, -1))
        if not drop.any():
            break
        # Edge i dropped: its ends a[i] and b[i] = a[i + 1] become the one point w[i].
        poly = np.where(drop[:, None], w, a)[~np.roll(drop, 1)]
    return np.ascontiguousarray(poly)


def _hull(pts: FloatArray) -> FloatArray:
    """Convex hull (Andrew's monotone chain), counter-clockwise, no repeated end point."""
    p = np.unique(pts, axis=0)
    if len(p) <= 2:
        return p

    def chain(seq: FloatArray) -> list[FloatArray]:
        out: list[FloatArray] = []
        for q in seq:
            while len(out) >= 2:
                a, b = out[-2], out[-1]
                if (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) > 0.0:
                    break
                out.pop()
            out.append(q)
        return out

    lower = chain(p)
    upper = chain(p[::-1])
    return np.asarray(lower[:-1] + upper[:-1])


def is_disc(star: OuterStar) -> bool:
    """Whether the star is a disc about its centre (every sector the same reach)."""
    return bool(np.all(star.reach_m == star.reach_m[0]))


def in_star(star: OuterStar, x: float, y: float, slack: float) -> bool:
    """Whether the point lies in the star (within ``slack`` metres)."""
    cx, cy = star.center_xy
    d = math.hypot(x - cx, y - cy)
    if d <= slack:
        return True
    n = star.reach_m.size
    t = math.atan2(y - cy, x - cx) % (2.0 * math.pi)
    k = min(int(t / (2.0 * math.pi) * n), n - 1)
    return d <= float(star.reach_m[k]) + slack


def shape_hull(shape: Polygon, star: OuterStar, k0: int, count: int) -> tuple[FloatArray, float]:
    """The hull of the polygon's part in sectors ``k0 .. k0 + count - 1`` about the star's
    centre, grown a hair against rounding.

    Parameters
    ----------
    shape
        The region as a polygon.
    star
        Its outer star: the centre and sector count the pieces are taken about.
    k0, count
        The first sector of the piece and how many sectors it spans (modulo the count).

    Returns
    -------
    vertices : numpy.ndarray
        Counter-clockwise hull vertices, ``(k, 2)``; none when the piece is empty.
    grow_m : float
        The radius the hull is grown by.
    """
    n = star.reach_m.size
    part = shape
    if count < n:
        cx, cy = star.center_xy
        far = 2.0 * float(star.reach_m.max()) + 1.0
        a = np.linspace(2.0 * math.pi * k0 / n, 2.0 * math.pi * (k0 + count) / n, 4 * count + 1)
        wedge = Polygon([(cx, cy), *zip(cx + far * np.cos(a), cy + far * np.sin(a), strict=True)])
        part = shape.intersection(wedge)
    xy = shapely.get_coordinates(part)
    if len(xy) == 0:
        return np.zeros((0, 2)), 0.0
    return _hull(xy), 1e-9 * (1.0 + float(np.abs(xy).max()))
