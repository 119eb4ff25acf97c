"""Tours through discs on the plane (the close-enough TSP): exact stop positions and order search.

A tour here is an order of *every* disc and one point in each: it starts at a fixed point
(the depot), visits ``pts[0], ..., pts[n-1]`` in turn and returns. A disc whose point lies on
the leg between its neighbours costs nothing: it is touched by that leg, so such "redundant
stops" need no special case.

- :func:`exact_positions`: with the order fixed the shortest such tour is a convex problem;
  it is solved by Newton's method on a smoothed barrier (legs ``sqrt(|d|^2 + eps^2)``, discs
  ``-mu log(r^2 - |p - c|^2)``), whose Hessian is block tridiagonal, so a step is linear in
  ``n``. Per-stop moves alone stall where consecutive stops coincide (overlapping discs
  entered at one point); a joint step does not.
- :func:`improve`: iterated local search over the continuous tour: relocate a disc next to a
  neighbour (its point re-optimised there), Or-opt and 2-opt, each followed by re-settling
  the stops around the change. Kicks (a local double bridge, or a disc and its nearest taken
  out and put back greedily) run in one compiled loop, each followed by a descent from the
  stops it changed; now and then the same search runs on the stops alone (the discs their
  legs cross anyway taken out and put back after). On few discs a search that has stalled
  moves the depot to a far leg and searches from there a while (:func:`_escape`). The exact
  positions for the best tour.
- :func:`insertion_tour`: a start for the search, the discs inserted in random order.
- :func:`region_ruin`, :func:`depot_moved`: a whole tour perturbed (one area's discs put back
  afresh; the depot joined to a far leg), for the search to start from again.
"""

from __future__ import annotations

import math
import time

import numba as nb
import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.solvers.refine import best_on_disc

# Nearest discs considered for a move. (With 10, some tours of 100-200 discs were local
# optima that no kick left: suri_CETSP-100-4 stuck 0.18 % above its optimum.)
NEIGHBOURS = 15
# Fewer discs than this are not searched (the descent alone settles them).
MIN_SEARCHED = 4
# Positions a random double bridge spans.
WINDOW = 30
# Nearest discs a ruin kick may take out with its disc (more than a move looks at).
RUIN_NEIGHBOURS = 30
# Share of the kicks that take a disc and its neighbours out and put them back greedily
# (the others are double bridges).
_RUIN_SHARE = 0.5
# Share of the batches of kicks after which the search also runs on the stops alone, the
# discs their legs cross anyway taken out and put back after.
_STRIP_SHARE = 0.3
# Up to this many discs, a search that has not shortened the tour by _STALL_GAIN (relative)
# in _STALL_S seconds moves the depot to one of the _DEPOT_CHOICES cheapest legs at least
# _DEPOT_AWAY stops from where it is, and searches from there for _ESCAPE_S seconds; the
# shortest tour met is kept either way. (No move or kick takes the depot out and puts it
# on a far leg; 2-opt changes one of its legs only. bubbles4's tour stuck 0.15 % above its
# best known leaves the depot on the other side of the ring from the best known's.) Above
# it the drift acceptance lets the search move instead.
_ESCAPE_MAX_DISCS = 200
_STALL_S = 3.0
_STALL_GAIN = 1e-9
_ESCAPE_S = 1.0
_DEPOT_CHOICES = 6
_DEPOT_AWAY = 10
# Seconds a batch of kicks should take (the time limit is checked between batches).
_BATCH_S = 0.05
# Stops kept this far (relative to the radius) inside their disc.
_INSIDE = 1e-9
# Newton steps per barrier stage within the search (the exact positions of a whole tour
# allow more: from a cold start the first stages need them).
_SEARCH_STEPS = 100
# Moves must gain at least this fraction of the tour.
_MIN_GAIN = 1e-9


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
def _kick(seq: IntArray, pts: FloatArray, pos: IntArray, a: int, b: int, c: int) -> None:
    """A double bridge: the stops ``a..b-1`` and ``b..c-1`` swap places."""
    old_seq = seq[a:c].copy()
    old_pts = pts[a:c].copy()
    k = a
    for src in range(b, c):
        seq[k] = old_seq[src - a]
        pts[k, 0] = old_pts[src - a, 0]
        pts[k, 1] = old_pts[src - a, 1]
        k += 1
    for src in range(a, b):
        seq[k] = old_seq[src - a]
        pts[k, 0] = old_pts[src - a, 0]
        pts[k, 1] = old_pts[src - a, 1]
        k += 1
    for k in range(a, c):
        pos[seq[k]] = k


@nb.njit(cache=True, nogil=True)
def _move_depot(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    ends: FloatArray,
    rng: np.random.Generator,
    away: int,
) -> int:
    """Move the depot of the closed tour (``ends`` both the depot) to another leg: one of
    the ``_DEPOT_CHOICES`` legs at least ``away`` stops from it where that costs least, at
    random. The stops from that leg's end come first; the position of the stop that was
    first (``-1`` when no leg is that far)."""
    n = seq.size
    if n < 2 * away + 1:
        return -1
    dx, dy = ends[0, 0], ends[0, 1]
    # The last stop joined to the first, and the depot put between stops k-1 and k.
    close = (
        _dist(pts[n - 1, 0], pts[n - 1, 1], pts[0, 0], pts[0, 1])
        - _dist(dx, dy, pts[0, 0], pts[0, 1])
        - _dist(pts[n - 1, 0], pts[n - 1, 1], dx, dy)
    )
    legs = np.arange(away, n - away + 1)
    cost = np.empty(legs.size)
    for q in range(legs.size):
        k = legs[q]
        ax, ay, bx, by = pts[k - 1, 0], pts[k - 1, 1], pts[k, 0], pts[k, 1]
        cost[q] = close + _dist(ax, ay, dx, dy) + _dist(dx, dy, bx, by) - _dist(ax, ay, bx, by)
    choices = min(_DEPOT_CHOICES, legs.size)
    k = int(legs[np.argsort(cost)[rng.integers(0, choices)]])
    old_seq = seq.copy()
    old_pts = pts.copy()
    for j in range(n):
        src = (j + k) % n
        seq[j] = old_seq[src]
        pts[j, 0] = old_pts[src, 0]
        pts[j, 1] = old_pts[src, 1]
        pos[seq[j]] = j
    return n - k


@nb.njit(cache=True, nogil=True)
def _put_at(seq: IntArray, pts: FloatArray, m: int, at: int, d: int, x: float, y: float) -> None:
    """Disc ``d`` at position ``at`` of the tour of the first ``m`` stops, point ``(x, y)``;
    the stops from ``at`` on shift one along."""
    for k in range(m, at, -1):
        seq[k] = seq[k - 1]
        pts[k, 0] = pts[k - 1, 0]
        pts[k, 1] = pts[k - 1, 1]
    seq[at] = d
    pts[at, 0] = x
    pts[at, 1] = y


@nb.njit(cache=True, nogil=True)
def _insert_cheapest(
    seq: IntArray, pts: FloatArray, discs: FloatArray, ends: FloatArray, m: int, d: int
) -> int:
    """Insert disc ``d`` into the tour of the first ``m`` stops at its cheapest place (free
    where a leg already crosses it), shifting the stops after it; its index."""
    cur = pts[:m]
    cx, cy, r = discs[d, 0], discs[d, 1], discs[d, 2] * (1.0 - _INSIDE)
    best, best_j, best_x, best_y = math.inf, -1, 0.0, 0.0
    for j in range(-1, m):
        ax, ay = _pt(cur, ends, j)
        bx, by = _pt(cur, ends, j + 1)
        leg = _dist(ax, ay, bx, by)
        near = _to_segment(cx, cy, ax, ay, bx, by)
        if near <= r:  # the leg crosses the disc: free
            best, best_j, best_x, best_y = 0.0, j, *_nearest_on_segment(cx, cy, ax, ay, bx, by)
            break
        # Every point within h of the leg costs at least sqrt(leg^2 + 4 h^2) - leg (the
        # ellipse through it with the leg's ends as foci is that wide).
        h = near - r
        if math.sqrt(leg * leg + 4.0 * h * h) - leg >= best:
            continue
        cost, px, py = _insert_cost(cur, ends, discs, d, j)
        if cost < best:
            best, best_j, best_x, best_y = cost, j, px, py
    _put_at(seq, pts, m, best_j + 1, d, best_x, best_y)
    return best_j + 1


@nb.njit(cache=True, nogil=True)
def _insert_near(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    m: int,
    d: int,
) -> None:
    """Insert disc ``d`` into the tour of the first ``m`` stops at the cheapest place next to
    one of its neighbours in the tour (free where that leg crosses it; anywhere when none of
    them is in the tour), shifting the stops after it."""
    best, best_j, best_x, best_y = math.inf, -2, 0.0, 0.0
    for q in range(neigh.shape[1]):
        at = pos[neigh[d, q]]
        if at < 0:
            continue
        for j in (at - 1, at):
            if _insert_floor(pts[:m], ends, discs, d, j) >= best:
                continue
            cost, px, py = _insert_cost(pts[:m], ends, discs, d, j)
            if cost < best:
                best, best_j, best_x, best_y = cost, j, px, py
    if best_j == -2:
        _insert_cheapest(seq, pts, discs, ends, m, d)
    else:
        _put_at(seq, pts, m, best_j + 1, d, best_x, best_y)
    for k in range(m + 1):
        pos[seq[k]] = k


@nb.njit(cache=True, nogil=True)
def _ruin(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    removed: IntArray,
) -> None:
    """Take the discs ``removed`` out of the tour and put each back (in the order given) at
    the cheapest place next to its neighbours, its point the best there."""
    n = seq.size
    for d in removed:
        pos[d] = -1
    m = 0
    for k in range(n):
        if pos[seq[k]] >= 0:
            seq[m] = seq[k]
            pts[m, 0] = pts[k, 0]
            pts[m, 1] = pts[k, 1]
            pos[seq[m]] = m
            m += 1
    for d in removed:
        _insert_near(seq, pts, pos, discs, ends, neigh, m, d)
        m += 1


@nb.njit(cache=True, nogil=True)
def _strip(
    seq: IntArray, pts: FloatArray, pos: IntArray, ends: FloatArray, tol: float
) -> tuple[int, IntArray]:
    """Take out every stop that lies on the leg between its neighbours (its disc is touched
    by that leg anyway); the stops left come first. The count left, and the discs taken."""
    n = seq.size
    taken = np.empty(n, dtype=np.int64)
    t = 0
    m = 0
    for k in range(n):
        ax, ay = _pt(pts[:m], ends, m - 1)
        bx, by = _pt(pts, ends, k + 1)
        gain = (
            _dist(ax, ay, pts[k, 0], pts[k, 1])
            + _dist(pts[k, 0], pts[k, 1], bx, by)
            - _dist(ax, ay, bx, by)
        )
        if gain <= tol:
            taken[t] = seq[k]
            pos[seq[k]] = -1
            t += 1
        else:
            seq[m] = seq[k]
            pts[m, 0] = pts[k, 0]
            pts[m, 1] = pts[k, 1]
            pos[seq[m]] = m
            m += 1
    return m, taken[:t].copy()


@nb.njit(cache=True, nogil=True)
def _put_back(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    m: int,
    taken: IntArray,
) -> None:
    """Put the discs ``taken`` back into the tour of the first ``m`` stops, each at its
    cheapest place (free where a leg already crosses it)."""
    for d in taken:
        _insert_cheapest(seq, pts, discs, ends, m, d)
        m += 1
    for k in range(m):
        pos[seq[k]] = k


def insertion_tour(
    discs: FloatArray, which: IntArray, depot_xy: FloatArray, rng: np.random.Generator
) -> tuple[IntArray, FloatArray]:
    """A tour from the depot through the discs ``which`` (rows of ``discs``), built by
    inserting them one at a time in random order, each at its cheapest place with its point
    the best there (free where a leg already crosses it). The order and a point in each.

    A start for the order search: different insertion orders give tours of different global
    shape, which the search's moves and kicks, all local, do not change."""
    discs = np.ascontiguousarray(np.asarray(discs, dtype=np.float64))
    depot = np.asarray(depot_xy, dtype=np.float64).reshape(2)
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    which = np.asarray(which, dtype=np.int64)
    seq = np.empty(which.size, dtype=np.int64)
    pts = np.empty((which.size, 2))
    for m, d in enumerate(rng.permutation(which)):
        _insert_cheapest(seq, pts, discs, ends, m, int(d))
    return seq, pts


def region_ruin(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    depot_xy: FloatArray,
    share: float,
    rng: np.random.Generator,
) -> tuple[IntArray, FloatArray]:
    """The tour with the discs of one random area taken out and put back: the ``share`` of
    its discs nearest a disc drawn at random (by centre, at least 3), inserted again in random
    order, each at its cheapest place (free where a leg already crosses it).

    A perturbation for the order search bigger than its own kicks: the discs of a whole area
    are routed afresh while the rest of the tour keeps its shape."""
    discs = np.ascontiguousarray(np.asarray(discs, dtype=np.float64))
    depot = np.asarray(depot_xy, dtype=np.float64).reshape(2)
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    seq = np.asarray(seq, dtype=np.int64)
    n = seq.size
    count = min(n, max(3, int(share * n)))
    centre = discs[seq[rng.integers(n)], :2]
    away = np.hypot(*(discs[seq, :2] - centre).T)
    out = np.argpartition(away, count - 1)[:count]
    keep = np.ones(n, dtype=bool)
    keep[out] = False
    m = int(keep.sum())
    new_seq = np.empty(n, dtype=np.int64)
    new_pts = np.empty((n, 2))
    new_seq[:m] = seq[keep]
    new_pts[:m] = np.asarray(pts, dtype=np.float64)[keep]
    for d in rng.permutation(seq[out]):
        _insert_cheapest(new_seq, new_pts, discs, ends, m, int(d))
        m += 1
    return new_seq, new_pts


def depot_moved(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    depot_xy: FloatArray,
    rng: np.random.Generator,
) -> tuple[IntArray, FloatArray]:
    """The tour with the depot moved to another leg far along it (:func:`_move_depot`),
    the stops either side of both joins re-settled; the tour unchanged where it is too
    short for a far leg.

    A perturbation the order search's own moves do not make: on a ring of discs the side
    the depot joins decides which detours the tour can save (bubbles4)."""
    discs = np.ascontiguousarray(np.asarray(discs, dtype=np.float64))
    depot = np.asarray(depot_xy, dtype=np.float64).reshape(2)
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    seq = np.array(seq, dtype=np.int64)
    pts = np.array(pts, dtype=np.float64).reshape(-1, 2)
    n = seq.size
    pos = np.empty(discs.shape[0], dtype=np.int64)
    pos[seq] = np.arange(n)
    at = _move_depot(seq, pts, pos, ends, rng, min(_DEPOT_AWAY, n // 4))
    if at >= 0:
        for lo, hi in ((-1, 2), (n - 3, n), (at - 2, at + 1)):
            _settle(seq, pts, discs, ends, lo, hi)
    return seq, pts


def neighbours(discs: FloatArray, k: int = NEIGHBOURS) -> IntArray:
    """Each disc's ``k`` nearest discs by the gap between them (rims, not centres)."""
    n = len(discs)
    k = min(k, n - 1)
    if k <= 0:
        return np.zeros((n, 0), dtype=np.int64)
    tree = cKDTree(discs[:, :2])
    q = min(n, 3 * k + 1)
    dist, idx = tree.query(discs[:, :2], k=q)
    gap = dist - discs[idx, 2] - discs[:, 2:3]
    gap[idx == np.arange(n)[:, None]] = np.inf
    order = np.argsort(gap, axis=1)[:, :k]
    out: IntArray = np.take_along_axis(idx, order, axis=1).astype(np.int64)
    return np.ascontiguousarray(out)


def _among(discs: FloatArray, kept: IntArray, k: int = NEIGHBOURS) -> IntArray:
    """Neighbour rows for the discs ``kept`` among themselves (rows of other discs unused).

    With the stops whose disc a leg crosses anyway taken out, a disc's nearest discs are
    mostly out of the tour too, and moves next to them are never tried."""
    local = neighbours(discs[kept], k)
    out = np.zeros((len(discs), local.shape[1]), dtype=np.int64)
    out[kept] = kept[local]
    return out


@nb.njit(cache=True, nogil=True)
def _kicks(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    wide: IntArray,
    cur_seq: IntArray,
    cur_pts: FloatArray,
    rec_seq: IntArray,
    rec_pts: FloatArray,
    count: int,
    rng: np.random.Generator,
    drift: float = 0.0,
) -> float:
    """``count`` kicks, each followed by a descent from the stops it changed and kept or
    undone (:func:`_keep_or_undo`). Moves look at the rows of ``neigh``; a ruin kick takes a
    disc out with up to all of its row of ``wide``. ``seq, pts`` start and end as the kept tour
    ``cur_seq, cur_pts``; the shortest met is ``rec_seq, rec_pts``, and its length returned."""
    n = seq.size
    rec_len = path_length(rec_pts, ends)
    tol = _MIN_GAIN * rec_len
    active = np.zeros(pos.size, dtype=np.bool_)
    queue = np.empty(pos.size, dtype=np.int64)
    window = min(n, WINDOW)
    k_max = wide.shape[1]
    for _ in range(count):
        size = 0
        if rng.random() < _RUIN_SHARE:
            # A disc and some of its nearest (rows of ``wide``) taken out and put back
            # greedily.
            centre = seq[rng.integers(0, n)]
            k = rng.integers(2, k_max + 1)
            removed = np.empty(k + 1, dtype=np.int64)
            removed[:k] = wide[centre, :k]
            removed[k] = centre
            rng.shuffle(removed)
            _ruin(seq, pts, pos, discs, ends, neigh, removed)
            for d in removed:
                size = _wake(seq, active, queue, 0, size, pos[d] - 1, pos[d] + 1)
        else:
            # A double bridge within a window: two runs of stops swap places.
            start = rng.integers(0, n - window + 1)
            cut = rng.permutation(window)[:3]
            cut.sort()
            a, b, c = cut[0] + start + 1, cut[1] + start + 1, cut[2] + start + 1
            _kick(seq, pts, pos, a, b, c)
            for at in (a, a + c - b, c):
                _settle(seq, pts, discs, ends, at - 2, at + 1)
                size = _wake(seq, active, queue, 0, size, at - 2, at + 1)
        _search(seq, pts, pos, discs, ends, neigh, active, queue, size, tol)
        rec_len = _keep_or_undo(
            seq, pts, pos, ends, cur_seq, cur_pts, rec_seq, rec_pts, rec_len, drift
        )
    return rec_len


@nb.njit(cache=True, nogil=True)
def _keep_or_undo(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    ends: FloatArray,
    cur_seq: IntArray,
    cur_pts: FloatArray,
    rec_seq: IntArray,
    rec_pts: FloatArray,
    rec_len: float,
    drift: float,
) -> float:
    """The tour ``seq, pts`` kept (as ``cur_seq, cur_pts``) if no longer than the shortest
    met (``rec_seq, rec_pts``, of length ``rec_len``) times ``1 + drift`` (ties too: they let
    the search cross plateaus), else undone back to the kept one. A shorter one becomes the
    shortest met; its length is returned."""
    length = path_length(pts, ends)
    if length < rec_len:
        rec_seq[:] = seq
        rec_pts[:] = pts
        rec_len = length
    if length <= rec_len * (1.0 + max(drift, 1e-12)):
        cur_seq[:] = seq
        cur_pts[:] = pts
        return rec_len
    seq[:] = cur_seq
    pts[:] = cur_pts
    for k in range(seq.size):
        pos[seq[k]] = k
    return rec_len


def improve(
    seq: IntArray,
    pts: FloatArray,
    discs: FloatArray,
    depot_xy: FloatArray,
    time_limit_s: float,
    seed: int = 0,
    drift: float = 0.0,
) -> tuple[IntArray, FloatArray]:
    """A shorter tour through the discs of ``seq`` from a given one, by iterated local search.

    ``seq`` holds discs (rows of ``discs``, each once); ``pts`` a point in each. Runs for
    about ``time_limit_s`` and returns the best order and points found (never longer than
    the start). A kicked tour is kept (the next kicks start from it) when it is no longer
    than the shortest met times ``1 + drift``; else it is undone.
    """
    started = time.perf_counter()
    # The search numbers the discs of the tour 0..n-1 in their starting order: ``seq`` may
    # hold only some of ``discs``.
    ids = np.array(seq, dtype=np.int64)
    discs = np.ascontiguousarray(np.asarray(discs, dtype=np.float64)[ids])
    depot = np.asarray(depot_xy, dtype=np.float64).reshape(2)
    ends = np.ascontiguousarray(np.vstack([depot, depot]))
    seq = np.arange(ids.size, dtype=np.int64)
    pts = np.array(pts, dtype=np.float64).reshape(-1, 2)
    n = seq.size
    start_len = path_length(pts, ends)
    start_seq, start_pts = seq.copy(), pts.copy()
    if n < 2:
        return ids, exact_positions(seq, pts, discs, depot)
    pos = np.empty(n, dtype=np.int64)
    pos[seq] = np.arange(n)
    neigh = neighbours(discs)
    wide = neighbours(discs, RUIN_NEIGHBOURS)
    _descent(seq, pts, pos, discs, ends, neigh, 0, n - 1)
    # The tour kept (which the kicks start from) and the shortest met.
    cur_seq, cur_pts = seq.copy(), pts.copy()
    best_seq, best_pts = seq.copy(), pts.copy()
    tours = (cur_seq, cur_pts, best_seq, best_pts)
    best_len = path_length(pts, ends)
    rng = np.random.default_rng(seed)
    # Kicks run in batches sized to take about _BATCH_S each, so the time limit holds.
    count = 16
    # The shortest length when the search last made headway, and when.
    headway_len, headway_at = best_len, started
    while n >= MIN_SEARCHED and time.perf_counter() - started < time_limit_s:
        tick = time.perf_counter()
        if best_len < headway_len * (1.0 - _STALL_GAIN):
            headway_len, headway_at = best_len, tick
        stalled = tick - headway_at > _STALL_S and n <= _ESCAPE_MAX_DISCS
        if stalled and time_limit_s - (tick - started) > _ESCAPE_S:
            best_len = _escape(seq, pts, pos, discs, ends, neigh, wide, tours, count, rng)
            headway_at = time.perf_counter()
            continue
        best_len = _kicks(seq, pts, pos, discs, ends, neigh, wide, *tours, count, rng, drift)
        took = time.perf_counter() - tick
        left = time_limit_s - (time.perf_counter() - started)
        count = int(np.clip(count * min(_BATCH_S, max(left, 0.0)) / max(took, 1e-6), 1, 4 * count))
        if rng.random() < _STRIP_SHARE:
            # Search over the stops that matter (kicks too), then put the others back.
            m, taken = _strip(seq, pts, pos, ends, _MIN_GAIN * best_len)
            if m >= 4:
                kept = seq[:m]
                near = _among(discs, kept)
                wide_near = _among(discs, kept, RUIN_NEIGHBOURS)
                _descend(kept, pts[:m], pos, discs, ends, near, 0, m - 1)
                if m > WINDOW:
                    # Kept and shortest: strict descent here (no drift).
                    sub = (kept.copy(), pts[:m].copy(), kept.copy(), pts[:m].copy())
                    _kicks(kept, pts[:m], pos, discs, ends, near, wide_near, *sub, count, rng)
            _put_back(seq, pts, pos, discs, ends, m, taken)
            _descend(seq, pts, pos, discs, ends, neigh, 0, n - 1)
            best_len = _keep_or_undo(seq, pts, pos, ends, *tours, best_len, drift)
    exact = exact_positions(best_seq, best_pts, discs, depot)
    if path_length(exact, ends) < best_len:
        best_pts, best_len = exact, path_length(exact, ends)
    if best_len >= start_len:
        return ids[start_seq], start_pts
    return ids[best_seq], best_pts


def _escape(
    seq: IntArray,
    pts: FloatArray,
    pos: IntArray,
    discs: FloatArray,
    ends: FloatArray,
    neigh: IntArray,
    wide: IntArray,
    tours: tuple[IntArray, FloatArray, IntArray, FloatArray],
    count: int,
    rng: np.random.Generator,
) -> float:
    """From the shortest tour met, the depot moved far along it (:func:`_move_depot`) and
    the kicks run from there for ``_ESCAPE_S`` seconds. A shorter tour found becomes the
    kept and the shortest one; else ``seq, pts`` go back to the kept tour. The shortest
    length."""
    cur_seq, cur_pts, best_seq, best_pts = tours
    best_len = path_length(best_pts, ends)
    n = seq.size
    seq[:], pts[:] = best_seq, best_pts
    pos[seq] = np.arange(n)
    at = _move_depot(seq, pts, pos, ends, rng, min(_DEPOT_AWAY, n // 4))
    if at >= 0:
        for lo, hi in ((-1, 2), (n - 3, n), (at - 2, at + 1)):
            _settle(seq, pts, discs, ends, lo, hi)
        _descent(seq, pts, pos, discs, ends, neigh, 0, n - 1)
        trial = (seq.copy(), pts.copy(), seq.copy(), pts.copy())
        until = time.perf_counter() + _ESCAPE_S
        length = path_length(pts, ends)
        while time.perf_counter() < until:
            length = _kicks(seq, pts, pos, discs, ends, neigh, wide, *trial, count, rng)
        if length < best_len:
            cur_seq[:], cur_pts[:] = trial[2], trial[3]
            best_seq[:], best_pts[:] = trial[2], trial[3]
            best_len = length
    seq[:], pts[:] = cur_seq, cur_pts
    pos[seq] = np.arange(n)
    return best_len


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
