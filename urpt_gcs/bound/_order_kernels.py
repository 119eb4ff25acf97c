"""Compiled kernels of the order search: the fixed-order problem over convex sets, solved by a
primal-dual iteration and certified by weak duality, and the geometry of a node's polyline.

``min sum_i |p_(i+1) - p_i|, p_i in C_i`` for a cyclic sequence of convex polygons ``C_i``
grown by radii ``r_i``: for any ``u_i`` with ``|u_i| <= 1`` the value
``sum_i min_(q in C_i) q . (u_(i-1) - u_i)`` bounds it from below
(:mod:`urpt_gcs.bound.order_bound` has the derivation). Sets are numbered; set ``s`` has the
vertices ``vx[vptr[s]:vptr[s + 1]], vy[...]`` and the radius ``rad[s]``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray

__all__ = ["I64", "_far_regions", "_insert_all", "_meets_star", "solve_order"]

I64 = npt.NDArray[np.int64]

# Primal-dual iterations: how often the certificate is evaluated.
_CHECK_EVERY = 25
# Relative primal-dual gap at which a node's solve stops.
_NODE_TOL = 2e-6
# Relative slack against rounding in every certified value.
_ROUNDING = 1e-10


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
