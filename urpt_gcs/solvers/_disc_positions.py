"""Exact stop positions for a disc tour in a fixed order (compiled kernels).

With the order fixed the shortest tour through the discs is a convex problem; it is solved
by Newton's method on a smoothed barrier (legs ``sqrt(|d|^2 + eps^2)``, discs
``-mu log(r^2 - |p - c|^2)``), whose Hessian is block tridiagonal, so a step is linear in
``n``. Per-stop moves alone (:func:`_settle`) stall where consecutive stops coincide
(overlapping discs entered at one point); a joint step does not. The tour's conventions are
:mod:`urpt_gcs.solvers.disc_tour`'s.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.solvers.refine import best_on_disc

__all__ = [
    "_INSIDE",
    "_dist",
    "_exact_window",
    "_pt",
    "_settle",
    "exact_positions",
    "path_length",
]

# Stops kept this far (relative to the radius) inside their disc.
_INSIDE = 1e-9
# Newton steps per barrier stage within the search (the exact positions of a whole tour
# allow more: from a cold start the first stages need them).
_SEARCH_STEPS = 100


@nb.njit(cache=True, nogil=True)
def _pt(pts: FloatArray, ends: FloatArray, i: int) -> tuple[float, float]:
    # ends[0] before the first stop, ends[1] after the last (both the depot for a tour).
    n = pts.shape[0]
    if i < 0:
        return ends[0, 0], ends[0, 1]
    if i >= n:
        return ends[1, 0], ends[1, 1]
    return pts[i, 0], pts[i, 1]


@nb.njit(cache=True, nogil=True)
def _dist(ax: float, ay: float, bx: float, by: float) -> float:
    return math.hypot(ax - bx, ay - by)


@nb.njit(cache=True, nogil=True)
def path_length(pts: FloatArray, ends: FloatArray) -> float:
    """Length of ends[0] -> pts[0] -> ... -> pts[n-1] -> ends[1]."""
    n = pts.shape[0]
    total = 0.0
    for i in range(n + 1):
        ax, ay = _pt(pts, ends, i - 1)
        bx, by = _pt(pts, ends, i)
        total += _dist(ax, ay, bx, by)
    return total


@nb.njit(cache=True, nogil=True)
def _settle(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    ends: FloatArray,
    lo: int,
    hi: int,
    sweeps: int = 50,
) -> float:
    """Per-stop best moves over positions ``lo..hi`` until they gain nothing (at most
    ``sweeps`` sweeps); the gain."""
    n = seq.size
    lo = max(lo, 0)
    hi = min(hi, n - 1)
    total = 0.0
    for _ in range(sweeps):
        gain = 0.0
        for k in range(lo, hi + 1):
            ax, ay = _pt(pts, ends, k - 1)
            bx, by = _pt(pts, ends, k + 1)
            i = seq[k]
            old = _dist(ax, ay, pts[k, 0], pts[k, 1]) + _dist(pts[k, 0], pts[k, 1], bx, by)
            r = discs[i, 2] * (1.0 - _INSIDE)
            px, py = best_on_disc(ax, ay, bx, by, discs[i, 0], discs[i, 1], r)
            new = _dist(ax, ay, px, py) + _dist(px, py, bx, by)
            if new < old:
                gain += old - new
                pts[k, 0] = px
                pts[k, 1] = py
        total += gain
        if gain <= 1e-13 * (1.0 + total):
            break
    return total


@nb.njit(cache=True, nogil=True)
def _barrier_value(
    seq: IntArray, x: FloatArray, discs: FloatArray, ends: FloatArray, mu: float, eps: float
) -> float:
    n = seq.size
    f = 0.0
    for leg in range(n + 1):
        ax, ay = _pt(x, ends, leg - 1)
        bx, by = _pt(x, ends, leg)
        f += math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + eps * eps)
    for k in range(n):
        i = seq[k]
        u = discs[i, 2] ** 2 - (x[k, 0] - discs[i, 0]) ** 2 - (x[k, 1] - discs[i, 1]) ** 2
        if u <= 0.0:
            return math.inf
        f -= mu * math.log(u)
    return f


@nb.njit(cache=True, nogil=True)
def _newton_stage(
    seq: IntArray,
    x: FloatArray,
    discs: FloatArray,
    ends: FloatArray,
    mu: float,
    eps: float,
    max_steps: int,
    tol: float,
) -> int:
    n = seq.size
    g = np.zeros((n, 2))
    dg = np.zeros((n, 3))  # diagonal blocks: xx, xy, yy
    off = np.zeros((n, 3))  # block between k and k + 1
    cp = np.zeros((n, 4))  # eliminated off blocks (2 x 2, row-major)
    rp = np.zeros((n, 2))
    step = np.zeros((n, 2))
    trial = np.zeros((n, 2))
    f = _barrier_value(seq, x, discs, ends, mu, eps)
    steps = 0
    for _ in range(max_steps):
        steps += 1
        g[:] = 0.0
        dg[:] = 0.0
        off[:] = 0.0
        for leg in range(n + 1):
            ax, ay = _pt(x, ends, leg - 1)
            bx, by = _pt(x, ends, leg)
            dx, dy = bx - ax, by - ay
            s = math.sqrt(dx * dx + dy * dy + eps * eps)
            hxx = (1.0 - dx * dx / (s * s)) / s
            hxy = -dx * dy / (s * s * s)
            hyy = (1.0 - dy * dy / (s * s)) / s
            a, b = leg - 1, leg
            if a >= 0:
                g[a, 0] -= dx / s
                g[a, 1] -= dy / s
                dg[a, 0] += hxx
                dg[a, 1] += hxy
                dg[a, 2] += hyy
            if b < n:
                g[b, 0] += dx / s
                g[b, 1] += dy / s
                dg[b, 0] += hxx
                dg[b, 1] += hxy
                dg[b, 2] += hyy
            if a >= 0 and b < n:
                off[a, 0] = -hxx
                off[a, 1] = -hxy
                off[a, 2] = -hyy
        for k in range(n):
            i = seq[k]
            ex, ey = x[k, 0] - discs[i, 0], x[k, 1] - discs[i, 1]
            u = discs[i, 2] ** 2 - ex * ex - ey * ey
            if not u > 0.0:
                return steps
            g[k, 0] += mu * 2.0 * ex / u
            g[k, 1] += mu * 2.0 * ey / u
            dg[k, 0] += mu * (2.0 / u + 4.0 * ex * ex / (u * u))
            dg[k, 1] += mu * (4.0 * ex * ey / (u * u))
            dg[k, 2] += mu * (2.0 / u + 4.0 * ey * ey / (u * u))
        # Block Thomas elimination of H step = -g.
        for k in range(n):
            m00, m01, m11 = dg[k, 0], dg[k, 1], dg[k, 2]
            r0, r1 = -g[k, 0], -g[k, 1]
            if k > 0:
                b00, b01, b11 = off[k - 1, 0], off[k - 1, 1], off[k - 1, 2]
                c00, c01, c10, c11 = cp[k - 1, 0], cp[k - 1, 1], cp[k - 1, 2], cp[k - 1, 3]
                # M -= B^T C' (B symmetric)
                m00 -= b00 * c00 + b01 * c10
                m01 -= b00 * c01 + b01 * c11
                m11 -= b01 * c01 + b11 * c11
                r0 -= b00 * rp[k - 1, 0] + b01 * rp[k - 1, 1]
                r1 -= b01 * rp[k - 1, 0] + b11 * rp[k - 1, 1]
            # A stop on the straight line between its neighbours, deep inside its disc, has
            # a nearly singular block; a tiny ridge keeps the step a descent direction.
            ridge = 1e-10 * (m00 + m11)
            m00 += ridge
            m11 += ridge
            det = m00 * m11 - m01 * m01
            if not det > 0.0:
                # Not positive definite to rounding (stops that coincide, legs that are
                # straight): no Newton step here; the stage ends where it is.
                return steps
            i00, i01, i11 = m11 / det, -m01 / det, m00 / det
            rp[k, 0] = i00 * r0 + i01 * r1
            rp[k, 1] = i01 * r0 + i11 * r1
            if k < n - 1:
                b00, b01, b11 = off[k, 0], off[k, 1], off[k, 2]
                cp[k, 0] = i00 * b00 + i01 * b01
                cp[k, 1] = i00 * b01 + i01 * b11
                cp[k, 2] = i01 * b00 + i11 * b01
                cp[k, 3] = i01 * b01 + i11 * b11
        for k in range(n - 1, -1, -1):
            sx, sy = rp[k, 0], rp[k, 1]
            if k < n - 1:
                sx -= cp[k, 0] * step[k + 1, 0] + cp[k, 1] * step[k + 1, 1]
                sy -= cp[k, 2] * step[k + 1, 0] + cp[k, 3] * step[k + 1, 1]
            step[k, 0] = sx
            step[k, 1] = sy
        dec = 0.0
        for k in range(n):
            dec -= g[k, 0] * step[k, 0] + g[k, 1] * step[k, 1]
        if not dec > tol:
            break
        t = 1.0
        moved = False
        for _ls in range(60):
            for k in range(n):
                trial[k, 0] = x[k, 0] + t * step[k, 0]
                trial[k, 1] = x[k, 1] + t * step[k, 1]
            ft = _barrier_value(seq, trial, discs, ends, mu, eps)
            if ft <= f - 0.25 * t * dec:
                x[:] = trial
                f = ft
                moved = True
                break
            t *= 0.5
        if not moved:
            break
    return steps


@nb.njit(cache=True, nogil=True)
def _exact_kernel(
    seq: IntArray, pts: FloatArray, discs: FloatArray, ends: FloatArray, steps: int
) -> FloatArray:
    n = seq.size
    length = path_length(pts, ends)
    scale = max(length, 1e-9)
    x: FloatArray = pts.copy()
    # Well inside each disc: from next to the rim the barrier's first steps are tiny.
    for k in range(n):
        i = seq[k]
        x[k, 0] = discs[i, 0] + (x[k, 0] - discs[i, 0]) * 0.9
        x[k, 1] = discs[i, 1] + (x[k, 1] - discs[i, 1]) * 0.9
    mu = 1e-3 * scale / (n + 1)
    eps = 1e-3 * scale / (n + 1)
    while mu > 1e-10 * scale / (n + 1):
        _newton_stage(seq, x, discs, ends, mu, eps, steps, 1e-13 * scale)
        mu *= 0.2
        eps *= 0.2
    # Pull every point a hair inside, as the sweeps keep them.
    for k in range(n):
        i = seq[k]
        ex, ey = x[k, 0] - discs[i, 0], x[k, 1] - discs[i, 1]
        d = math.hypot(ex, ey)
        r = discs[i, 2] * (1.0 - _INSIDE)
        if d > r:
            x[k, 0] = discs[i, 0] + ex * r / d
            x[k, 1] = discs[i, 1] + ey * r / d
    _settle(seq, x, discs, ends, 0, n - 1, 2)
    return x


def exact_positions(
    seq: IntArray, pts: FloatArray, discs: FloatArray, depot_xy: FloatArray
) -> FloatArray:
    """The shortest tour through the discs in the order ``seq`` (to about 1e-9 of its length).

    Parameters
    ----------
    seq
        The disc of each stop, in tour order.
    pts
        A point in each stop's disc (the start; returned when nothing shorter is found).
    discs
        ``(x, y, r)`` rows.
    depot_xy
        The fixed point the tour starts and ends at.

    Returns
    -------
    numpy.ndarray
        One point per stop, each inside its disc; the tour is never longer than ``pts``'.
    """
    seq = np.ascontiguousarray(seq, dtype=np.int64)
    pts = np.array(pts, dtype=np.float64).reshape(-1, 2)
    discs = np.ascontiguousarray(discs, dtype=np.float64)
    depot = np.asarray(depot_xy, dtype=np.float64).reshape(2)
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    _exact_window(seq, pts, discs, ends, 0, seq.size - 1, 400)
    return pts


@nb.njit(cache=True, nogil=True)
def _exact_window(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    ends: FloatArray,
    lo: int,
    hi: int,
    steps: int = _SEARCH_STEPS,
) -> None:
    """Exact positions for the stops ``lo..hi`` (the others fixed), in place, if shorter.

    A disc of radius 0 pins its stop (the barrier needs an inside): the runs between pinned
    stops are solved each on its own."""
    n = seq.size
    lo = max(lo, 0)
    hi = min(hi, n - 1)
    if hi < lo:
        return
    start = lo
    for k in range(lo, hi + 2):
        if k > hi or discs[seq[k], 2] <= 0.0:
            if k > start:
                _exact_run(seq, pts, discs, ends, start, k - 1, steps)
            start = k + 1


@nb.njit(cache=True, nogil=True)
def _exact_run(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    ends: FloatArray,
    lo: int,
    hi: int,
    steps: int,
) -> None:
    sub_ends = np.empty((2, 2))
    sub_ends[0, 0], sub_ends[0, 1] = _pt(pts, ends, lo - 1)
    sub_ends[1, 0], sub_ends[1, 1] = _pt(pts, ends, hi + 1)
    sub_seq = seq[lo : hi + 1]
    sub = pts[lo : hi + 1].copy()
    x = _exact_kernel(sub_seq, sub, discs, sub_ends, steps)
    if path_length(x, sub_ends) < path_length(sub, sub_ends):
        pts[lo : hi + 1] = x
