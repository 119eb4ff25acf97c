"""Sorties as routes: which stops fly in which sortie, and in what order, for the least total
flight time with every sortie within the endurance.

This is the multi-trip routing problem over fixed stops: one home, any number of sorties,
each timed by the :class:`~urpt_gcs.problem.flight_time.FlightModel` (take-off, the legs with
their speed-up and braking, a stop at every point, the leg home at the return speed, the
landing) and each within ``endurance_s``. The search starts from sorties it is given (the
tour's order cut at its best cut points) and never returns worse ones:

- a local search over the routes themselves, each move timed in constant time from every
  stop's time since take-off and time to landing: a stop moved into another sortie or
  elsewhere in its own, two stops swapped, the tails of two sorties exchanged (2-opt*), a
  piece of a sortie reversed (2-opt); each move puts a stop next to one of its nearest stops,
  and only stops whose surroundings changed are looked at again;
- then, while the budget lasts, ruin and recreate: a stop and some of its nearest stops taken
  out and put back where they cost least (or into a sortie of their own), the local search
  run again around them, and the result kept when the total time falls. A whole sortie
  emptied this way saves its take-off and landing.

Level legs between stops are timed from a table of the model's short-leg times (linear
between samples; every leg long enough to reach the cruise speed is timed exactly), and the
routes found timed again exactly by the model before they are returned. A flight that follows
the terrain gives its legs' times instead (``leg_times``: each leg as flown, climbs and
descents included; a pair it does not time is never joined). Either way the routes are given
back unchanged if they are not quicker or any leaves the endurance.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.problem.flight_time import FlightModel

__all__ = [
    "LEG_SAMPLES",
    "NEIGHBOURS",
    "RUIN_MAX",
    "RouteSearch",
    "route_times",
    "search_routes",
    "warm_up",
]

# How many of each stop's nearest stops the moves look at (the stop is put next to one).
NEIGHBOURS = 10
# Samples of the time of a leg too short to reach the cruise speed, from 0 to that length.
LEG_SAMPLES = 1024
# Ruin and recreate takes out one stop and up to this many of its nearest stops.
RUIN_MAX = 10
# Improving moves one local search makes at most, per stop: each shortens the total, so this
# is never reached in practice; it bounds the search if rounding ever let two moves undo
# each other.
_MOVES_PER_STOP = 1000
# Ruin-and-recreate rounds run between two looks at the clock.
_ROUNDS_PER_CALL = 64
_EPS_S = 1e-7

# The scalars the kernels read, by index into one array.
_V, _OVER, _SHORT, _TAKEOFF, _LANDING, _STOP, _ENDURANCE = range(7)
# The rows of the routes' integer state: per stop its next and previous stop (-1 for home),
# its route and place in it; per route its first and last stop and its size.
_NXT, _PRV, _RID, _POS, _FIRST, _LAST, _SIZE = range(7)
# The rows of their times: per route its flight time; per stop the time from take-off to the
# end of its stop, and from leaving it to the landing.
_RTIME, _PRE, _SUF = range(3)
# The rows of each stop's legs from and to home.
_OUT, _BACK = range(2)


@dataclass(frozen=True, slots=True)
class RouteSearch:
    """What the route search did.

    Attributes
    ----------
    start_s
        Total flight time of the sorties it was given.
    flight_time_s
        Total flight time of the sorties it returns (never more than ``start_s``).
    start_sorties, sorties
        How many sorties, before and after.
    rounds
        Ruin-and-recreate rounds run.
    search_s
        Wall time spent.
    stops_xy
        Where each stop is flown from: as given, or the alternative the search chose.
    """

    start_s: float
    flight_time_s: float
    start_sorties: int
    sorties: int
    rounds: int
    search_s: float
    stops_xy: FloatArray


def route_times(
    stops_xy: FloatArray,
    home_xy: tuple[float, float],
    altitude_rel_m: float,
    model: FlightModel,
    routes: list[IntArray],
    leg_times: FloatArray | None = None,
) -> FloatArray:
    """Each route's flight time: exactly as the model times a sortie of level legs through
    those stops, or from ``leg_times`` (see :func:`search_routes`) with the model's take-off,
    stops and landing."""
    out = np.empty(len(routes))
    if leg_times is not None:
        home = len(stops_xy)
        ends = model.takeoff_s(altitude_rel_m) + model.landing_s(altitude_rel_m)
        for r, stops in enumerate(routes):
            visits = [home, *(int(v) for v in stops), home]
            legs = [float(leg_times[a, b]) for a, b in itertools.pairwise(visits)]
            out[r] = ends + math.fsum(legs) + len(stops) * model.stop_s
        return out
    home_xy_arr = np.asarray(home_xy, dtype=np.float64)
    for r, stops in enumerate(routes):
        path = np.vstack([home_xy_arr, stops_xy[stops], home_xy_arr])
        out[r] = model.sortie_s(np.hypot(*np.diff(path, axis=0).T), altitude_rel_m)
    return out


def search_routes(
    stops_xy: FloatArray,
    home_xy: tuple[float, float],
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float,
    routes: list[IntArray],
    budget_s: float,
    seed: int = 0,
    leg_times: FloatArray | None = None,
    alternatives: tuple[FloatArray, IntArray] | None = None,
) -> tuple[list[IntArray], RouteSearch]:
    """Improve sorties over fixed stops for the least total flight time.

    Parameters
    ----------
    stops_xy
        The stops, (k, 2) metres in the planning CRS.
    home_xy, altitude_rel_m, model
        Home, the flight's height above it and the flight model, as for
        :func:`~urpt_gcs.problem.flight_time.split_sorties`.
    endurance_s
        The longest a sortie may take.
    routes
        The sorties to start from, each the indices of its stops in flying order; together
        every stop exactly once, each within the endurance.
    budget_s
        Wall time the search may spend (it stops at its local optimum sooner on small
        instances only when ruin and recreate finds nothing, so it usually takes all of it).
    seed
        Seed of the ruin-and-recreate choices.
    leg_times
        When the legs are not level: (k + 1, k + 1) seconds, row and column ``k`` home, each
        leg's time from rest to rest as flown (its stop aside); inf where a leg is not
        timed. ``altitude_rel_m`` then gives the take-off's and landing's height.
    alternatives
        With level legs: other positions each stop may be flown from (each seeing what
        the stop must see, checked by the caller): ``(xy, ptr)``, stop ``i``'s in
        ``xy[ptr[i]:ptr[i + 1]]``. A move puts a stop at one of them when that shortens its
        sortie.

    Returns
    -------
    tuple of (list of IntArray, RouteSearch)
        The sorties found (each non-empty, in flying order) and what the search did.
    """
    warm_up()
    start = time.perf_counter()
    xy = np.array(stops_xy, dtype=np.float64, order="C")
    k = len(xy)
    start_times = route_times(xy, home_xy, altitude_rel_m, model, routes, leg_times)
    start_total = math.fsum(start_times.tolist())

    def result(
        found: list[IntArray], total: float, rounds: int, at: FloatArray
    ) -> tuple[list[IntArray], RouteSearch]:
        return found, RouteSearch(
            start_s=start_total,
            flight_time_s=total,
            start_sorties=len(routes),
            sorties=len(found),
            rounds=rounds,
            search_s=time.perf_counter() - start,
            stops_xy=at,
        )

    given_xy = xy.copy()
    if k < 2:
        return routes, result(routes, start_total, 0, given_xy)[1]
    links, times, near, leg = _prepare(
        xy, home_xy, altitude_rel_m, model, endurance_s, routes, leg_times, alternatives
    )
    _local_search(near, np.ones(k, dtype=np.bool_), links, times, leg)
    rounds = 0
    rng = np.random.default_rng(seed)
    while time.perf_counter() - start < budget_s:
        _ruin_and_recreate(near, _ROUNDS_PER_CALL, rng, links, times, leg)
        rounds += _ROUNDS_PER_CALL
    found = _routes(links)
    at = leg[0]
    exact = route_times(at, home_xy, altitude_rel_m, model, found, leg_times)
    total = math.fsum(exact.tolist())
    if total >= start_total or float(exact.max()) > endurance_s:
        return result(routes, start_total, rounds, given_xy)
    return result(found, total, rounds, at)


@functools.cache
def warm_up() -> None:
    """Compile the kernels, or load them from numba's cache, on a tiny instance, so that a
    search's budget is spent searching."""
    xy = np.random.default_rng(0).random((6, 2)) * 100.0
    model = FlightModel.arducopter(cruise_m_s=10.0, hold_s=1.0)
    routes = [np.arange(3), np.arange(3, 6)]
    level = _prepare(
        xy, (50.0, 50.0), 30.0, model, 1e6, routes, None, (xy[::-1].copy(), np.arange(7))
    )
    gap = np.hypot(*(np.vstack([xy, [50.0, 50.0]])[:, None] - np.vstack([xy, [50.0, 50.0]])).T)
    timed = _prepare(xy, (50.0, 50.0), 30.0, model, 1e6, routes, model.leg_s(gap))
    for links, times, near, leg in (level, timed):
        _local_search(near, np.ones(6, dtype=np.bool_), links, times, leg)
        _ruin_and_recreate(near, 1, np.random.default_rng(0), links, times, leg)


Legs = tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, IntArray
]


def _prepare(
    xy: FloatArray,
    home_xy: tuple[float, float],
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float,
    routes: list[IntArray],
    leg_times: FloatArray | None = None,
    alternatives: tuple[FloatArray, IntArray] | None = None,
) -> tuple[IntArray, FloatArray, IntArray, Legs]:
    """The routes as the kernels hold them (linked, and timed), each stop's nearest stops,
    and what the kernels time legs with: the stops, their legs from and to home, the
    scalars, the short-leg table, the legs' times between stops when given (else empty),
    and the alternative positions with their legs from and to home (else none)."""
    k = len(xy)
    to_home = np.hypot(*(xy - np.asarray(home_xy, dtype=np.float64)).T)
    short_m, over_s = model.cruise_overhead()
    par = np.array(
        [
            model.cruise_m_s,
            over_s,
            short_m,
            model.takeoff_s(altitude_rel_m),
            model.landing_s(altitude_rel_m),
            model.stop_s,
            endurance_s,
        ]
    )
    table = np.asarray(model.leg_s(np.linspace(0.0, short_m, LEG_SAMPLES)), dtype=np.float64)
    if leg_times is None:
        home_s = np.vstack([model.leg_s(to_home), model.return_s(to_home)]).astype(np.float64)
        _, idx = cKDTree(xy).query(xy, k=min(NEIGHBOURS + 1, k))
        near = np.ascontiguousarray(np.asarray(idx).reshape(k, -1)[:, 1:], dtype=np.int64)
        dense = np.zeros((0, 0))
    else:
        home_s = np.ascontiguousarray(np.vstack([leg_times[k, :k], leg_times[:k, k]]))
        dense = np.ascontiguousarray(leg_times[:k, :k], dtype=np.float64)
        # The quickest legs out of each stop (itself last: its own entry is taken as inf).
        own = dense.copy()
        np.fill_diagonal(own, np.inf)
        near = np.ascontiguousarray(
            np.argsort(own, axis=1, kind="stable")[:, : min(NEIGHBOURS, k - 1)], dtype=np.int64
        )
    links = np.full((7, k), -1, dtype=np.int64)
    links[_POS] = 0
    links[_SIZE] = 0
    for r, stops in enumerate(routes):
        order = [int(v) for v in stops]
        links[_FIRST, r] = order[0]
        for a, b in itertools.pairwise(order):
            links[_NXT, a] = b
            links[_PRV, b] = a
    times = np.zeros((3, k))
    if alternatives is None or leg_times is not None:
        alt_xy, alt_ptr = np.zeros((0, 2)), np.zeros(k + 1, dtype=np.int64)
    else:
        alt_xy = np.array(alternatives[0], dtype=np.float64, order="C").reshape(-1, 2)
        alt_ptr = np.ascontiguousarray(alternatives[1], dtype=np.int64)
    alt_away = np.hypot(*(alt_xy - np.asarray(home_xy, dtype=np.float64)).T)
    alt_home = np.vstack([model.leg_s(alt_away), model.return_s(alt_away)]).astype(np.float64)
    alt_home = np.ascontiguousarray(alt_home.reshape(2, -1))
    leg = (xy, home_s, par, table, dense, alt_xy, alt_home, alt_ptr)
    for r in range(len(routes)):
        _retime(r, links, times, leg)
    return links, times, near, leg


def _routes(links: IntArray) -> list[IntArray]:
    """The non-empty routes, each its stops in flying order."""
    found = []
    for r in np.flatnonzero(links[_SIZE] > 0).tolist():
        stops = []
        a = int(links[_FIRST, r])
        while a >= 0:
            stops.append(a)
            a = int(links[_NXT, a])
        found.append(np.asarray(stops, dtype=np.int64))
    return found


@njit(cache=True)
def _cost(x, y, leg):  # type: ignore[no-untyped-def]
    """Time of the leg from ``x`` to ``y`` (-1 is home: out at the cruise speed, back at the
    return speed)."""
    xy, home_s, par, table, dense = leg[0], leg[1], leg[2], leg[3], leg[4]
    if x < 0:
        return home_s[_OUT, y]
    if y < 0:
        return home_s[_BACK, x]
    if dense.shape[0] > 0:
        return dense[x, y]
    d = math.hypot(xy[x, 0] - xy[y, 0], xy[x, 1] - xy[y, 1])
    short = par[_SHORT]
    if d >= short:
        return d / par[_V] + par[_OVER]
    n = table.shape[0]
    f = d / short * (n - 1)
    i = int(f)
    if i >= n - 1:
        return table[n - 1]
    f -= i
    return table[i] + f * (table[i + 1] - table[i])


@njit(cache=True)
def _retime(r, links, times, leg):  # type: ignore[no-untyped-def]
    """Walk route ``r`` from its first stop: its stops' route, place and times, and its last
    stop, size and time."""
    nxt, prv = links[_NXT], links[_PRV]
    pre, suf = times[_PRE], times[_SUF]
    par = leg[2]
    a = links[_FIRST, r]
    if a < 0:
        links[_SIZE, r] = 0
        links[_LAST, r] = -1
        times[_RTIME, r] = 0.0
        return
    t = par[_TAKEOFF]
    x = -1
    n = 0
    while a >= 0:
        t += _cost(x, a, leg) + par[_STOP]
        pre[a] = t
        links[_RID, a] = r
        links[_POS, a] = n
        n += 1
        x = a
        a = nxt[a]
    links[_LAST, r] = x
    links[_SIZE, r] = n
    s = leg[1][_BACK, x] + par[_LANDING]
    suf[x] = s
    a = x
    while prv[a] >= 0:
        p = prv[a]
        s += par[_STOP] + _cost(p, a, leg)
        suf[p] = s
        a = p
    times[_RTIME, r] = pre[x] + suf[x]


@njit(cache=True)
def _joined(x, c, times, leg):  # type: ignore[no-untyped-def]
    """Time of a route made of one route's stops up to ``x`` and another's from ``c`` on
    (-1: none of that route)."""
    par = leg[2]
    if x < 0 and c < 0:
        return 0.0
    head = par[_TAKEOFF] if x < 0 else times[_PRE, x]
    if c < 0:
        return head + leg[1][_BACK, x] + par[_LANDING]
    return head + _cost(x, c, leg) + par[_STOP] + times[_SUF, c]


@njit(cache=True)
def _reverse(s, e, r, links):  # type: ignore[no-untyped-def]
    """Reverse the stops from ``s`` to ``e`` (``s`` before ``e``) of route ``r``."""
    nxt, prv = links[_NXT], links[_PRV]
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
        links[_NXT, u] = w
    else:
        links[_FIRST, r] = w
    if w >= 0:
        links[_PRV, w] = u


@njit(cache=True)
def _unlink(a, links):  # type: ignore[no-untyped-def]
    _join(links[_PRV, a], links[_NXT, a], links[_RID, a], links)
    links[_NXT, a] = -1
    links[_PRV, a] = -1


@njit(cache=True)
def _link(a, u, w, r, links):  # type: ignore[no-untyped-def]
    """Put ``a`` between ``u`` and ``w`` (adjacent in route ``r``; -1 for home)."""
    _join(u, a, r, links)
    _join(a, w, r, links)
    links[_RID, a] = r


@njit(cache=True)
def _wake(a, active, stack, top, links):  # type: ignore[no-untyped-def]
    """Mark ``a`` and its route neighbours to be looked at again."""
    for v in (a, links[_NXT, a], links[_PRV, a]):
        if v >= 0 and not active[v]:
            active[v] = True
            stack[top] = v
            top += 1
    return top


@njit(cache=True)
def _inserted(a, u, w, leg):  # type: ignore[no-untyped-def]
    """What putting stop ``a`` between ``u`` and ``w`` adds to their route's time."""
    return _cost(u, a, leg) + _cost(a, w, leg) + leg[2][_STOP] - _cost(u, w, leg)


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
        if then < now - _EPS_S and times[_RTIME, ra] + then - now <= limit:
            _retime(ra, links, times, leg)
            return True
        _swap_position(a, j, leg)
    return False


@njit(cache=True)
def _improve_at(a, near, links, times, leg):  # type: ignore[no-untyped-def]
    """Apply the first move that puts ``a`` next to one of its near stops and shortens the
    total time; return the other stop it touched, or -1 when there is none."""
    nxt, prv, rid, pos = links[_NXT], links[_PRV], links[_RID], links[_POS]
    rtime = times[_RTIME]
    limit = leg[2][_ENDURANCE] + _EPS_S
    ra = rid[a]
    pa = prv[a]
    na = nxt[a]
    # Flying a from another of its positions.
    if _replace(a, pa, na, ra, links, times, leg, limit):
        return a
    # Taking a out saves its place in its sortie, or the whole sortie when it flies alone.
    removed = -rtime[ra] if links[_SIZE, ra] == 1 else -_inserted(a, pa, na, leg)
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
                _retime(ra, links, times, leg)
                if rb != ra:
                    _retime(rb, links, times, leg)
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
                _retime(ra, links, times, leg)
                if rb != ra:
                    _retime(rb, links, times, leg)
                return b
        if ra != rb:
            # 2-opt*: a's route up to x, then b's from its stop after y; and the other way.
            for side in range(2):
                x = a if side == 0 else pa
                y = pb if side == 0 else b
                ca = nxt[x] if x >= 0 else links[_FIRST, ra]
                cb = nxt[y] if y >= 0 else links[_FIRST, rb]
                if (x < 0 and y < 0) or (ca < 0 and cb < 0):
                    continue
                ta = _joined(x, cb, times, leg)
                tb = _joined(y, ca, times, leg)
                if ta <= limit and tb <= limit and ta + tb < rtime[ra] + rtime[rb] - _EPS_S:
                    _join(x, cb, ra, links)
                    _join(y, ca, rb, links)
                    _retime(ra, links, times, leg)
                    _retime(rb, links, times, leg)
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
                    _retime(ra, links, times, leg)
                    return b
    return -1


@njit(cache=True)
def _local_search(near, active, links, times, leg):  # type: ignore[no-untyped-def]
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
        if links[_RID, a] < 0:
            continue
        na, pa = links[_NXT, a], links[_PRV, a]
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
        if links[_SIZE, r] > 0:
            out += times[_RTIME, r]
    return out


@njit(cache=True)
def _reinsert(a, near, links, times, leg):  # type: ignore[no-untyped-def]
    """Put stop ``a`` (out of every route) back where it costs least: next to one of its
    near stops, from whichever of its positions, or alone in a sortie of its own."""
    par = leg[2]
    limit = par[_ENDURANCE] + _EPS_S
    rid = links[_RID]
    best = np.inf
    bu, bw, br, bj = -1, -1, -1, -1
    alt_ptr = leg[7]
    # j: the alternative position tried (-1: where a is now).
    for j in range(alt_ptr[a] - 1, alt_ptr[a + 1]):
        if j >= alt_ptr[a]:
            _swap_position(a, j, leg)
        alone = leg[1][_OUT, a] + leg[1][_BACK, a] + par[_STOP] + par[_TAKEOFF] + par[_LANDING]
        if alone < best:
            best, bu, bw, br, bj = alone, -1, -1, -1, j
        for i in range(near.shape[1]):
            b = near[a, i]
            rb = rid[b]
            if rb < 0:
                continue
            for side in range(2):
                u = b if side == 0 else links[_PRV, b]
                w = links[_NXT, b] if side == 0 else b
                ins = _inserted(a, u, w, leg)
                if ins < best and times[_RTIME, rb] + ins <= limit:
                    best, bu, bw, br, bj = ins, u, w, rb, j
        if j >= alt_ptr[a]:
            _swap_position(a, j, leg)
    if bj >= alt_ptr[a]:
        _swap_position(a, bj, leg)
    if br < 0:
        for r in range(rid.shape[0]):
            if links[_SIZE, r] == 0:
                br = r
                break
    _link(a, bu, bw, br, links)
    _retime(br, links, times, leg)


@njit(cache=True)
def _ruin_and_recreate(near, rounds, rng, links, times, leg):  # type: ignore[no-untyped-def]
    """Rounds of ruin (a stop and some of its nearest taken out), recreate (each put back
    where it costs least, or alone) and local search; a round is kept when the total time
    falls, and undone otherwise."""
    k = near.shape[0]
    rid = links[_RID]
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
                _retime(r, links, times, leg)
        back = taken[:count].copy()
        rng.shuffle(back)
        for a in back:
            _reinsert(a, near, links, times, leg)
            active[a] = True
        _local_search(near, active, links, times, leg)
        if _total(links, times) >= before - _EPS_S:
            links[:] = keep
            leg[0][:] = kept_at[0]
            leg[1][:] = kept_at[1]
            leg[5][:] = kept_at[2]
            leg[6][:] = kept_at[3]
            for r in range(k):
                _retime(r, links, times, leg)
