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

import time

import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.solvers._disc_kicks import (
    WINDOW,
    _insert_cheapest,
    _keep_or_undo,
    _kicks,
    _move_depot,
    _put_back,
    _strip,
)
from urpt_gcs.solvers._disc_moves import _MIN_GAIN, _descend, _descent
from urpt_gcs.solvers._disc_positions import _settle, exact_positions, path_length

__all__ = [
    "MIN_SEARCHED",
    "NEIGHBOURS",
    "RUIN_NEIGHBOURS",
    "WINDOW",
    "depot_moved",
    "exact_positions",
    "improve",
    "insertion_tour",
    "neighbours",
    "path_length",
    "region_ruin",
]

# Nearest discs considered for a move (fewer left some tours local optima that no kick left;
# benchmarks/README.md has the figures).
NEIGHBOURS = 15
# Fewer discs than this are not searched (the descent alone settles them).
MIN_SEARCHED = 4
# Nearest discs a ruin kick may take out with its disc (more than a move looks at).
RUIN_NEIGHBOURS = 30
# Share of the batches of kicks after which the search also runs on the stops alone, the
# discs their legs cross anyway taken out and put back after.
_STRIP_SHARE = 0.3
# Up to this many discs, a search that has not shortened the tour by _STALL_GAIN (relative)
# in _STALL_S seconds moves the depot to one of the cheapest legs at least _DEPOT_AWAY stops
# from where it is (:func:`_move_depot`), and searches from there for _ESCAPE_S seconds; the
# shortest tour met is kept either way. (No move or kick takes the depot out and puts it on
# a far leg; 2-opt changes one of its legs only; on a ring of discs the side the depot joins
# decides which detours the tour can save, see benchmarks/README.md.) Above it the drift
# acceptance lets the search move instead.
_ESCAPE_MAX_DISCS = 200
_STALL_S = 3.0
_STALL_GAIN = 1e-9
_ESCAPE_S = 1.0
_DEPOT_AWAY = 10
# Seconds a batch of kicks should take (the time limit is checked between batches).
_BATCH_S = 0.05


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
    the depot joins decides which detours the tour can save."""
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
