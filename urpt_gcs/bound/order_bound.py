"""A lower bound by branch and bound over visiting orders, each node certified by duality.

A node is a cyclic *sequence* of some of the regions (the depot, if any, is one of them). Any
tour enters every region; keeping one entry point per region of the sequence, in the order the
tour reaches them, gives a closed polyline no longer than the tour (triangle inequality) that
visits the sequence's regions in one cyclic order. So the shortest closed polyline visiting,
in the sequence's order, *convex supersets* ``C_i`` of those regions bounds every tour whose
restriction to them has that order. Inserting a further region at each position of the
sequence gives children that cover every such tour between them; the root is three regions
(one cyclic order, up to reversal, which leaves lengths alone).

The fixed-order problem ``min sum_i |p_(i+1) - p_i|, p_i in C_i`` is bounded by weak duality:
for any ``u_i`` with ``|u_i| <= 1``, ``|d| >= u . d`` gives

    ``sum_i |p_(i+1) - p_i| >= sum_i p_i . (u_(i-1) - u_i) >= sum_i min_(q in C_i) q . w_i``

with ``w_i = u_(i-1) - u_i``. Each ``C_i`` here is a convex polygon grown by a radius ``r_i``
(a disc is a point grown by its radius), so the minimum is ``min_v v . w_i - r_i |w_i|`` over
the polygon's vertices: a certificate that does not rely on the solver having converged. The
multipliers come from a primal-dual (Chambolle-Pock) iteration on the saddle problem.

A region's superset is the convex hull of its outer star (exact for a disc); for a star that
is not convex, when the node's point for it lies in the hull but outside the star, the node is
branched on which angular half of the star piece holds the tour's entry point.

The bound is the least certified value over the nodes not pruned when the search stops, so it
holds whenever it stops. Nodes whose certified value reaches the known tour length are pruned.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass

import numba as nb
import numpy as np
import numpy.typing as npt
import shapely
from scipy.spatial import ConvexHull, QhullError
from shapely.geometry import LineString, Point, Polygon

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.regions import OuterStar

I64 = npt.NDArray[np.int64]

# Sub-arcs per turn at least: each is covered by the triangle of its tangents, at most
# 1 / cos(pi / 256) - 1 = 7.5e-5 relative beyond the arc.
_SUBARCS = 256
# Hulls of more points than this are Qhull's (scipy), fewer the monotone chain's.
_QHULL_FROM = 64
# Such hulls lose short edges where that moves them out by at most this share of the star's
# widest reach (a finely walked star's hull has hundreds of vertices, and a node's solve
# takes time in proportion to its sets' vertices).
_SIMPLIFY = 1e-5
# Primal-dual iterations per node, and how often the certificate is evaluated.
_NODE_ITERATIONS = 4000
_CHECK_EVERY = 25
# Relative primal-dual gap at which a node's solve stops.
_NODE_TOL = 2e-6
# Relative slack against rounding in every certified value.
_ROUNDING = 1e-10
# Regions tried for insertion at each branching (the farthest from the node's polyline).
_STRONG = 1
# Open nodes kept at most (memory); past it the search stops.
_MAX_OPEN = 250_000


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


# --- kernels ------------------------------------------------------------------------------


@nb.njit(cache=True)
def _project(
    x: float, y: float, s: int, vptr: I64, vx: FloatArray, vy: FloatArray, rad: FloatArray
) -> tuple[float, float]:
    """The point of set ``s`` (convex polygon grown by ``rad[s]``) nearest to ``(x, y)``."""
    lo, hi = vptr[s], vptr[s + 1]
    nv = hi - lo
    qx, qy = vx[lo], vy[lo]
    if nv >= 3:
        inside = True
        for e in range(nv):
            ax, ay = vx[lo + e], vy[lo + e]
            bx, by = vx[lo + (e + 1) % nv], vy[lo + (e + 1) % nv]
            if (bx - ax) * (y - ay) - (by - ay) * (x - ax) < 0.0:
                inside = False
                break
        if inside:
            return x, y
    if nv >= 2:
        best = np.inf
        for e in range(nv):
            ax, ay = vx[lo + e], vy[lo + e]
            bx, by = vx[lo + (e + 1) % nv], vy[lo + (e + 1) % nv]
            dx, dy = bx - ax, by - ay
            ll = dx * dx + dy * dy
            t = 0.0 if ll <= 0.0 else ((x - ax) * dx + (y - ay) * dy) / ll
            t = min(max(t, 0.0), 1.0)
            px, py = ax + t * dx, ay + t * dy
            d = (x - px) ** 2 + (y - py) ** 2
            if d < best:
                best, qx, qy = d, px, py
    r = rad[s]
    dx, dy = x - qx, y - qy
    d = math.hypot(dx, dy)
    if d <= r:
        return x, y
    return qx + r * dx / d, qy + r * dy / d


@nb.njit(cache=True)
def _support_min(
    wx: float, wy: float, s: int, vptr: I64, vx: FloatArray, vy: FloatArray, rad: FloatArray
) -> float:
    """``min_(q in set s) q . w``."""
    best = np.inf
    for v in range(vptr[s], vptr[s + 1]):
        d = vx[v] * wx + vy[v] * wy
        if d < best:
            best = d
    return float(best - rad[s] * math.hypot(wx, wy))


@nb.njit(cache=True)
def _certify(
    seq: I64, ux: FloatArray, uy: FloatArray, vptr: I64, vx: FloatArray, vy: FloatArray,
    rad: FloatArray, scale: float,
) -> float:  # fmt: skip
    """The weak-duality value at ``u`` (shrunk into the unit ball), less a rounding slack."""
    k = seq.size
    total = 0.0
    mag = 0.0
    for i in range(k):
        j = (i - 1) % k
        ax, ay = ux[j], uy[j]
        bx, by = ux[i], uy[i]
        na = math.hypot(ax, ay)
        nb_ = math.hypot(bx, by)
        if na > 1.0 - 1e-13:
            ax, ay = ax * (1.0 - 1e-13) / na, ay * (1.0 - 1e-13) / na
        if nb_ > 1.0 - 1e-13:
            bx, by = bx * (1.0 - 1e-13) / nb_, by * (1.0 - 1e-13) / nb_
        total += _support_min(ax - bx, ay - by, seq[i], vptr, vx, vy, rad)
        mag += scale
    return total - _ROUNDING * mag - 1e-12 * k


@nb.njit(cache=True)
def _length(px: FloatArray, py: FloatArray) -> float:
    k = px.size
    total = 0.0
    for i in range(k):
        j = (i + 1) % k
        total += math.hypot(px[j] - px[i], py[j] - py[i])
    return total


@nb.njit(cache=True)
def solve_order(
    seq: I64, px: FloatArray, py: FloatArray, ux: FloatArray, uy: FloatArray,
    vptr: I64, vx: FloatArray, vy: FloatArray, rad: FloatArray,
    step: float, prune_at: float, scale: float, iterations: int,
) -> tuple[float, float]:  # fmt: skip
    """Chambolle-Pock on the fixed-order problem from ``(p, u)`` (updated in place).

    Returns ``(primal, certified)``: the length of the closed polyline through ``p`` (each
    ``p_i`` in its set) and the best weak-duality value met. ``step`` is the primal step
    (metres); the dual step is ``0.24 / step``, so that their product times ``|K|^2 <= 4``
    stays below one."""
    k = seq.size
    tau = step
    sigma = 0.24 / step
    bx = px.copy()
    by = py.copy()
    best_ux = ux.copy()
    best_uy = uy.copy()
    dirx = np.empty(k)
    diry = np.empty(k)
    best_l = -np.inf
    # The starting points need not lie in their sets (a split piece): lengths count only
    # after a projection.
    primal = np.inf
    for it in range(iterations + 1):
        if it % _CHECK_EVERY == 0:
            if it > 0:
                primal = min(primal, _length(px, py))
            cert = _certify(seq, ux, uy, vptr, vx, vy, rad, scale)
            if cert > best_l:
                best_l = cert
                best_ux[:] = ux
                best_uy[:] = uy
            # The multipliers the legs' own directions give (where a leg has a length).
            for i in range(k):
                j = (i + 1) % k
                dx, dy = px[j] - px[i], py[j] - py[i]
                d = math.hypot(dx, dy)
                if d > 1e-9 * scale:
                    dirx[i], diry[i] = dx / d, dy / d
                else:
                    dirx[i], diry[i] = ux[i], uy[i]
            cert = _certify(seq, dirx, diry, vptr, vx, vy, rad, scale)
            if cert > best_l:
                best_l = cert
                best_ux[:] = dirx
                best_uy[:] = diry
            if best_l >= prune_at or (it > 0 and primal - best_l <= _NODE_TOL * primal):
                break
            if it == iterations:
                break
        for i in range(k):
            j = (i + 1) % k
            ax = ux[i] + sigma * (bx[j] - bx[i])
            ay = uy[i] + sigma * (by[j] - by[i])
            n = math.hypot(ax, ay)
            if n > 1.0:
                ax, ay = ax / n, ay / n
            ux[i], uy[i] = ax, ay
        for i in range(k):
            j = (i - 1) % k
            qx = px[i] - tau * (ux[j] - ux[i])
            qy = py[i] - tau * (uy[j] - uy[i])
            nx, ny = _project(qx, qy, seq[i], vptr, vx, vy, rad)
            bx[i] = 2.0 * nx - px[i]
            by[i] = 2.0 * ny - py[i]
            px[i], py[i] = nx, ny
    ux[:] = best_ux
    uy[:] = best_uy
    return min(primal, _length(px, py)), best_l


@nb.njit(cache=True)
def _seg_dist(
    ax: float, ay: float, bx: float, by: float, s: int,
    vptr: I64, vx: FloatArray, vy: FloatArray, rad: FloatArray,
) -> float:  # fmt: skip
    """Distance from segment ``ab`` to set ``s`` (0 when they meet)."""
    lo, hi = vptr[s], vptr[s + 1]
    nv = hi - lo
    dx, dy = bx - ax, by - ay
    ll = dx * dx + dy * dy
    best = np.inf
    for v in range(lo, hi):
        t = 0.0 if ll <= 0.0 else ((vx[v] - ax) * dx + (vy[v] - ay) * dy) / ll
        t = min(max(t, 0.0), 1.0)
        d = math.hypot(vx[v] - ax - t * dx, vy[v] - ay - t * dy)
        if d < best:
            best = d
    if nv >= 2:
        for q in range(2):
            x = ax if q == 0 else bx
            y = ay if q == 0 else by
            qx, qy = _project(x, y, s, vptr, vx, vy, rad)
            d = math.hypot(x - qx, y - qy) + rad[s]
            if d < best:
                best = d
        # The segment crossing an edge.
        for e in range(nv):
            cx, cy = vx[lo + e], vy[lo + e]
            ex, ey = vx[lo + (e + 1) % nv], vy[lo + (e + 1) % nv]
            d1 = (ex - cx) * (ay - cy) - (ey - cy) * (ax - cx)
            d2 = (ex - cx) * (by - cy) - (ey - cy) * (bx - cx)
            d3 = dx * (cy - ay) - dy * (cx - ax)
            d4 = dx * (ey - ay) - dy * (ex - ax)
            if d1 * d2 <= 0.0 and d3 * d4 <= 0.0:
                return 0.0
    return float(max(best - rad[s], 0.0))


@nb.njit(cache=True)
def _far_regions(
    px: FloatArray, py: FloatArray, cand: I64, vptr: I64, vx: FloatArray, vy: FloatArray,
    rad: FloatArray, out: FloatArray,
) -> None:  # fmt: skip
    """Per candidate set: its distance to the closed polyline through ``p``."""
    k = px.size
    for c in range(cand.size):
        best = np.inf
        for i in range(k):
            j = (i + 1) % k
            d = _seg_dist(px[i], py[i], px[j], py[j], cand[c], vptr, vx, vy, rad)
            if d < best:
                best = d
                if d == 0.0:
                    break
        out[c] = best


@nb.njit(cache=True)
def _meets_star(
    px: FloatArray, py: FloatArray, cx: float, cy: float, reach: FloatArray, slack: float
) -> bool:
    """Whether the closed polyline through ``p`` meets the star (centre, sector reaches)."""
    k = px.size
    n = reach.size
    for i in range(k):
        j = (i + 1) % k
        ax, ay = px[i] - cx, py[i] - cy
        dx, dy = px[j] - px[i], py[j] - py[i]
        for s in range(n):
            a = 2.0 * math.pi * s / n
            b = 2.0 * math.pi * (s + 1) / n
            ea, eb = (math.cos(a), math.sin(a)), (math.cos(b), math.sin(b))
            lo, hi = 0.0, 1.0
            # Left of the ray at angle a, right of the ray at angle b (sectors narrower than pi).
            for f0, f1 in (
                (ea[0] * ay - ea[1] * ax, ea[0] * (ay + dy) - ea[1] * (ax + dx)),
                (ax * eb[1] - ay * eb[0], (ax + dx) * eb[1] - (ay + dy) * eb[0]),
            ):
                if f0 < 0.0 and f1 < 0.0:
                    lo, hi = 1.0, 0.0
                elif f0 < 0.0:
                    lo = max(lo, f0 / (f0 - f1))
                elif f1 < 0.0:
                    hi = min(hi, f0 / (f0 - f1))
            if lo > hi:
                continue
            ll = dx * dx + dy * dy
            t = 0.0 if ll <= 0.0 else -(ax * dx + ay * dy) / ll
            t = min(max(t, lo), hi)
            if math.hypot(ax + t * dx, ay + t * dy) <= reach[s] + slack:
                return True
    return False


# --- the search ---------------------------------------------------------------------------


def _shape_hull(shape: Polygon, star: OuterStar, k0: int, count: int) -> tuple[FloatArray, float]:
    """The hull of the polygon's part in sectors ``k0 .. k0 + count - 1`` about the star's
    centre (empty: no vertex), grown a hair against rounding."""
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


class _Sets:
    """Convex supersets, numbered: per region its whole star's hull and, on demand, hulls of
    star pieces ``(region, first sector, sector count)``."""

    def __init__(
        self,
        stars: list[OuterStar | None],
        depot_xy: tuple[float, float] | None,
        shapes: list[Polygon | None] | None = None,
    ):
        self.stars = stars
        self.depot_xy = depot_xy
        self.shapes = shapes or [None] * len(stars)
        self.key: dict[tuple[int, int, int], int] = {}
        self.piece: list[tuple[int, int, int]] = []
        self.verts: list[FloatArray] = []
        self.radius: list[float] = []
        self.region_of = np.zeros(0, dtype=np.int64)
        self._arrays: tuple[I64, FloatArray, FloatArray, FloatArray] | None = None
        for i in range(len(stars)):
            self.get(i, 0, self.sectors(i))

    def sectors(self, region: int) -> int:
        star = self.stars[region]
        return 1 if star is None else int(star.reach_m.size)

    def get(self, region: int, k0: int, count: int) -> int:
        key = (region, k0, count)
        if key in self.key:
            return self.key[key]
        star = self.stars[region]
        if star is None:
            assert self.depot_xy is not None
            verts, r = np.asarray([self.depot_xy], dtype=np.float64), 0.0
        elif self.shapes[region] is not None:
            verts, r = _shape_hull(self.shapes[region], star, k0, count)
        elif is_disc(star):
            verts, r = np.asarray([star.center_xy], dtype=np.float64), float(star.reach_m[0])
        else:
            verts, r = star_hull(star, k0, count), 0.0
        self.key[key] = len(self.piece)
        self.piece.append(key)
        self.verts.append(verts)
        self.radius.append(r)
        self.region_of = np.append(self.region_of, region)
        self._arrays = None
        return self.key[key]

    def holds(self, region: int, x: float, y: float, slack: float) -> bool:
        """Whether the region's star (or shape) holds the point, to ``slack``."""
        shape, star = self.shapes[region], self.stars[region]
        if shape is not None:
            return bool(shape.distance(Point(x, y)) <= slack)
        return star is None or in_star(star, x, y, slack)

    def met_by(self, region: int, px: FloatArray, py: FloatArray, slack: float) -> bool:
        """Whether the closed polyline through ``p`` meets the region's star (or shape)."""
        shape, star = self.shapes[region], self.stars[region]
        if shape is not None:
            ring = LineString(np.column_stack([np.append(px, px[0]), np.append(py, py[0])]))
            return bool(shape.distance(ring) <= slack)
        if star is None or is_disc(star):
            return True
        return bool(_meets_star(px, py, *star.center_xy, star.reach_m, slack))

    def arrays(self) -> tuple[I64, FloatArray, FloatArray, FloatArray]:
        if self._arrays is None:
            ptr = np.zeros(len(self.verts) + 1, dtype=np.int64)
            np.cumsum([len(v) for v in self.verts], out=ptr[1:])
            flat = np.vstack(self.verts)
            self._arrays = (
                ptr,
                np.ascontiguousarray(flat[:, 0]),
                np.ascontiguousarray(flat[:, 1]),
                np.asarray(self.radius, dtype=np.float64),
            )
        return self._arrays


@dataclass(frozen=True, slots=True)
class OrderBound:
    """The least certified value over the search's open ends, and how far it went."""

    value: float
    nodes: int
    open_nodes: int
    finished: bool
    seconds: float
    # The shortest closed polyline met that meets every set searched (the stars, or the
    # shapes where given; when the search met none, one a dive found): a real tour when
    # those are the regions themselves.
    leaf_length: float = math.inf
    # That polyline's points, in order.
    leaf_xy: FloatArray | None = None


@dataclass(slots=True)
class _Node:
    seq: I64  # set ids in cyclic order
    px: FloatArray
    py: FloatArray
    ux: FloatArray
    uy: FloatArray
    cert: float
    primal: float


def order_bound(
    stars: list[OuterStar | None],
    depot_xy: tuple[float, float] | None,
    upper: float,
    time_limit_s: float,
    gap_target: float = 1e-4,
    shapes: list[Polygon | None] | None = None,
    max_nodes: int | None = None,
    strong: int | None = None,
) -> OrderBound:
    """A lower bound of every closed tour entering every star (``None``: the depot point).

    ``shapes[i]``, where given, is region ``i`` itself (inside its star): its pieces are then
    hulls of the shape, not of the star. The search stops when its bound reaches
    ``upper * (1 - gap_target)``, when the open nodes reach (to half the gap target) the
    least value closed -- a polyline met that meets every set, or a pruned node -- past
    which the bound cannot rise, when nothing is left open, or at the time limit; the bound
    holds in every case (``finished`` in the first three). ``max_nodes`` also stops it after
    that many node solves; ``strong`` is how many regions each branching tries."""
    started = time.perf_counter()
    m = len(stars)
    if m <= 1:
        return OrderBound(0.0, 0, 0, True, 0.0)
    sets = _Sets(stars, depot_xy, shapes)
    cx = np.asarray([s.center_xy[0] if s else depot_xy[0] for s in stars])  # type: ignore[index]
    cy = np.asarray([s.center_xy[1] if s else depot_xy[1] for s in stars])  # type: ignore[index]
    cr = np.asarray([float(s.reach_m.max()) if s else 0.0 for s in stars])
    scale = float(np.abs(cx).max() + np.abs(cy).max() + cr.max() + 1.0)
    spread = float(np.hypot(cx - cx.mean(), cy - cy.mean()).mean() + cr.mean())
    step = max(0.15 * spread, 1e-9)
    prune_at = upper * (1.0 - 0.5 * gap_target)

    # The root: three regions far apart (the depot first, when there is one).
    first = (
        [m - 1]
        if depot_xy is not None
        else [int(np.argmax(np.hypot(cx - cx.mean(), cy - cy.mean()) + cr))]
    )
    while len(first) < min(3, m):
        gap = np.min([np.hypot(cx - cx[j], cy - cy[j]) - cr - cr[j] for j in first], axis=0)
        gap[first] = -np.inf
        first.append(int(np.argmax(gap)))
    seq = np.asarray([j for j in first], dtype=np.int64)
    root = _Node(
        seq, cx[seq].copy(), cy[seq].copy(), np.zeros(len(seq)), np.zeros(len(seq)), 0.0, 0.0
    )
    _solve(root, sets, step, prune_at, scale)

    closed = math.inf  # the least certified value of the nodes taken out for good
    heap: list[tuple[float, int, _Node]] = []
    counter = 0
    nodes = 1
    if root.cert >= prune_at:
        closed = root.cert
    else:
        heap.append((root.cert, 0, root))
    finished = True
    done = False  # stopped where searching on cannot raise the bound enough, nodes still open
    leaf = math.inf
    leaf_node: _Node | None = None
    while heap:
        # The bound is the least of the values closed and the open nodes': once the open
        # nodes reach the least closed (a polyline met that meets every set: the relaxation
        # is solved), searching on cannot raise it.
        if heap[0][0] >= min(prune_at, closed * (1.0 - 0.5 * gap_target)):
            done = True
            break
        over = max_nodes is not None and nodes >= max_nodes
        if over or time.perf_counter() - started >= time_limit_s or len(heap) >= _MAX_OPEN:
            finished = False
            break
        _, _, node = heapq.heappop(heap)
        ways = _branch(node, sets, m, _STRONG if strong is None else strong)
        if ways is None:
            # Every region met: this node's value bounds all its completions.
            closed = min(closed, node.cert)
            if node.primal < leaf:
                leaf, leaf_node = node.primal, node
            continue
        for way in ways:
            for child in way:
                _solve(child, sets, step, prune_at, scale)
            nodes += len(way)
        # Any way is a valid branching: take the one whose weakest child is strongest.
        children = max(ways, key=lambda w: min((c.cert for c in w), default=math.inf))
        for child in children:
            if child.cert >= prune_at:
                closed = min(closed, child.cert)
            else:
                counter += 1
                heapq.heappush(heap, (child.cert, counter, child))
    open_low = heap[0][0] if heap else math.inf
    value = min(closed, open_low, upper)
    if leaf_node is None and heap:
        # The dive may overrun the time limit by a quarter of it at most.
        deadline = max(started + time_limit_s, time.perf_counter()) + _DIVE_SHARE * time_limit_s
        leaf_node = _dive(heap[0][2], sets, m, step, scale, deadline)
        leaf = math.inf if leaf_node is None else leaf_node.primal
    seconds = time.perf_counter() - started
    leaf_xy = None if leaf_node is None else np.column_stack([leaf_node.px, leaf_node.py])
    return OrderBound(
        max(value, 0.0), nodes, len(heap), done or (finished and not heap), seconds, leaf,
        leaf_xy,
    )  # fmt: skip


# Node solves a dive for a polyline meeting every set may take at most (a dive inserts
# one region a step, a child per position: it is for a few tens of regions).
_DIVE_SOLVES = 400
_DIVE_SHARE = 0.25


def _dive(
    node: _Node, sets: _Sets, m: int, step: float, scale: float, deadline: float
) -> _Node | None:
    """From an open node, always into the child with the shortest polyline, until one meets
    every set (None when the dive's budget or ``deadline`` runs out first): a polyline for a
    tour to be read off when the search stopped before meeting one. It bounds nothing."""
    solves = 0
    while solves < _DIVE_SOLVES and time.perf_counter() < deadline:
        ways = _branch(node, sets, m, 1)
        if ways is None:
            return node
        children = ways[0]
        if not children or solves + len(children) > _DIVE_SOLVES:
            return None
        for child in children:
            if time.perf_counter() >= deadline:
                return None
            _solve(child, sets, step, math.inf, scale)
        solves += len(children)
        node = min(children, key=lambda c: c.primal)
    return None


def _solve(node: _Node, sets: _Sets, step: float, prune_at: float, scale: float) -> None:
    vptr, vx, vy, rad = sets.arrays()
    primal, cert = solve_order(
        node.seq, node.px, node.py, node.ux, node.uy, vptr, vx, vy, rad,
        step, prune_at, scale, _NODE_ITERATIONS,
    )  # fmt: skip
    node.primal, node.cert = primal, cert


def _branch(node: _Node, sets: _Sets, m: int, strong: int) -> list[list[_Node]] | None:
    """Ways to branch a node (each a list of children that cover its completions between
    them; up to ``strong`` regions to insert), or None when its polyline meets every set."""
    absent = np.ones(m, dtype=np.bool_)
    absent[sets.region_of[node.seq]] = False
    slack = 1e-9 * (1.0 + abs(node.primal))
    vptr, vx, vy, rad = sets.arrays()
    missing = np.flatnonzero(absent)
    if missing.size:
        dist = np.empty(missing.size)
        _far_regions(node.px, node.py, missing, vptr, vx, vy, rad, dist)
        far = np.argsort(-dist)[:strong]
        far = far[dist[far] > 1e-9 * (1.0 + abs(node.primal))]
        if far.size:
            return [_insertions(node, int(missing[f]), sets) for f in far]
        # The polyline meets every hull; a star it misses all the same (a crescent's notch).
        for j in missing:
            if not sets.met_by(int(j), node.px, node.py, slack):
                return [_insertions(node, int(j), sets)]
    # A point in its piece's hull but outside the star: split that piece.
    for pos, s in enumerate(node.seq):
        region, k0, count = sets.piece[int(s)]
        star = sets.stars[region]
        if star is None or count <= 1 or (is_disc(star) and sets.shapes[region] is None):
            continue
        if sets.holds(region, float(node.px[pos]), float(node.py[pos]), slack):
            continue
        half = count // 2
        out = []
        for a, c in ((k0, half), ((k0 + half) % sets.sectors(region), count - half)):
            child = _copy(node)
            child.seq[pos] = sets.get(region, a, c)
            if len(sets.verts[int(child.seq[pos])]):
                out.append(child)
        return [out]
    return None


def _copy(node: _Node) -> _Node:
    return _Node(
        node.seq.copy(),
        node.px.copy(),
        node.py.copy(),
        node.ux.copy(),
        node.uy.copy(),
        node.cert,
        node.primal,
    )


def _insertions(node: _Node, region: int, sets: _Sets) -> list[_Node]:
    """The children inserting ``region`` after each position of the node's sequence."""
    s = sets.get(region, 0, sets.sectors(region))
    vptr, vx, vy, rad = sets.arrays()
    seq, px, py, ux, uy = _insert_all(
        node.seq, node.px, node.py, node.ux, node.uy, s, vptr, vx, vy, rad
    )
    return [
        _Node(seq[c], px[c], py[c], ux[c], uy[c], node.cert, node.primal)
        for c in range(node.seq.size)
    ]


@nb.njit(cache=True)
def _insert_all(
    seq: I64, px: FloatArray, py: FloatArray, ux: FloatArray, uy: FloatArray, s: int,
    vptr: I64, vx: FloatArray, vy: FloatArray, rad: FloatArray,
) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """Row ``c``: the sequence with set ``s`` after position ``c``, its new point the set's
    point nearest the middle of the leg it splits, its new leg's multiplier the split leg's."""
    k = seq.size
    oseq = np.empty((k, k + 1), dtype=np.int64)
    opx = np.empty((k, k + 1))
    opy = np.empty((k, k + 1))
    oux = np.empty((k, k + 1))
    ouy = np.empty((k, k + 1))
    for c in range(k):
        b = (c + 1) % k
        qx, qy = _project(0.5 * (px[c] + px[b]), 0.5 * (py[c] + py[b]), s, vptr, vx, vy, rad)
        for i in range(k + 1):
            if i <= c:
                src = i
            elif i == c + 1:
                src = -1
            else:
                src = i - 1
            if src >= 0:
                oseq[c, i], opx[c, i], opy[c, i] = seq[src], px[src], py[src]
                oux[c, i], ouy[c, i] = ux[src], uy[src]
            else:
                oseq[c, i], opx[c, i], opy[c, i] = s, qx, qy
                oux[c, i], ouy[c, i] = ux[c], uy[c]
    return oseq, opx, opy, oux, ouy


def prepare() -> None:
    """Compile the search's kernels (cached on disk) on a tiny instance, so that a first
    bound's time limit is not spent compiling."""
    disc = OuterStar((0.0, 0.0), np.ones(8))
    notch = OuterStar((5.0, 0.0), np.asarray([1.0, 1.0, 0.2, 1.0, 1.0, 1.0, 1.0, 1.0]))
    order_bound([disc, notch, None], (0.0, 5.0), 1e9, 1.0, max_nodes=20)
