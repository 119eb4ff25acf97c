"""Compiled removal, insertion and the annealing loop of the large-neighbourhood search.

Conventions (``P``, ``t``, ``pos``, ``W``, ``Q``) are those of :mod:`._ls_kernels`. Every
random draw comes from the ``numpy.random.Generator`` passed in as ``rng``, so that a run is a
pure function of its seed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from urpt_gcs.solvers._ls_kernels import (
    EPS,
    best_insertion,
    cycle_cost,
    dist,
    dtr,
    insert_at,
    local_search,
    push_around,
    set_positions,
)

__all__ = [
    "F_BEST",
    "F_CUR",
    "F_TEMP",
    "I_ITER",
    "I_LAST",
    "I_PHASE",
    "I_RESTARTS",
    "N_INSERTIONS",
    "N_REMOVALS",
    "P_COOL",
    "P_NOISE",
    "P_POWER",
    "P_TEMP0",
    "P_TEMP_MIN",
    "Q_HORIZON",
    "Q_KMAX",
    "Q_MOVES",
    "Q_RESTARTS",
    "Q_STALL",
    "insert_clusters",
    "lns_chunk",
    "queue_all",
    "rebuild",
    "recombine",
    "remove_clusters",
]

# Slots of the float state vector of one trial (see lns_chunk) ...
F_CUR, F_BEST, F_TEMP = 0, 1, 2
# ... of its int state vector ...
I_ITER, I_LAST, I_RESTARTS, I_PHASE = 0, 1, 2, 3
# ... and of the parameter vectors.
P_TEMP0, P_COOL, P_TEMP_MIN, P_NOISE, P_POWER = 0, 1, 2, 3, 4
Q_KMAX, Q_STALL, Q_RESTARTS, Q_MOVES, Q_HORIZON = 0, 1, 2, 3, 4
# Removal heuristics (random, worst, related, segment) and insertion orders (random,
# cheapest first, costliest first), in the order of the weight vector.
N_REMOVALS, N_INSERTIONS = 4, 3


@njit(cache=True, nogil=True)
def insert_clusters(P, t, n, pos, rem, k, mode, noise, rng):  # type: ignore[no-untyped-def]
    """Insert the clusters ``rem[:k]`` into the partial tour ``t[:n]``; return the new length.

    Each waiting cluster keeps its cheapest (node, place); inserting one node removes one edge
    and adds two, so the others are refreshed from those two edges unless their best place
    was the removed edge. ``mode`` orders the insertions: 0 random, 1 cheapest first,
    2 costliest first; ``noise`` scales a multiplicative random factor on that choice.
    """
    _, _, _, start, cl, _, _, _ = P
    cost = np.zeros(k)
    node = np.empty(k, np.int32)
    pred = np.full(k, -1, np.int32)  # the node to insert after; -1: to be recomputed
    alive = np.ones(k, np.bool_)
    for r in range(k):
        node[r] = start[rem[r]]
    for left in range(k, 0, -1):
        if n > 0:
            for r in range(k):
                if alive[r] and pred[r] < 0:
                    c, v, i = best_insertion(P, t, n, pos, rem[r])
                    cost[r], node[r], pred[r] = c, v, t[i - 1]
        pick = -1
        if mode == 0:
            j = rng.integers(0, left)
            for r in range(k):
                if alive[r]:
                    if j == 0:
                        pick = r
                        break
                    j -= 1
        else:
            key_best = np.inf
            for r in range(k):
                if alive[r]:
                    key = cost[r] * (1.0 + noise * (2.0 * rng.random() - 1.0))
                    if mode == 2:
                        key = -key
                    if pick < 0 or key < key_best:
                        key_best, pick = key, r
        alive[pick] = False
        v = node[pick]
        if n == 0:
            insert_at(t, pos, cl, 0, 0, v)
            n = 1
            continue
        a = pred[pick]
        i = pos[cl[a]]
        b = t[i + 1] if i + 1 < n else t[0]
        insert_at(t, pos, cl, n, i + 1, v)
        n += 1
        for r in range(k):
            if not alive[r] or pred[r] < 0:
                continue
            if pred[r] == a or n == 2:
                pred[r] = -1
                continue
            c = rem[r]
            for w in range(start[c], start[c + 1]):
                c1 = dist(P, a, w) + dtr(P, v, w) - dist(P, a, v)
                if c1 < cost[r]:
                    cost[r], node[r], pred[r] = c1, w, a
                c2 = dist(P, v, w) + dtr(P, b, w) - dist(P, v, b)
                if c2 < cost[r]:
                    cost[r], node[r], pred[r] = c2, w, v
    return n


@njit(cache=True, nogil=True)
def remove_clusters(P, t, m, pos, k, method, power, rem, rng):  # type: ignore[no-untyped-def]
    """Remove ``k`` clusters from ``t[:m]`` into ``rem``; return the new length.

    ``method`` 0 removes at random, 1 the clusters whose removal saves most, 2 the clusters
    nearest to a random one, 3 a random segment. 1 and 2 draw from the ranked list with a
    bias ``power`` to its front (1: uniform; larger: greedier).
    """
    _, _, _, _, cl, _, setd, _ = P
    mark = np.zeros(m, np.bool_)
    if method == 3:
        s = rng.integers(0, m)
        for q in range(k):
            mark[(s + q) % m] = True
    else:
        key = np.empty(m)
        if method == 1:
            for i in range(m):
                p = t[i - 1] if i > 0 else t[m - 1]
                x = t[i]
                nx = t[i + 1] if i + 1 < m else t[0]
                key[i] = dist(P, p, nx) - dist(P, p, x) - dist(P, x, nx)
        elif method == 2:
            a = t[rng.integers(0, m)]
            c = cl[a]
            for i in range(m):
                # On the plane the clusters are related by their nodes' distance instead.
                key[i] = setd[c, cl[t[i]]] if setd.shape[0] > 0 else dist(P, a, t[i])
        else:
            for i in range(m):
                key[i] = rng.random()
        order = np.argsort(key)
        bias = power if method != 0 else 1.0
        for n in range(m, m - k, -1):
            j = int(n * rng.random() ** bias)
            mark[order[j]] = True
            for q in range(j, n - 1):
                order[q] = order[q + 1]
    w = 0
    r = 0
    for i in range(m):
        if mark[i]:
            rem[r] = cl[t[i]]
            r += 1
        else:
            t[w] = t[i]
            w += 1
    set_positions(t, pos, cl, w)
    return w


@njit(cache=True, nogil=True)
def _roulette(weights, lo, hi, rng):  # type: ignore[no-untyped-def]
    """Index in ``lo:hi`` (counted from ``lo``) drawn with probability proportional to weight."""
    x = rng.random() * weights[lo:hi].sum()
    for q in range(lo, hi - 1):
        x -= weights[q]
        if x < 0.0:
            return q - lo
    return hi - 1 - lo


@njit(cache=True, nogil=True)
def rebuild(P, t, m, moves, W, Q, rng):  # type: ignore[no-untyped-def]
    """A fresh tour: every cluster inserted in random order, then local search; its cost."""
    cl = P[4]
    pos, rem = W[0], W[1]
    for c in range(m):
        rem[c] = c
    pos[:] = -1
    insert_clusters(P, t, 0, pos, rem, m, 0, 0.0, rng)
    for c in range(m):
        push_around(Q, t, cl, m, pos[c])
    return local_search(P, t, m, moves, W, Q)


@njit(cache=True, nogil=True)
def queue_all(P, t, m, W, Q):  # type: ignore[no-untyped-def]
    """Queue every cluster of ``t[:m]`` for the local search."""
    cl = P[4]
    pos = W[0]
    set_positions(t, pos, cl, m)
    for c in range(m):
        push_around(Q, t, cl, m, pos[c])


@njit(cache=True, nogil=True)
def lns_chunk(P, tours, sf, si, pf, pi, weights, W, Q, rng, n_iter):  # type: ignore[no-untyped-def]
    """Run up to ``n_iter`` iterations of one trial; return True once the trial has ended.

    ``tours = (cur, best, trial)``. One iteration removes k clusters from the current tour,
    re-inserts them, searches locally around them, then keeps the result by a
    simulated-annealing rule at temperature ``sf[F_TEMP]``, which cools geometrically. When
    the trial best has not improved for ``pi[Q_STALL]`` iterations, the search restarts warm
    from the trial best, up to ``pi[Q_RESTARTS]`` times, then the trial ends. Removal and
    insertion heuristics are drawn with probabilities proportional to ``weights``.
    """
    cl = P[4]
    cur, best, trial = tours
    pos, rem = W[0], W[1]
    m = cur.shape[0]
    moves = pi[Q_MOVES]
    for _ in range(n_iter):
        trial[:] = cur
        set_positions(trial, pos, cl, m)
        k = 1 + rng.integers(0, pi[Q_KMAX])
        method = _roulette(weights, 0, N_REMOVALS, rng)
        n = remove_clusters(P, trial, m, pos, k, method, pf[P_POWER], rem, rng)
        mode = _roulette(weights, N_REMOVALS, N_REMOVALS + N_INSERTIONS, rng)
        insert_clusters(P, trial, n, pos, rem, k, mode, pf[P_NOISE], rng)
        for r in range(k):
            push_around(Q, trial, cl, m, pos[rem[r]])
        cost = local_search(P, trial, m, moves, W, Q)
        delta = cost - sf[F_CUR]
        if delta < -EPS or rng.random() < np.exp(-delta / sf[F_TEMP]):
            cur[:] = trial
            sf[F_CUR] = cost
        si[I_ITER] += 1
        if cost < sf[F_BEST] - EPS:
            best[:] = trial
            sf[F_BEST] = cost
            si[I_LAST] = si[I_ITER]
        sf[F_TEMP] = max(sf[F_TEMP] * pf[P_COOL], pf[P_TEMP_MIN])
        if si[I_ITER] - si[I_PHASE] >= pi[Q_HORIZON] and si[I_ITER] - si[I_LAST] >= pi[Q_STALL]:
            if si[I_RESTARTS] >= pi[Q_RESTARTS]:
                return True
            si[I_RESTARTS] += 1
            si[I_LAST] = si[I_ITER]
            si[I_PHASE] = si[I_ITER]
            cur[:] = best
            sf[F_CUR] = sf[F_BEST]
            sf[F_TEMP] = pf[P_TEMP0]
    return False


@njit(cache=True, nogil=True)
def recombine(P, best, elite, n_children, moves, W, Q, rng, child):  # type: ignore[no-untyped-def]
    """Cross ``best`` with the tours ``elite`` ``n_children`` times; keep improvements in place.

    A child is a random segment of an elite tour (its order and nodes) followed by the other
    clusters in the order and with the nodes of ``best``, then improved by local search
    everywhere. Returns the cost of ``best`` afterwards.
    """
    cl = P[4]
    pos = W[0]
    m = best.shape[0]
    best_cost = cycle_cost(P, best, m)
    taken = np.zeros(m, np.bool_)
    for _ in range(n_children):
        b = elite[rng.integers(0, elite.shape[0])]
        length = 2 + rng.integers(0, max(1, m // 2 - 1))
        s = rng.integers(0, m)
        taken[:] = False
        for q in range(length):
            child[q] = b[(s + q) % m]
            taken[cl[child[q]]] = True
        # Go on in best from the cluster that follows the segment in the elite tour.
        after = cl[b[(s + length) % m]]
        j = 0
        while cl[best[j]] != after:
            j += 1
        w = length
        for q in range(m):
            v = best[(j + q) % m]
            if not taken[cl[v]]:
                child[w] = v
                w += 1
        set_positions(child, pos, cl, m)
        for c in range(m):
            push_around(Q, child, cl, m, pos[c])
        cost = local_search(P, child, m, moves, W, Q)
        if cost < best_cost - EPS:
            best[:] = child
            best_cost = cost
    return best_cost
