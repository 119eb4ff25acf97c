"""The compiled moves of the route search (:mod:`urpt_gcs.solvers.sortie_routes`).

The routes are linked lists held in one integer array (``links``, rows below) and timed in
one float array (``times``): each stop's time since take-off and time to landing make every
move's cost, and every route's new time, a constant-time sum. ``leg`` holds what legs are
timed with: the stops' positions, their legs from and to home, the model's scalars, the
short-leg table, the legs' given times (or none) and the alternative positions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "BACK",
    "ENDURANCE",
    "FIRST",
    "LANDING",
    "NXT",
    "OUT",
    "OVER",
    "PRE",
    "PRV",
    "RID",
    "RTIME",
    "RUIN_MAX",
    "SHORT",
    "SIZE",
    "STOP",
    "SUF",
    "TAKEOFF",
    "V",
    "local_search",
    "retime",
    "ruin_and_recreate",
]

# Ruin and recreate takes out one stop and up to this many of its nearest stops.
RUIN_MAX = 10
# Improving moves one local search makes at most, per stop: each shortens the total, so this
# is never reached in practice; it bounds the search if rounding ever let two moves undo
# each other.
_MOVES_PER_STOP = 1000
_EPS_S = 1e-7

# The scalars the kernels read, by index into one array.
V, OVER, SHORT, TAKEOFF, LANDING, STOP, ENDURANCE = range(7)
# The rows of the routes' integer state: per stop its next and previous stop (-1 for home),
# its route and place in it; per route its first and last stop and its size.
NXT, PRV, RID, POS, FIRST, LAST, SIZE = range(7)
# The rows of their times: per route its flight time; per stop the time from take-off to the
# end of its stop, and from leaving it to the landing.
RTIME, PRE, SUF = range(3)
# The rows of each stop's legs from and to home.
OUT, BACK = range(2)


@njit(cache=True)
def _cost(x, y, leg):  # type: ignore[no-untyped-def]
    """Time of the leg from ``x`` to ``y`` (-1 is home: out at the cruise speed, back at the
    return speed)."""
    xy, home_s, par, table, dense = leg[0], leg[1], leg[2], leg[3], leg[4]
    if x < 0:
        return home_s[OUT, y]
    if y < 0:
        return home_s[BACK, x]
    if dense.shape[0] > 0:
        return dense[x, y]
    d = math.hypot(xy[x, 0] - xy[y, 0], xy[x, 1] - xy[y, 1])
    short = par[SHORT]
    if d >= short:
        return d / par[V] + par[OVER]
    n = table.shape[0]
    f = d / short * (n - 1)
    i = int(f)
    if i >= n - 1:
        return table[n - 1]
    f -= i
    return table[i] + f * (table[i + 1] - table[i])


@njit(cache=True)
def retime(r, links, times, leg):  # type: ignore[no-untyped-def]
    """Walk route ``r`` from its first stop: its stops' route, place and times, and its last
    stop, size and time."""
    nxt, prv = links[NXT], links[PRV]
    pre, suf = times[PRE], times[SUF]
    par = leg[2]
    a = links[FIRST, r]
    if a < 0:
        links[SIZE, r] = 0
        links[LAST, r] = -1
        times[RTIME, r] = 0.0
        return
    t = par[TAKEOFF]
    x = -1
    n = 0
    while a >= 0:
        t += _cost(x, a, leg) + par[STOP]
        pre[a] = t
        links[RID, a] = r
        links[POS, a] = n
        n += 1
        x = a
        a = nxt[a]
    links[LAST, r] = x
    links[SIZE, r] = n
    s = leg[1][BACK, x] + par[LANDING]
    suf[x] = s
    a = x
    while prv[a] >= 0:
        p = prv[a]
        s += par[STOP] + _cost(p, a, leg)
        suf[p] = s
        a = p
    times[RTIME, r] = pre[x] + suf[x]


@njit(cache=True)
def _joined(x, c, times, leg):  # type: ignore[no-untyped-def]
    """Time of a route made of one route's stops up to ``x`` and another's from ``c`` on
    (-1: none of that route)."""
    par = leg[2]
    if x < 0 and c < 0:
        return 0.0
    head = par[TAKEOFF] if x < 0 else times[PRE, x]
    if c < 0:
        return head + leg[1][BACK, x] + par[LANDING]
    return head + _cost(x, c, leg) + par[STOP] + times[SUF, c]


@njit(cache=True)
def _reverse(s, e, r, links):  # type: ignore[no-untyped-def]
    """Reverse the stops from ``s`` to ``e`` (``s`` before ``e``) of route ``r``."""
    nxt, prv = links[NXT], links[PRV]
    before = prv[s]
    after = nxt[e]
    a = s
    while True:
        b = nxt[a]
        nxt[a] = prv[a]
        prv[a] = b
        if a == e:
            break
        a = b
    # Now e..s run forwards through the swapped links.
    _join(before, e, r, links)
    _join(s, after, r, links)


@njit(cache=True)
def _join(u, w, r, links):  # type: ignore[no-untyped-def]
    """Make ``w`` follow ``u`` in route ``r`` (-1 for home: ``w`` first, or ``u`` last)."""
    if u >= 0:
        links[NXT, u] = w
    else:
        links[FIRST, r] = w
    if w >= 0:
        links[PRV, w] = u


@njit(cache=True)
def _unlink(a, links):  # type: ignore[no-untyped-def]
    _join(links[PRV, a], links[NXT, a], links[RID, a], links)
    links[NXT, a] = -1
    links[PRV, a] = -1


@njit(cache=True)
def _link(a, u, w, r, links):  # type: ignore[no-untyped-def]
    """Put ``a`` between ``u`` and ``w`` (adjacent in route ``r``; -1 for home)."""
    _join(u, a, r, links)
    _join(a, w, r, links)
    links[RID, a] = r


@njit(cache=True)
def _wake(a, active, stack, top, links):  # type: ignore[no-untyped-def]
    """Mark ``a`` and its route neighbours to be looked at again."""
    for v in (a, links[NXT, a], links[PRV, a]):
        if v >= 0 and not active[v]:
            active[v] = True
            stack[top] = v
            top += 1
    return top


@njit(cache=True)
def _inserted(a, u, w, leg):  # type: ignore[no-untyped-def]
    """What putting stop ``a`` between ``u`` and ``w`` adds to their route's time."""
    return _cost(u, a, leg) + _cost(a, w, leg) + leg[2][STOP] - _cost(u, w, leg)


@njit(cache=True)
def _swap_position(a, j, leg):  # type: ignore[no-untyped-def]
    """Exchange stop ``a``'s position (and its legs from and to home) with alternative
    ``j``."""
    xy, home_s, alt_xy, alt_home = leg[0], leg[1], leg[5], leg[6]
    for c in range(2):
        xy[a, c], alt_xy[j, c] = alt_xy[j, c], xy[a, c]
        home_s[c, a], alt_home[c, j] = alt_home[c, j], home_s[c, a]


@njit(cache=True)
def _replace(a, pa, na, ra, links, times, leg, limit):  # type: ignore[no-untyped-def]
    """Fly ``a`` from the first of its alternative positions that shortens its sortie
    (between ``pa`` and ``na`` of route ``ra``); whether one did."""
    alt_ptr = leg[7]
    now = _cost(pa, a, leg) + _cost(a, na, leg)
    for j in range(alt_ptr[a], alt_ptr[a + 1]):
        _swap_position(a, j, leg)
        then = _cost(pa, a, leg) + _cost(a, na, leg)
        if then < now - _EPS_S and times[RTIME, ra] + then - now <= limit:
            retime(ra, links, times, leg)
            return True
        _swap_position(a, j, leg)
    return False


@njit(cache=True)
def _improve_at(a, near, links, times, leg):  # type: ignore[no-untyped-def]
    """Apply the first move that puts ``a`` next to one of its near stops and shortens the
    total time; return the other stop it touched, or -1 when there is none."""
    nxt, prv, rid, pos = links[NXT], links[PRV], links[RID], links[POS]
    rtime = times[RTIME]
    limit = leg[2][ENDURANCE] + _EPS_S
    ra = rid[a]
    pa = prv[a]
    na = nxt[a]
    # Flying a from another of its positions.
    if _replace(a, pa, na, ra, links, times, leg, limit):
        return a
    # Taking a out saves its place in its sortie, or the whole sortie when it flies alone.
    removed = -rtime[ra] if links[SIZE, ra] == 1 else -_inserted(a, pa, na, leg)
    for j in range(near.shape[1]):
        b = near[a, j]
        if b == a:
            continue  # stops at one position: the tree may list a among its own nearest
        rb = rid[b]
        pb = prv[b]
        nb = nxt[b]
        # Relocate a just after b, or just before it.
        for side in range(2):
            u = b if side == 0 else pb
            w = nb if side == 0 else b
            if u == a or w == a:
                continue
            ins = _inserted(a, u, w, leg)
            # Into another sortie only that one grows; within a sortie both changes count.
            grown = rtime[ra] + removed + ins if ra == rb else rtime[rb] + ins
            if grown <= limit and removed + ins < -_EPS_S:
                _unlink(a, links)
                _link(a, u, w, rb, links)
                retime(ra, links, times, leg)
                if rb != ra:
                    retime(rb, links, times, leg)
                return b
        # Swap a and b (not neighbours in a route).
        if nb != a and na != b:
            da = _cost(pa, b, leg) + _cost(b, na, leg) - _cost(pa, a, leg) - _cost(a, na, leg)
            db = _cost(pb, a, leg) + _cost(a, nb, leg) - _cost(pb, b, leg) - _cost(b, nb, leg)
            if ra == rb:
                ok = rtime[ra] + da + db <= limit
            else:
                ok = rtime[ra] + da <= limit and rtime[rb] + db <= limit
            if ok and da + db < -_EPS_S:
                _link(b, pa, na, ra, links)
                _link(a, pb, nb, rb, links)
                retime(ra, links, times, leg)
                if rb != ra:
                    retime(rb, links, times, leg)
                return b
        if ra != rb:
            # 2-opt*: a's route up to x, then b's from its stop after y; and the other way.
            for side in range(2):
                x = a if side == 0 else pa
                y = pb if side == 0 else b
                ca = nxt[x] if x >= 0 else links[FIRST, ra]
                cb = nxt[y] if y >= 0 else links[FIRST, rb]
                if (x < 0 and y < 0) or (ca < 0 and cb < 0):
                    continue
                ta = _joined(x, cb, times, leg)
                tb = _joined(y, ca, times, leg)
                if ta <= limit and tb <= limit and ta + tb < rtime[ra] + rtime[rb] - _EPS_S:
                    _join(x, cb, ra, links)
                    _join(y, ca, rb, links)
                    retime(ra, links, times, leg)
                    retime(rb, links, times, leg)
                    return b
        else:
            # 2-opt: reverse the stops between them so that a and b become neighbours.
            if pos[a] < pos[b]:
                s, e, before, after = na, b, a, nb
            else:
                s, e, before, after = b, pa, pb, a
            if s != e:
                delta = (
                    _cost(before, e, leg)
                    + _cost(s, after, leg)
                    - _cost(before, s, leg)
                    - _cost(e, after, leg)
                )
                if leg[4].shape[0] > 0:
                    # Given legs need not be the same both ways: the reversed stretch's own
                    # legs change too.
                    x = s
                    while x != e:
                        y = nxt[x]
                        delta += _cost(y, x, leg) - _cost(x, y, leg)
                        x = y
                if delta < -_EPS_S and rtime[ra] + delta <= limit:
                    _reverse(s, e, ra, links)
                    retime(ra, links, times, leg)
                    return b
    return -1


@njit(cache=True)
def local_search(near, active, links, times, leg):  # type: ignore[no-untyped-def]
    """Improving moves until none is left among the active stops (each improvement wakes
    the stops it touched)."""
    k = near.shape[0]
    stack = np.empty(4 * k + 8, dtype=np.int64)
    top = 0
    for a in range(k):
        if active[a]:
            stack[top] = a
            top += 1
    moves = 0
    while top > 0 and moves < _MOVES_PER_STOP * k:
        top -= 1
        a = stack[top]
        active[a] = False
        if links[RID, a] < 0:
            continue
        na, pa = links[NXT, a], links[PRV, a]
        b = _improve_at(a, near, links, times, leg)
        if b < 0:
            continue
        moves += 1
        if top + 12 > stack.shape[0]:
            # Deeper than every stop four times over: wake them all and start again.
            top = 0
            for v in range(k):
                active[v] = True
                stack[top] = v
                top += 1
            continue
        for v in (a, b, na, pa):
            if v >= 0:
                top = _wake(v, active, stack, top, links)


@njit(cache=True)
def _total(links, times):  # type: ignore[no-untyped-def]
    out = 0.0
    for r in range(links.shape[1]):
        if links[SIZE, r] > 0:
            out += times[RTIME, r]
    return out


@njit(cache=True)
def _reinsert(a, near, links, times, leg):  # type: ignore[no-untyped-def]
    """Put stop ``a`` (out of every route) back where it costs least: next to one of its
    near stops, from whichever of its positions, or alone in a sortie of its own."""
    par = leg[2]
    limit = par[ENDURANCE] + _EPS_S
    rid = links[RID]
    best = np.inf
    bu, bw, br, bj = -1, -1, -1, -1
    alt_ptr = leg[7]
    # j: the alternative position tried (-1: where a is now).
    for j in range(alt_ptr[a] - 1, alt_ptr[a + 1]):
        if j >= alt_ptr[a]:
            _swap_position(a, j, leg)
        alone = leg[1][OUT, a] + leg[1][BACK, a] + par[STOP] + par[TAKEOFF] + par[LANDING]
        if alone < best:
            best, bu, bw, br, bj = alone, -1, -1, -1, j
        for i in range(near.shape[1]):
            b = near[a, i]
            rb = rid[b]
            if rb < 0:
                continue
            for side in range(2):
                u = b if side == 0 else links[PRV, b]
                w = links[NXT, b] if side == 0 else b
                ins = _inserted(a, u, w, leg)
                if ins < best and times[RTIME, rb] + ins <= limit:
                    best, bu, bw, br, bj = ins, u, w, rb, j
        if j >= alt_ptr[a]:
            _swap_position(a, j, leg)
    if bj >= alt_ptr[a]:
        _swap_position(a, bj, leg)
    if br < 0:
        for r in range(rid.shape[0]):
            if links[SIZE, r] == 0:
                br = r
                break
    _link(a, bu, bw, br, links)
    retime(br, links, times, leg)


@njit(cache=True)
def ruin_and_recreate(near, rounds, rng, links, times, leg):  # type: ignore[no-untyped-def]
    """Rounds of ruin (a stop and some of its nearest taken out), recreate (each put back
    where it costs least, or alone) and local search; a round is kept when the total time
    falls, and undone otherwise."""
    k = near.shape[0]
    rid = links[RID]
    active = np.zeros(k, dtype=np.bool_)
    taken = np.empty(near.shape[1] + 1, dtype=np.int64)
    for _ in range(rounds):
        before = _total(links, times)
        keep = links.copy()
        kept_at = (leg[0].copy(), leg[1].copy(), leg[5].copy(), leg[6].copy())
        seed_stop = rng.integers(0, k)
        m = 1 + rng.integers(0, min(RUIN_MAX, near.shape[1]))
        taken[0] = seed_stop
        count = 1
        for j in range(m - 1):
            if near[seed_stop, j] != seed_stop:
                taken[count] = near[seed_stop, j]
                count += 1
        touched = np.zeros(k, dtype=np.bool_)
        for j in range(count):
            a = taken[j]
            touched[rid[a]] = True
            _unlink(a, links)
            rid[a] = -1
        for r in range(k):
            if touched[r]:
                retime(r, links, times, leg)
        back = taken[:count].copy()
        rng.shuffle(back)
        for a in back:
            _reinsert(a, near, links, times, leg)
            active[a] = True
        local_search(near, active, links, times, leg)
        if _total(links, times) >= before - _EPS_S:
            links[:] = keep
            leg[0][:] = kept_at[0]
            leg[1][:] = kept_at[1]
            leg[5][:] = kept_at[2]
            leg[6][:] = kept_at[3]
            for r in range(k):
                retime(r, links, times, leg)
