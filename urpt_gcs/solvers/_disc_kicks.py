"""Kicks of a disc tour (compiled kernels): a local double bridge, or a disc and its nearest
taken out and put back greedily, each followed by a descent from the stops it changed and
kept or undone; the depot moved to a far leg; the stops a leg crosses anyway taken out and
put back.

The tour's conventions are :mod:`urpt_gcs.solvers.disc_tour`'s.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.solvers._disc_moves import (
    _MIN_GAIN,
    _insert_cost,
    _insert_floor,
    _nearest_on_segment,
    _search,
    _to_segment,
    _wake,
)
from urpt_gcs.solvers._disc_positions import _INSIDE, _dist, _pt, _settle, path_length

__all__ = [
    "WINDOW",
    "_DEPOT_CHOICES",
    "_insert_cheapest",
    "_keep_or_undo",
    "_kicks",
    "_move_depot",
    "_put_back",
    "_strip",
]

# Positions a random double bridge spans.
WINDOW = 30
# Share of the kicks that take a disc and its neighbours out and put them back greedily
# (the others are double bridges).
_RUIN_SHARE = 0.5
# A moved depot joins one of this many cheapest legs far enough from where it was, at random.
_DEPOT_CHOICES = 6


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
