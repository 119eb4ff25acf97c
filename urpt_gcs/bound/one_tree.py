"""A Lagrangian 1-tree (Held-Karp) bound over every region, in memory linear in the regions.

The relaxation is that of :mod:`urpt_gcs.bound.lower_bound` (pieces of outer stars, a cost
``c(P, Q)`` no more than the distance between any points of two pieces, multipliers ``mu``
per piece): for every ``mu`` the minimum 1-tree under the weights

    ``w_ij = min over pieces P of i, Q of j of c(P, Q) + mu_P + mu_Q``

less ``2 sum_i max_(P of i) mu_P`` is no longer than any tour. Any weight no larger than
``w_ij`` keeps that true (a 1-tree only shortens when its weights fall), so far pairs take
``max(0, |c_i - c_j| - R_i - R_j) + min mu_i + min mu_j`` from the regions' enclosing discs,
and only the nearest pairs (a KD-tree's neighbours) weigh their pieces one by one. Prim's
algorithm runs over the complete graph with the weights computed as it goes: time
quadratic in the regions per round, memory linear. Every round's value is a valid bound, so
the best so far holds whenever the clock stops the subgradient ascent.

The ascent's direction per piece is its degree in the 1-tree less two where it is its
region's piece of largest multiplier (ties going to the piece the tree uses most), plus the
region's degree less two on every piece of the region: Held-Karp's node penalty, which is a
shift of all of a region's multipliers at once. On points this is Held-Karp itself.
"""

from __future__ import annotations

import math
import time
from typing import Protocol

import numba as nb
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray

__all__ = ["one_tree_bound"]

I64 = npt.NDArray[np.int64]


class _Pieces(Protocol):
    """Annular sectors by region, as :class:`urpt_gcs.bound.pieces.Pieces` holds them."""

    @property
    def region(self) -> I64: ...

    @property
    def cx(self) -> FloatArray: ...

    @property
    def cy(self) -> FloatArray: ...

    @property
    def r1(self) -> FloatArray: ...

    @property
    def n(self) -> int: ...

    def circles(self) -> tuple[FloatArray, FloatArray, FloatArray]: ...


# Per region: the nearest regions (by centre) whose piece pairs are weighed one by one.
_NEAR = 10
# Subgradient rounds without a better bound before the step is halved (and the ascent
# goes back to the best multipliers), and the step below which it stops.
_STALL = 20
_LEAST_STEP = 1e-5
# The step aims this share above the best bound so far (aimed at the far tour, steps
# overshoot).
_AIM = 0.05
# Rounding: a reported bound is lowered by this share of its size.
_ROUNDING = 1e-9
# Multipliers this close (relative) to a region's largest count as tied with it.
_TIE = 1e-12


@nb.njit(cache=True)
def _edge(
    u: int,
    i: int,
    stamp: I64,
    slot: I64,
    nw: FloatArray,
    cx: FloatArray,
    cy: FloatArray,
    cr: FloatArray,
    mu: FloatArray,
    amin: I64,
) -> tuple[float, int]:
    """The weighted edge from region ``u`` to ``i`` and its near-list entry (-1: far, the
    circles' gap with each side's least multiplier), with ``u``'s near list stamped."""
    if stamp[i] == u:
        return nw[slot[i]], slot[i]
    d = math.hypot(cx[u] - cx[i], cy[u] - cy[i]) - cr[u] - cr[i]
    return max(d, 0.0) + mu[amin[u]] + mu[amin[i]], -1


@nb.njit(cache=True)
def _round(
    start: I64,
    mx: FloatArray,
    my: FloatArray,
    rho: FloatArray,
    cx: FloatArray,
    cy: FloatArray,
    cr: FloatArray,
    near_ptr: I64,
    near: I64,
    mu: FloatArray,
    deg: FloatArray,
) -> float:
    """The 1-tree bound at multipliers ``mu`` over regions ``0 .. m - 1`` (region ``m - 1``
    the 1-tree's special node: the depot when there is one); ``deg`` gets each piece's
    degree in it less two for each region's piece of largest multiplier (a subgradient)."""
    m = start.size - 1
    amin = np.empty(m, dtype=np.int64)
    amax = np.empty(m, dtype=np.int64)
    for i in range(m):
        bi, bx = start[i], start[i]
        for p in range(start[i], start[i + 1]):
            if mu[p] < mu[bi]:
                bi = p
            if mu[p] > mu[bx]:
                bx = p
        amin[i], amax[i] = bi, bx
    # The near pairs, piece by piece (each pair weighed once, from its lower region).
    nk = near.size
    nw = np.empty(nk)
    npp = np.empty(nk, dtype=np.int64)
    nqq = np.empty(nk, dtype=np.int64)
    for i in range(m):
        for k in range(near_ptr[i], near_ptr[i + 1]):
            j = near[k]
            floor = max(math.hypot(cx[i] - cx[j], cy[i] - cy[j]) - cr[i] - cr[j], 0.0)
            bv, bp, bq = np.inf, -1, -1
            for p in range(start[i], start[i + 1]):
                if floor + mu[p] + mu[amin[j]] >= bv:
                    continue
                for q in range(start[j], start[j + 1]):
                    d = math.hypot(mx[p] - mx[q], my[p] - my[q]) - rho[p] - rho[q]
                    v = max(d, floor) + mu[p] + mu[q]
                    if v < bv:
                        bv, bp, bq = v, p, q
            nw[k], npp[k], nqq[k] = bv, bp, bq
    for p in range(deg.size):
        deg[p] = 0.0
    total = 0.0
    s = m - 1
    key = np.full(m, np.inf)
    via = np.full(m, -1, dtype=np.int64)  # near-list entry of the key's edge, -1: far
    parent = np.full(m, -1, dtype=np.int64)
    done = np.zeros(m, dtype=np.bool_)
    stamp = np.full(m, -1, dtype=np.int64)
    slot = np.zeros(m, dtype=np.int64)
    done[s] = True
    u = 0
    for _ in range(m - 1):
        done[u] = True
        if parent[u] >= 0:
            total += key[u]
            k = via[u]
            if k >= 0:
                deg[npp[k]] += 1.0
                deg[nqq[k]] += 1.0
            else:
                deg[amin[u]] += 1.0
                deg[amin[parent[u]]] += 1.0
        for k in range(near_ptr[u], near_ptr[u + 1]):
            stamp[near[k]] = u
            slot[near[k]] = k
        nxt = -1
        for i in range(m):
            if done[i]:
                continue
            v, kk = _edge(u, i, stamp, slot, nw, cx, cy, cr, mu, amin)
            if v < key[i]:
                key[i] = v
                parent[i] = u
                via[i] = kk
            if nxt < 0 or key[i] < key[nxt]:
                nxt = i
        if nxt < 0:
            break
        u = nxt
    # The special node's two lightest edges.
    for k in range(near_ptr[s], near_ptr[s + 1]):
        stamp[near[k]] = s
        slot[near[k]] = k
    b1, b2 = np.inf, np.inf
    i1, i2, k1, k2 = -1, -1, -1, -1
    for i in range(s):
        v, kk = _edge(s, i, stamp, slot, nw, cx, cy, cr, mu, amin)
        if v < b1:
            b2, i2, k2 = b1, i1, k1
            b1, i1, k1 = v, i, kk
        elif v < b2:
            b2, i2, k2 = v, i, kk
    for v, i, kk in ((b1, i1, k1), (b2, i2, k2)):
        total += v
        if kk >= 0:
            deg[npp[kk]] += 1.0
            deg[nqq[kk]] += 1.0
        else:
            deg[amin[s]] += 1.0
            deg[amin[i]] += 1.0
    for i in range(m):
        top = mu[amax[i]]
        total -= 2.0 * top
        # Of the pieces of largest multiplier, the one the tree uses most takes the -2: at
        # the start (every multiplier 0) any other choice points away from every ascent.
        pick, used = amax[i], 0.0
        for p in range(start[i], start[i + 1]):
            used += deg[p]
            if mu[p] >= top - _TIE * (1.0 + abs(top)) and deg[p] > deg[pick]:
                pick = p
        deg[pick] -= 2.0
        # And Held-Karp's own direction, the region's degree less two, on all its pieces
        # alike (a shift of all of a region's multipliers is its node penalty).
        for p in range(start[i], start[i + 1]):
            deg[p] += used - 2.0
    return total


def _near_lists(cx: FloatArray, cy: FloatArray) -> tuple[I64, I64]:
    """Each region's nearest regions by centre, symmetric, as a CSR list (both ways)."""
    m = cx.size
    k = min(_NEAR, m - 1)
    _, nearest = cKDTree(np.column_stack([cx, cy])).query(np.column_stack([cx, cy]), k + 1)
    a = np.repeat(np.arange(m), k)
    b = np.asarray(nearest[:, 1:], dtype=np.int64).ravel()
    keep = a != b
    pairs = np.unique(np.sort(np.column_stack([a[keep], b[keep]]), axis=1), axis=0)
    both = np.vstack([pairs, pairs[:, ::-1]])
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    ptr = np.searchsorted(both[:, 0], np.arange(m + 1)).astype(np.int64)
    return ptr, np.ascontiguousarray(both[:, 1], dtype=np.int64)


def one_tree_bound(
    pieces: _Pieces, m: int, upper: float, time_limit_s: float, gap_target: float = 1e-4
) -> tuple[float, int]:
    """The best 1-tree bound found within ``time_limit_s`` (the first round always runs),
    and the rounds run.

    Parameters
    ----------
    pieces
        Pieces of the ``m`` regions, sorted by region (the depot, if any, last), as
        :func:`urpt_gcs.bound.lower_bound.start_pieces` makes them.
    m
        Regions, the depot included.
    upper
        The length of a known tour: the ascent stops there and aims its steps below it.
    time_limit_s
        Seconds for the ascent.
    gap_target
        Stop once ``(upper - bound) / bound`` is at most this.
    """
    started = time.perf_counter()
    if m <= 1:
        return 0.0, 0
    mx, my, rho = pieces.circles()
    cx, cy, cr = np.zeros(m), np.zeros(m), np.zeros(m)
    cx[pieces.region], cy[pieces.region] = pieces.cx, pieces.cy
    np.maximum.at(cr, pieces.region, pieces.r1)
    # A hair more, as for the pieces' circles, so that rounding cannot raise the bound.
    cr = cr * (1.0 + 1e-12) + 1e-12
    start = np.searchsorted(pieces.region, np.arange(m + 1)).astype(np.int64)
    if m == 2:
        # The only tour is there and back: twice the least distance between the two.
        return 2.0 * max(math.hypot(cx[0] - cx[1], cy[0] - cy[1]) - cr[0] - cr[1], 0.0), 1
    ptr, near = _near_lists(cx, cy)
    mu = np.zeros(pieces.n)
    best_mu = mu.copy()
    deg = np.zeros(pieces.n)
    g_prev = np.zeros(pieces.n)
    best, lam, stall, rounds = -math.inf, 1.0, 0, 0
    while True:
        value = _round(start, mx, my, rho, cx, cy, cr, ptr, near, mu, deg)
        rounds += 1
        if value > best:
            best, best_mu[:], stall = value, mu, 0
        else:
            stall += 1
        if upper - best <= gap_target * best or time.perf_counter() - started >= time_limit_s:
            break
        if stall >= _STALL:
            lam *= 0.5
            stall = 0
            mu[:] = best_mu
            g_prev[:] = 0.0
            if lam < _LEAST_STEP:
                break
            continue
        g = 0.7 * deg + 0.3 * g_prev
        g_prev = g
        norm = float(g @ g)
        if norm == 0.0:
            break
        aim = min(upper, best + _AIM * abs(best) + 1e-9 * upper)
        step = lam * (aim - value) / norm
        if step <= 0.0:
            step = lam * 1e-3 * upper / norm
        mu += step * g
    return max(best - _ROUNDING * abs(best), 0.0), rounds
