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
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers import _route_kernels as kernels
from urpt_gcs.solvers._route_kernels import RUIN_MAX

__all__ = [
    "LEG_SAMPLES",
    "NEIGHBOURS",
    "RUIN_MAX",
    "RouteSearch",
    "route_times",
    "search_routes",
    "viewpoints_seeing",
    "warm_up",
]

# How many of each stop's nearest stops the moves look at (the stop is put next to one).
NEIGHBOURS = 10
# Samples of the time of a leg too short to reach the cruise speed, from 0 to that length.
LEG_SAMPLES = 1024
# Ruin-and-recreate rounds run between two looks at the clock.
_ROUNDS_PER_CALL = 64


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
        return result(routes, start_total, 0, given_xy)
    links, times, near, leg = _prepare(
        xy, home_xy, altitude_rel_m, model, endurance_s, routes, leg_times, alternatives
    )
    kernels.local_search(near, np.ones(k, dtype=np.bool_), links, times, leg)
    rounds = 0
    rng = np.random.default_rng(seed)
    while time.perf_counter() - start < budget_s:
        kernels.ruin_and_recreate(near, _ROUNDS_PER_CALL, rng, links, times, leg)
        rounds += _ROUNDS_PER_CALL
    found = _routes(links)
    at = leg[0]
    exact = route_times(at, home_xy, altitude_rel_m, model, found, leg_times)
    total = math.fsum(exact.tolist())
    if total >= start_total or float(exact.max()) > endurance_s:
        return result(routes, start_total, rounds, given_xy)
    return result(found, total, rounds, at)


def viewpoints_seeing(
    instance: Instance, stops_xy: FloatArray, sees: np.ndarray, count: int
) -> tuple[FloatArray, IntArray]:
    """For each stop, the ``count`` viewpoints of the instance nearest it (its own position
    aside) that see every target of its row of ``sees``: their positions, and the stop each
    is for (ascending). What they see from around them is the caller's to check."""
    assert instance.points_xy is not None
    covers = instance.covers
    pair_viewpoint = np.repeat(np.arange(len(covers.ptr) - 1), np.diff(covers.ptr))
    by_target = np.argsort(covers.target, kind="stable")
    viewpoints_of = pair_viewpoint[by_target]
    target_ptr = np.searchsorted(covers.target[by_target], np.arange(covers.n_targets + 1))
    found: list[FloatArray] = [np.zeros((0, 2))]
    owner: list[IntArray] = [np.zeros(0, dtype=np.int64)]
    for k, row in enumerate(np.asarray(sees, dtype=bool)):
        targets = np.flatnonzero(row)
        if targets.size == 0:
            continue
        pool = viewpoints_of[target_ptr[targets[0]] : target_ptr[targets[0] + 1]]
        for t in targets[1:].tolist():
            pool = np.intersect1d(pool, viewpoints_of[target_ptr[t] : target_ptr[t + 1]])
        away = np.hypot(*(instance.points_xy[pool] - stops_xy[k]).T)
        pool, away = pool[away > 0.0], away[away > 0.0]
        pick = pool[np.argsort(away, kind="stable")[:count]]
        found.append(instance.points_xy[pick])
        owner.append(np.full(len(pick), k, dtype=np.int64))
    return np.vstack(found), np.concatenate(owner)


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
        kernels.local_search(near, np.ones(6, dtype=np.bool_), links, times, leg)
        kernels.ruin_and_recreate(near, 1, np.random.default_rng(0), links, times, leg)


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
    links[kernels.POS] = 0
    links[kernels.SIZE] = 0
    for r, stops in enumerate(routes):
        order = [int(v) for v in stops]
        links[kernels.FIRST, r] = order[0]
        for a, b in itertools.pairwise(order):
            links[kernels.NXT, a] = b
            links[kernels.PRV, b] = a
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
        kernels.retime(r, links, times, leg)
    return links, times, near, leg


def _routes(links: IntArray) -> list[IntArray]:
    """The non-empty routes, each its stops in flying order."""
    found = []
    for r in np.flatnonzero(links[kernels.SIZE] > 0).tolist():
        stops = []
        a = int(links[kernels.FIRST, r])
        while a >= 0:
            stops.append(a)
            a = int(links[kernels.NXT, a])
        found.append(np.asarray(stops, dtype=np.int64))
    return found
