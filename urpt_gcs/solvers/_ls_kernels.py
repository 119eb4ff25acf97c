"""Compiled tour bookkeeping, cheapest insertion, exact node re-selection and local search.

Conventions shared with :mod:`._lns_kernels`:

- ``P = (d, dt, xy, start, cl, nbr, setd, kn)`` describes the instance. Nodes are renumbered
  so that the nodes of cluster ``c`` are ``start[c]:start[c + 1]``; ``cl[v]`` is the cluster
  of node ``v``. Distances come in one of two forms: explicit, ``d[u, v]`` is the cost of
  ``u -> v`` (asymmetric allowed) and ``dt`` its transpose, C-contiguous, so that reading a
  column is reading a row, and ``xy`` is empty; or on the plane, ``xy[v]`` is node ``v``'s
  position, the cost is Euclidean, computed where needed, and ``d``, ``dt`` are empty, so that
  memory stays linear in the nodes. The third column of ``xy`` is half of what a stop costs
  at each node (0 for none): a leg between two distinct points costs their two halves on top
  of its length, so a tour pays one stop's cost per point it stops at (and the depot).
  ``nbr[c]`` lists other clusters nearest first (all of them, ranked by ``setd``, the
  cluster-to-cluster distance, when explicit; the nearest few by a spatial index, ``setd``
  empty, on the plane), and moves look at the first ``kn``.
- A tour is an int32 array ``t`` of nodes, one per cluster, read cyclically; a partial tour is
  its first ``n`` entries. ``pos[c]`` is the index of cluster ``c`` in ``t`` (-1: absent).
- ``Q = (stack, queued, top)`` is the set of clusters the local search still has to look at
  (``top`` is a one-element array holding the stack height); ``W = (pos, rem, fw, bw, buf)``
  is scratch space: ``pos`` as above, ``rem`` an int32 array of ``m`` entries, ``fw`` and
  ``bw`` float arrays of ``m + 1`` and ``buf`` an int32 array of ``m``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "DP_WORK_CAP",
    "EPS",
    "OR_OPT",
    "SYMMETRIC",
    "TWO_OPT",
    "best_insertion",
    "cycle_cost",
    "descend_nodes",
    "dist",
    "dtr",
    "insert_at",
    "local_search",
    "local_search_for",
    "push",
    "push_around",
    "remove_at",
    "reopt_nodes",
    "set_positions",
]

EPS = 1e-9
# Bits of the ``moves`` argument of local_search: the distances are symmetric; use 2-opt;
# use Or-opt. Moving single clusters and the exact node choice are always on.
SYMMETRIC, TWO_OPT, OR_OPT = 1, 2, 4
# Distance evaluations one exact node re-selection may take; beyond it (thousands of clusters
# of hundreds of nodes each) the nodes are re-chosen one cluster at a time instead.
DP_WORK_CAP = 300_000_000
# Sweeps of that one-at-a-time re-selection, at most.
_DESCENT_SWEEPS = 4


@njit(cache=True, nogil=True)
def dist(P, u, v):  # type: ignore[no-untyped-def]
    """The cost of ``u -> v``: from the matrix, or Euclidean between the node positions (plus
    their halves of a stop's cost, the third column, between distinct points)."""
    xy = P[2]
    if xy.shape[0] == 0:
        return P[0][u, v]
    dx = xy[u, 0] - xy[v, 0]
    dy = xy[u, 1] - xy[v, 1]
    d = np.sqrt(dx * dx + dy * dy)
    return d + (xy[u, 2] + xy[v, 2]) * (d > 0.0)


@njit(cache=True, nogil=True)
def dtr(P, u, v):  # type: ignore[no-untyped-def]
    """The cost of ``v -> u``, read from the transposed matrix so that a loop over ``v``
    reads a row."""
    xy = P[2]
    if xy.shape[0] == 0:
        return P[1][u, v]
    dx = xy[u, 0] - xy[v, 0]
    dy = xy[u, 1] - xy[v, 1]
    d = np.sqrt(dx * dx + dy * dy)
    return d + (xy[u, 2] + xy[v, 2]) * (d > 0.0)


@njit(cache=True, nogil=True)
def cycle_cost(P, t, n):  # type: ignore[no-untyped-def]
    if n < 2:
        return dist(P, t[0], t[0]) if n == 1 else 0.0
    total = dist(P, t[n - 1], t[0])
    for i in range(n - 1):
        total += dist(P, t[i], t[i + 1])
    return total


@njit(cache=True, nogil=True)
def set_positions(t, pos, cl, n):  # type: ignore[no-untyped-def]
    pos[:] = -1
    for i in range(n):
        pos[cl[t[i]]] = i


@njit(cache=True, nogil=True)
def insert_at(t, pos, cl, n, i, v):  # type: ignore[no-untyped-def]
    for j in range(n, i, -1):
        t[j] = t[j - 1]
        pos[cl[t[j]]] = j
    t[i] = v
    pos[cl[v]] = i


@njit(cache=True, nogil=True)
def remove_at(t, pos, cl, n, i):  # type: ignore[no-untyped-def]
    pos[cl[t[i]]] = -1
    for j in range(i, n - 1):
        t[j] = t[j + 1]
        pos[cl[t[j]]] = j


@njit(cache=True, nogil=True)
def _wrap(i, m):  # type: ignore[no-untyped-def]
    return i - m if i >= m else i


@njit(cache=True, nogil=True)
def push(Q, c):  # type: ignore[no-untyped-def]
    stack, queued, top = Q
    if not queued[c]:
        queued[c] = True
        stack[top[0]] = c
        top[0] += 1


@njit(cache=True, nogil=True)
def push_around(Q, t, cl, n, i):  # type: ignore[no-untyped-def]
    """Queue the cluster at index ``i`` of ``t[:n]`` and its two tour neighbours."""
    push(Q, cl[t[i]])
    push(Q, cl[t[i - 1 if i > 0 else n - 1]])
    push(Q, cl[t[i + 1 if i + 1 < n else 0]])


@njit(cache=True, nogil=True)
def best_insertion(P, t, n, pos, c):  # type: ignore[no-untyped-def]
    """Cheapest node of cluster ``c`` and place in ``t[:n]``: (cost, node, index to insert at).

    On a long tour only the edges next to the ``kn`` clusters of the tour nearest to ``c`` are
    tried; on a short one, every edge.
    """
    _, _, _, start, _, nbr, _, kn = P
    v0, v1 = start[c], start[c + 1]
    if n == 0:
        return 0.0, v0, 0
    best, best_v, best_i = np.inf, v0, 0
    full = n <= 2 * kn + 2
    if not full:
        found = 0
        for q in nbr[c]:
            j = pos[q]
            if j < 0:
                continue
            found += 1
            for side in range(2):
                e = j if side else (j - 1 if j > 0 else n - 1)
                a = t[e]
                b = t[e + 1] if e + 1 < n else t[0]
                base = dist(P, a, b)
                for v in range(v0, v1):
                    cost = dist(P, a, v) + dtr(P, b, v) - base
                    if cost < best:
                        best, best_v, best_i = cost, v, e + 1
            if found == kn:
                break
        full = found < 2
    if full:
        for e in range(n):
            a = t[e]
            b = t[e + 1] if e + 1 < n else t[0]
            base = dist(P, a, b) if n > 1 else 0.0
            for v in range(v0, v1):
                cost = dist(P, a, v) + dtr(P, b, v) - base
                if cost < best:
                    best, best_v, best_i = cost, v, e + 1
    return best, best_v, best_i


@njit(cache=True, nogil=True)
def descend_nodes(P, t, m, Q):  # type: ignore[no-untyped-def]
    """Re-choose each cluster's node, one at a time, as the cheapest between its neighbours'
    current nodes; sweep until nothing changes (or ``_DESCENT_SWEEPS`` sweeps). Changed
    clusters are queued in ``Q``. Never lengthens the tour; returns its cost."""
    _, _, _, start, cl, _, _, _ = P
    for _sweep in range(_DESCENT_SWEEPS):
        changed = False
        for i in range(m):
            a = t[i - 1] if i > 0 else t[m - 1]
            b = t[i + 1] if i + 1 < m else t[0]
            c = cl[t[i]]
            best_v = t[i]
            best = dist(P, a, best_v) + dtr(P, b, best_v)
            for v in range(start[c], start[c + 1]):
                cost = dist(P, a, v) + dtr(P, b, v)
                if cost < best - EPS:
                    best, best_v = cost, v
            if best_v != t[i]:
                t[i] = best_v
                push(Q, c)
                changed = True
        if not changed:
            break
    return cycle_cost(P, t, m)


@njit(cache=True, nogil=True)
def reopt_nodes(P, t, m, pos, best_cost, Q):  # type: ignore[no-untyped-def]
    """Best node per cluster for the cluster order of ``t[:m]`` (exact); rewrite ``t`` if shorter.

    A shortest path through the layered graph of cluster members, once from each node of the
    smallest cluster, which closes the cycle. Clusters whose node changed are queued in ``Q``.
    When that would take more than ``DP_WORK_CAP`` distance evaluations, the nodes are
    re-chosen one cluster at a time instead (:func:`descend_nodes`), which is not exact.
    Returns the cost of ``t`` afterwards.
    """
    _, _, _, start, cl, _, _, _ = P
    if m < 2:
        return cycle_cost(P, t, m)
    s = 0
    for i in range(1, m):
        c, cs = cl[t[i]], cl[t[s]]
        if start[c + 1] - start[c] < start[cs + 1] - start[cs]:
            s = i
    work = 0.0
    for i in range(m):
        c, prev = cl[t[i]], cl[t[i - 1]]
        work += float(start[c + 1] - start[c]) * float(start[prev + 1] - start[prev])
    cs = cl[t[s]]
    if work * float(start[cs + 1] - start[cs]) > DP_WORK_CAP:
        return descend_nodes(P, t, m, Q)
    lab = np.empty(start[-1])
    back = np.empty(start[-1], np.int32)
    out = np.empty(m, np.int32)
    improved = False
    c0 = cl[t[s]]
    for u in range(start[c0], start[c0 + 1]):
        prev = c0
        for step in range(1, m):
            c = cl[t[(s + step) % m]]
            for v in range(start[c], start[c + 1]):
                if step == 1:
                    lab[v], back[v] = dist(P, u, v), u
                    continue
                bd, bw = np.inf, -1
                for w in range(start[prev], start[prev + 1]):
                    x = lab[w] + dtr(P, v, w)
                    if x < bd:
                        bd, bw = x, w
                lab[v], back[v] = bd, bw
            prev = c
        for w in range(start[prev], start[prev + 1]):
            total = lab[w] + dist(P, w, u)
            if total < best_cost - EPS:
                best_cost = total
                improved = True
                x = w
                for j in range(m - 1, 0, -1):
                    out[j] = x
                    x = back[x]
                out[0] = u
    if improved:
        for i in range(m):
            if t[(s + i) % m] != out[i]:
                push(Q, cl[out[i]])
        t[:m] = out
        set_positions(t, pos, cl, m)
    return best_cost


@njit(cache=True, nogil=True)
def _try_move(P, t, m, pos, c, Q):  # type: ignore[no-untyped-def]
    """Take cluster ``c`` out and put it back at its cheapest place with its cheapest node.

    The edges next to its nearest clusters (or all, on a short tour) are tried, and the edge
    its neighbours would form without it, where only its node can change.
    """
    _, _, _, start, cl, nbr, _, kn = P
    v0, v1 = start[c], start[c + 1]
    i = pos[c]
    x = t[i]
    ip = i - 1 if i > 0 else m - 1
    p = t[ip]
    nx = t[i + 1 if i + 1 < m else 0]
    base = dist(P, p, nx)
    gain = dist(P, p, x) + dist(P, x, nx) - base
    best, best_v, best_e = gain - EPS, -1, -1
    for v in range(v0, v1):
        cost = dist(P, p, v) + dtr(P, nx, v) - base
        if cost < best:
            best, best_v = cost, v
    full = m <= 2 * kn + 2
    n_cand = m if full else 2 * kn
    for q in range(n_cand):
        if full:
            e = q
        else:
            j = pos[nbr[c, q >> 1]]
            e = j if q & 1 else (j - 1 if j > 0 else m - 1)
        if e == i or e == ip:  # noqa: SIM109 (numba: no `in` on mixed int tuples)
            continue
        a = t[e]
        b = t[e + 1 if e + 1 < m else 0]
        base = dist(P, a, b)
        for v in range(v0, v1):
            cost = dist(P, a, v) + dtr(P, b, v) - base
            if cost < best:
                best, best_v, best_e = cost, v, e
    if best_v < 0:
        return False
    push(Q, cl[p])
    push(Q, cl[nx])
    if best_e < 0:
        t[i] = best_v
        push(Q, c)
        return True
    remove_at(t, pos, cl, m, i)
    j = best_e + 1 if best_e < i else best_e
    insert_at(t, pos, cl, m - 1, j, best_v)
    push_around(Q, t, cl, m, j)
    return True


@njit(cache=True, nogil=True)
def _try_two_opt(P, t, m, pos, c, sym, fw, bw, Q):  # type: ignore[no-untyped-def]
    """2-opt moves that join cluster ``c`` to one of its nearest clusters.

    Removing the edges after indices ``lo < hi`` and reversing ``t[lo + 1 : hi + 1]``; for an
    asymmetric instance the reversed part is costed in reverse via prefix sums.
    """
    _, _, _, _, cl, nbr, _, kn = P
    if not sym:
        fw[0] = 0.0
        bw[0] = 0.0
        for q in range(m - 1):
            fw[q + 1] = fw[q] + dist(P, t[q], t[q + 1])
            bw[q + 1] = bw[q] + dist(P, t[q + 1], t[q])
    i = pos[c]
    for q in nbr[c, :kn]:
        j = pos[q]
        for shift in range(2):
            p1 = (i - shift) % m
            p2 = (j - shift) % m
            lo, hi = min(p1, p2), max(p1, p2)
            if hi - lo < 2 or (lo == 0 and hi == m - 1):
                continue
            a, b, x = t[lo], t[lo + 1], t[hi]
            e = t[hi + 1] if hi + 1 < m else t[0]
            delta = dist(P, a, x) + dist(P, b, e) - dist(P, a, b) - dist(P, x, e)
            if not sym:
                delta += (bw[hi] - bw[lo + 1]) - (fw[hi] - fw[lo + 1])
            if delta < -EPS:
                u, w = lo + 1, hi
                while u < w:
                    t[u], t[w] = t[w], t[u]
                    pos[cl[t[u]]] = u
                    pos[cl[t[w]]] = w
                    u += 1
                    w -= 1
                for z in (a, b, x, e):
                    push(Q, cl[z])
                return True
    return False


@njit(cache=True, nogil=True)
def _try_or_opt(P, t, m, pos, c, buf, Q):  # type: ignore[no-untyped-def]
    """Move the 2 or 3 clusters starting at ``c`` next to a cluster near its ends, either way."""
    _, _, _, _, cl, nbr, _, kn = P
    s = pos[c]
    for length in range(2, 4):
        if m < length + 3:
            return False
        p = t[s - 1 if s > 0 else m - 1]
        first = t[s]
        last = t[_wrap(s + length - 1, m)]
        nx = t[_wrap(s + length, m)]
        fwd = 0.0
        rev = 0.0
        for q in range(length - 1):
            x, y = t[_wrap(s + q, m)], t[_wrap(s + q + 1, m)]
            fwd += dist(P, x, y)
            rev += dist(P, y, x)
        gain = dist(P, p, first) + dist(P, last, nx) - dist(P, p, nx)
        best, best_off, best_rev = -EPS, -1, False
        for end in (first, last):
            for q in nbr[cl[end], :kn]:
                j = pos[q]
                for side in range(2):
                    off = j - 1 + side - s
                    off += m if off < 0 else 0
                    if off < length or off > m - 2:
                        continue
                    a = t[_wrap(s + off, m)]
                    b = t[_wrap(s + off + 1, m)]
                    base = dist(P, a, b) + gain
                    x = dist(P, a, first) + dist(P, last, b) - base
                    if x < best:
                        best, best_off, best_rev = x, off, False
                    y = dist(P, a, last) + dist(P, first, b) - base + rev - fwd
                    if y < best:
                        best, best_off, best_rev = y, off, True
        if best_off < 0:
            continue
        # Rebuild from the node after the segment: the rest up to a, the segment, the rest.
        w = 0
        for off in range(length, best_off + 1):
            buf[w] = t[_wrap(s + off, m)]
            w += 1
        for q in range(length):
            buf[w] = t[_wrap(s + (length - 1 - q if best_rev else q), m)]
            w += 1
        for off in range(best_off + 1, m):
            buf[w] = t[_wrap(s + off, m)]
            w += 1
        t[:m] = buf[:m]
        set_positions(t, pos, cl, m)
        for z in (p, nx, first, last):
            push(Q, cl[z])
        push_around(Q, t, cl, m, pos[cl[first]])
        push_around(Q, t, cl, m, pos[cl[last]])
        return True
    return False


@njit(cache=True, nogil=True)
def local_search(P, t, m, moves, W, Q):  # type: ignore[no-untyped-def]
    """Improve ``t[:m]`` around the queued clusters, then re-choose all nodes exactly; repeat.

    Each queued cluster is tried with a move (out and back in with its node re-chosen), 2-opt
    and Or-opt towards its nearest clusters; a change queues the clusters it touched. When the
    queue is empty the node choice for the order is made exact, which may queue more.
    Returns the cost of the tour.
    """
    return local_search_for(P, t, m, moves, W, Q, -1)[0]


@njit(cache=True, nogil=True)
def local_search_for(P, t, m, moves, W, Q, budget):  # type: ignore[no-untyped-def]
    """:func:`local_search` that stops after ``budget`` queued clusters (-1: none), so that a
    caller can read the clock between calls; the tour is whole at every stop. Returns the
    cost of the tour and whether the search has ended (queue empty, nodes re-chosen)."""
    pos, _, fw, bw, buf = W
    stack, queued, top = Q
    while True:
        while top[0] > 0:
            if budget == 0:
                return cycle_cost(P, t, m), False
            budget -= 1
            top[0] -= 1
            c = stack[top[0]]
            queued[c] = False
            if m < 3:
                continue
            if _try_move(P, t, m, pos, c, Q):
                continue
            sym = moves & SYMMETRIC != 0
            if moves & TWO_OPT and m >= 5 and _try_two_opt(P, t, m, pos, c, sym, fw, bw, Q):
                continue
            if moves & OR_OPT:
                _try_or_opt(P, t, m, pos, c, buf, Q)
        cost = cycle_cost(P, t, m)
        new = reopt_nodes(P, t, m, pos, cost, Q)
        if top[0] == 0 or new >= cost - EPS:
            return new, True
