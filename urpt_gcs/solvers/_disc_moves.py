"""Local search moves of a disc tour (compiled kernels): relocate a disc next to a
neighbour (its point re-optimised there), Or-opt and 2-opt, each followed by re-settling the
stops around the change, and the descent to a local optimum that runs them.

The tour's conventions are :mod:`urpt_gcs.solvers.disc_tour`'s; ``pos[d]`` is the position of
disc ``d`` in the tour (``-1`` when it is out of it).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.solvers._disc_positions import (
    _INSIDE,
    _dist,
    _exact_window,
    _pt,
    _settle,
    path_length,
)
from urpt_gcs.solvers.refine import best_on_disc

__all__ = [
    "_MIN_GAIN",
    "_descend",
    "_descent",
    "_insert_cost",
    "_insert_floor",
    "_nearest_on_segment",
    "_search",
    "_to_segment",
    "_wake",
]

# Moves must gain at least this fraction of the tour.
_MIN_GAIN = 1e-9


@nb.njit(cache=True, nogil=True)
def _nearest_on_segment(
    cx: float, cy: float, ax: float, ay: float, bx: float, by: float
) -> tuple[float, float]:
    dx, dy = bx - ax, by - ay
    ll = dx * dx + dy * dy
    t = 0.0 if ll == 0.0 else min(max(((cx - ax) * dx + (cy - ay) * dy) / ll, 0.0), 1.0)
    return ax + t * dx, ay + t * dy


@nb.njit(cache=True, nogil=True)
def _to_segment(cx: float, cy: float, ax: float, ay: float, bx: float, by: float) -> float:
    qx, qy = _nearest_on_segment(cx, cy, ax, ay, bx, by)
    return _dist(cx, cy, qx, qy)


@nb.njit(cache=True, nogil=True)
def _insert_cost(
    pts: FloatArray, ends: FloatArray, discs: FloatArray, d: int, j: int
) -> tuple[float, float, float]:
    """Cost of putting disc ``d`` between positions ``j`` and ``j + 1``, and its point."""
    ax, ay = _pt(pts, ends, j)
    bx, by = _pt(pts, ends, j + 1)
    r = discs[d, 2] * (1.0 - _INSIDE)
    px, py = best_on_disc(ax, ay, bx, by, discs[d, 0], discs[d, 1], r)
    return _dist(ax, ay, px, py) + _dist(px, py, bx, by) - _dist(ax, ay, bx, by), px, py


@nb.njit(cache=True, nogil=True)
def _insert_floor(pts: FloatArray, ends: FloatArray, discs: FloatArray, d: int, j: int) -> float:
    """A lower bound on :func:`_insert_cost`, cheaply: every point ``h`` from the leg
    ``j -> j + 1`` costs at least ``sqrt(leg^2 + 4 h^2) - leg`` (the ellipse through it with
    the leg's ends as foci is that wide)."""
    ax, ay = _pt(pts, ends, j)
    bx, by = _pt(pts, ends, j + 1)
    h = _to_segment(discs[d, 0], discs[d, 1], ax, ay, bx, by) - discs[d, 2]
    if h <= 0.0:
        return 0.0
    leg = _dist(ax, ay, bx, by)
    return math.sqrt(leg * leg + 4.0 * h * h) - leg


@nb.njit(cache=True, nogil=True)
def _move_stop(seq: IntArray, pts: FloatArray, pos: IntArray, i: int, j: int) -> int:
    """Move the stop at ``i`` to just after position ``j`` (positions before the move); its
    new position."""
    d = seq[i]
    px, py = pts[i, 0], pts[i, 1]
    if j > i:
        for k in range(i, j):
            seq[k] = seq[k + 1]
            pts[k, 0] = pts[k + 1, 0]
            pts[k, 1] = pts[k + 1, 1]
            pos[seq[k]] = k
        new = j
    else:
        for k in range(i, j + 1, -1):
            seq[k] = seq[k - 1]
            pts[k, 0] = pts[k - 1, 0]
            pts[k, 1] = pts[k - 1, 1]
            pos[seq[k]] = k
        new = j + 1
    seq[new] = d
    pts[new, 0] = px
    pts[new, 1] = py
    pos[d] = new
    return new


@nb.njit(cache=True, nogil=True)
def _reverse(seq: IntArray, pts: FloatArray, pos: IntArray, i: int, j: int) -> None:
    while i < j:
        seq[i], seq[j] = seq[j], seq[i]
        t0, t1 = pts[i, 0], pts[i, 1]
        pts[i, 0], pts[i, 1] = pts[j, 0], pts[j, 1]
        pts[j, 0], pts[j, 1] = t0, t1
        pos[seq[i]] = i
        pos[seq[j]] = j
        i += 1
        j -= 1


@nb.njit(cache=True, nogil=True)
def _or_opt(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    d: int,
    tol: float,
) -> tuple[int, int]:
    """Move the two or three stops from disc ``d``'s on, either way round, next to a
    neighbour of ``d``, if that gains (points fixed); the positions changed (``n, -1`` when
    it moved nothing)."""
    n = seq.size
    i = pos[d]
    best, best_j, best_len, best_rev = -tol, -2, 0, False
    for seg in range(2, 4):
        e = i + seg - 1
        if e >= n:
            break
        ax, ay = _pt(pts, ends, i - 1)
        bx, by = _pt(pts, ends, e + 1)
        gain = (
            _dist(ax, ay, pts[i, 0], pts[i, 1])
            + _dist(pts[e, 0], pts[e, 1], bx, by)
            - _dist(ax, ay, bx, by)
        )
        if gain <= tol:
            continue
        for m in neigh[d]:
            if pos[m] < 0:
                continue
            for j in (pos[m] - 1, pos[m]):
                if i - 1 <= j <= e:
                    continue
                ux, uy = _pt(pts, ends, j)
                vx, vy = _pt(pts, ends, j + 1)
                base = _dist(ux, uy, vx, vy)
                fwd = (
                    _dist(ux, uy, pts[i, 0], pts[i, 1])
                    + _dist(pts[e, 0], pts[e, 1], vx, vy)
                    - base
                    - gain
                )
                rev = (
                    _dist(ux, uy, pts[e, 0], pts[e, 1])
                    + _dist(pts[i, 0], pts[i, 1], vx, vy)
                    - base
                    - gain
                )
                if fwd < best:
                    best, best_j, best_len, best_rev = fwd, j, seg, False
                if rev < best:
                    best, best_j, best_len, best_rev = rev, j, seg, True
    if best_j == -2:
        return n, -1
    e = i + best_len - 1
    j = best_j
    # A rotation by three reversals puts the segment after j, in its own orientation.
    if j > e:
        _reverse(seq, pts, pos, i, e)
        _reverse(seq, pts, pos, e + 1, j)
        _reverse(seq, pts, pos, i, j)
        lo, hi = j - best_len + 1, j
        gap = i
    else:
        _reverse(seq, pts, pos, j + 1, i - 1)
        _reverse(seq, pts, pos, i, e)
        _reverse(seq, pts, pos, j + 1, e)
        lo, hi = j + 1, j + best_len
        gap = e + 1
    if best_rev:
        _reverse(seq, pts, pos, lo, hi)
    _settle(seq, pts, discs, ends, lo - 2, hi + 2)
    _settle(seq, pts, discs, ends, gap - 3, gap + 2)
    return min(lo, gap) - 3, max(hi, gap) + 3


@nb.njit(cache=True, nogil=True)
def _wake(
    seq: IntArray, active: BoolArray, queue: IntArray, head: int, size: int, lo: int, hi: int
) -> int:
    """Queue the discs at positions ``lo..hi`` not queued yet; the new queue size."""
    n = seq.size
    for k in range(max(lo, 0), min(hi, n - 1) + 1):
        d = seq[k]
        if not active[d]:
            active[d] = True
            queue[(head + size) % queue.size] = d
            size += 1
    return size


@nb.njit(cache=True, nogil=True)
def _descend(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    lo: int,
    hi: int,
) -> tuple[int, int]:
    """Relocate, Or-opt and 2-opt moves until none gains, starting from the discs at
    positions ``lo..hi`` and then those around each change; the first and last positions
    changed (``n, -1`` when none)."""
    tol = _MIN_GAIN * path_length(pts, ends)
    # Indexed by disc: the tour may hold only some of them (the others stripped).
    active = np.zeros(pos.size, dtype=np.bool_)
    queue = np.empty(pos.size, dtype=np.int64)
    size = _wake(seq, active, queue, 0, 0, lo, hi)
    return _search(seq, pts, pos, discs, ends, neigh, active, queue, size, tol)


@nb.njit(cache=True, nogil=True)
def _search(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    active: BoolArray,
    queue: IntArray,
    size: int,
    tol: float,
) -> tuple[int, int]:
    """The moves of :func:`_descend` from the discs ``queue[:size]`` (marked ``active``),
    each gaining more than ``tol``; ``active`` is left all False."""
    n = seq.size
    first, last = n, -1
    head = 0
    budget = 200 * n
    while size > 0 and budget > 0:
        budget -= 1
        d = queue[head]
        head = (head + 1) % queue.size
        size -= 1
        active[d] = False
        # Relocate disc d next to one of its neighbours.
        i = pos[d]
        ax, ay = _pt(pts, ends, i - 1)
        bx, by = _pt(pts, ends, i + 1)
        gain = (
            _dist(ax, ay, pts[i, 0], pts[i, 1])
            + _dist(pts[i, 0], pts[i, 1], bx, by)
            - _dist(ax, ay, bx, by)
        )
        best, best_j, best_x, best_y = -tol, -2, 0.0, 0.0
        if gain > tol:
            for m in neigh[d]:
                if pos[m] < 0:
                    continue
                for j in (pos[m] - 1, pos[m]):
                    # The slots either side of the stop itself are where it is now.
                    if j == i or j == i - 1:
                        continue
                    if _insert_floor(pts, ends, discs, d, j) - gain >= best:
                        continue
                    cost, px, py = _insert_cost(pts, ends, discs, d, j)
                    delta = cost - gain
                    if delta < best:
                        best, best_j, best_x, best_y = delta, j, px, py
        if best_j > -2:
            pts[i, 0] = best_x
            pts[i, 1] = best_y
            new = _move_stop(seq, pts, pos, i, best_j)
            old_near = i if i < new else i + 1
            _settle(seq, pts, discs, ends, old_near - 2, old_near + 1)
            _settle(seq, pts, discs, ends, new - 2, new + 2)
            first = min(first, i - 2, new - 2)
            last = max(last, i + 2, new + 2)
            size = _wake(seq, active, queue, head, size, old_near - 2, old_near + 1)
            size = _wake(seq, active, queue, head, size, new - 2, new + 2)
            continue
        a, b = _or_opt(seq, pts, pos, discs, ends, neigh, d, tol)
        if b >= a:
            first = min(first, a)
            last = max(last, b)
            size = _wake(seq, active, queue, head, size, a, a + 6)
            size = _wake(seq, active, queue, head, size, b - 6, b)
            size = _wake(seq, active, queue, head, size, pos[d] - 2, pos[d] + 4)
            continue
        # 2-opt: the leg out of d's stop against the legs near its neighbours.
        done = False
        for m in neigh[d]:
            if done:
                break
            if pos[m] < 0:
                continue
            i = pos[d]
            j = pos[m]
            for side in range(2):
                if side == 0:
                    a, b = i, j  # legs (a, a+1) and (b, b+1) become (a, b), (a+1, b+1)
                else:
                    a, b = i - 1, j - 1  # legs into d and into m
                lo2, hi2 = min(a, b), max(a, b)
                if hi2 - lo2 < 2 or lo2 < -1 or hi2 > n - 1:
                    continue
                p0x, p0y = _pt(pts, ends, lo2)
                p1x, p1y = _pt(pts, ends, lo2 + 1)
                q0x, q0y = _pt(pts, ends, hi2)
                q1x, q1y = _pt(pts, ends, hi2 + 1)
                delta = (
                    _dist(p0x, p0y, q0x, q0y)
                    + _dist(p1x, p1y, q1x, q1y)
                    - _dist(p0x, p0y, p1x, p1y)
                    - _dist(q0x, q0y, q1x, q1y)
                )
                if delta < -tol:
                    _reverse(seq, pts, pos, lo2 + 1, hi2)
                    _settle(seq, pts, discs, ends, lo2 - 1, lo2 + 2)
                    _settle(seq, pts, discs, ends, hi2 - 1, hi2 + 2)
                    first = min(first, lo2 - 1)
                    last = max(last, hi2 + 2)
                    size = _wake(seq, active, queue, head, size, lo2 - 1, lo2 + 2)
                    size = _wake(seq, active, queue, head, size, hi2 - 1, hi2 + 2)
                    done = True
                    break
    while size > 0:  # out of budget: the rest unmarked
        active[queue[head]] = False
        head = (head + 1) % queue.size
        size -= 1
    return first, last


@nb.njit(cache=True, nogil=True)
def _descent(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    lo: int,
    hi: int,
) -> None:
    """Local search to a local optimum from the stops ``lo..hi`` on, the positions exact
    around them and around every change."""
    a, b = lo - 5, hi + 5
    _exact_window(seq, pts, discs, ends, a, b)
    for _ in range(20):
        before = path_length(pts, ends)
        first, last = _descend(seq, pts, pos, discs, ends, neigh, a, b)
        if last < first:
            break
        a, b = first - 5, last + 5
        _exact_window(seq, pts, discs, ends, a, b)
        if path_length(pts, ends) >= before * (1.0 - 1e-12):
            break
