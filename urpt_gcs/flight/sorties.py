"""Sorties: which stops fly in which sortie, and in what order.

The solver minimises one closed tour. When that tour does not fit ``--endurance`` it is cut
into sorties (:func:`urpt_gcs.problem.flight_time.split_sorties`), and the order that is
shortest in one piece is seldom the one that cuts best: each sortie flies out from home and
back. This stage improves what is flown, the total flight time of the sorties, in two steps:

1. the order: from the solver's order, 2-opt and Or-opt moves between stops near each other
   and moves of the tour's ends, each order timed by its optimal cut (the cut-point DP of
   ``split_sorties``, compiled here);
2. the sorties themselves (:func:`urpt_gcs.solvers.sortie_routes.search_routes`), from that
   order's cut: stops moved between sorties, tails exchanged, ruin and recreate.

The stops are the solver's, with their margins and refinement; given alternatives (other
positions that see what a stop must, checked by the caller), the route search may fly a stop
from one of them instead.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.problem.flight_time import FlightModel, Sortie, split_sorties
from urpt_gcs.solvers import Tour
from urpt_gcs.solvers.sortie_routes import RouteSearch, search_routes, warm_up

__all__ = [
    "NEIGHBOURS",
    "ORDER_SHARE",
    "SEARCH_SHARE",
    "SEGMENT_MAX",
    "SortieOrder",
    "order_sorties",
]

# The share of --time-limit the search may spend (on top of the solve), the share of that
# the order search may take before the sorties are searched as routes, and how many of each
# stop's nearest stops the order's moves look at.
SEARCH_SHARE = 0.2
ORDER_SHARE = 0.25
NEIGHBOURS = 8
# Or-opt moves segments of up to this many stops.
SEGMENT_MAX = 3
_EPS_S = 1e-6


@dataclass(frozen=True, slots=True)
class SortieOrder:
    """What the sortie-order search did.

    Attributes
    ----------
    tour_length_m
        The solver's tour in one piece, before the search.
    plain_cut_sorties, plain_cut_length_m, plain_cut_flight_time_s
        The solver's order cut into sorties as it is: how many, and their totals.
    order_flight_time_s
        The searched order's optimal cut, before the route search (total).
    length_m, flight_time_s
        The sorties found, as flown (total).
    moves
        Improving moves of the order accepted.
    routes
        What the route search did.
    search_s
        Time spent searching; at most ``budget_s`` (one move's evaluation more).
    budget_s
        The time the search was given.
    """

    tour_length_m: float
    plain_cut_sorties: int
    plain_cut_length_m: float
    plain_cut_flight_time_s: float
    order_flight_time_s: float
    length_m: float
    flight_time_s: float
    moves: int
    routes: RouteSearch
    search_s: float
    budget_s: float

    def __post_init__(self) -> None:
        if self.flight_time_s > self.plain_cut_flight_time_s + _EPS_S:
            raise ValueError(
                f"sortie search made the flight longer: {self.flight_time_s:.1f} s "
                f"against {self.plain_cut_flight_time_s:.1f} s for the plain cut"
            )


@njit(cache=True)
def _cut_time(out_s, back_s, cum_s, ends_s, endurance_s, best, first):  # type: ignore[no-untyped-def]
    """Least total flight time of sorties over stops in this order, each within
    ``endurance_s`` (as :func:`urpt_gcs.problem.flight_time.split_sorties`); ``best[j]`` is that of
    the first ``j`` stops and is reused up to ``first``, where the order last changed."""
    k = out_s.shape[0]
    for j in range(first + 1, k + 1):
        b = np.inf
        for i in range(j - 1, -1, -1):
            t = out_s[i] + cum_s[j - 1] - cum_s[i] + back_s[j - 1] + ends_s
            if t > endurance_s:
                break  # longer sorties ending at j only get longer
            v = best[i] + t
            if v < b:
                b = v
        best[j] = b
    return best[k]


class _Objective:
    """The total flight time of an order of the stops, cut optimally."""

    def __init__(
        self,
        stops_xy: FloatArray,
        home_xy: tuple[float, float],
        altitude_rel_m: float,
        model: FlightModel,
        endurance_s: float,
    ) -> None:
        self.xy = stops_xy
        to_home = np.hypot(*(stops_xy - np.asarray(home_xy)).T)
        self.out_s = model.leg_s(to_home)
        self.back_s = model.return_s(to_home)
        self.ends_s = (
            model.takeoff_s(altitude_rel_m) + model.stop_s + model.landing_s(altitude_rel_m)
        )
        self.model = model
        self.endurance_s = endurance_s

    def __call__(self, order: IntArray, best: FloatArray, first: int) -> float:
        xy = self.xy[order]
        hops = np.hypot(*np.diff(xy, axis=0).T)
        cum = np.concatenate([[0.0], np.cumsum(self.model.leg_s(hops) + self.model.stop_s)])
        return float(
            _cut_time(
                self.out_s[order],
                self.back_s[order],
                cum,
                self.ends_s,
                self.endurance_s,
                best,
                first,
            )
        )


def _moves(order: IntArray, pos: IntArray, near: IntArray, a: int) -> list[tuple[int, IntArray]]:
    """Orders one move away that put stop ``a`` next to one of its near stops, or at an end
    of the order; each with the first position it changes."""
    k = len(order)
    p = int(pos[a])
    out: list[tuple[int, IntArray]] = []
    for b in near[a]:
        q = int(pos[b])
        if q == p:
            continue
        lo, hi = (p, q) if p < q else (q, p)
        # 2-opt: reverse lo+1 .. hi, so order[lo] and the old order[hi] become neighbours.
        if hi > lo + 1:
            new = order.copy()
            new[lo + 1 : hi + 1] = order[lo + 1 : hi + 1][::-1]
            out.append((lo + 1, new))
        # Or-opt: the segment starting at a, moved to just after b (either way round).
        for s in range(1, SEGMENT_MAX + 1):
            if p + s > k or p <= q < p + s:
                break
            seg = order[p : p + s]
            rest = np.concatenate([order[:p], order[p + s :]])
            at = q + 1 if q < p else q + 1 - s
            for piece in (seg, seg[::-1]) if s > 1 else (seg,):
                new = np.concatenate([rest[:at], piece, rest[at:]])
                out.append((min(p, at), new))
    # The ends: reverse the prefix up to a, or the suffix from a (a becomes the first or
    # the last stop, next to home).
    if p > 0:
        new = order.copy()
        new[: p + 1] = order[: p + 1][::-1]
        out.append((0, new))
    if p < k - 1:
        new = order.copy()
        new[p:] = order[p:][::-1]
        out.append((p, new))
    return out


def order_sorties(
    tour: Tour,
    home_xy: tuple[float, float],
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float | None,
    names: list[str],
    budget_s: float,
    seed: int = 0,
    alternatives: Callable[[], tuple[FloatArray, IntArray] | None] | None = None,
) -> tuple[Tour, SortieOrder | None]:
    """Reorder the tour's stops for the least total flight time once cut into sorties.

    Parameters
    ----------
    tour
        The solver's tour; its stops are reordered, never changed.
    home_xy, altitude_rel_m, model, endurance_s, names
        As for :func:`urpt_gcs.problem.flight_time.split_sorties`.
    budget_s
        Wall time the search may spend.
    seed
        Order in which the stops are visited by the search.
    alternatives
        Gives the other positions each stop may be flown from (see
        :func:`~urpt_gcs.solvers.sortie_routes.search_routes`); called only for a flight of
        several sorties. None: each stop from where it is.

    Returns
    -------
    tuple of Tour and SortieOrder
        The reordered tour (``length`` its closed length in the new order), and what the
        search did; the tour unchanged and None when the flight fits in one sortie.
    """
    assert tour.points_xy is not None
    xy = tour.points_xy
    plain = split_sorties(xy, home_xy, altitude_rel_m, model, endurance_s, names)
    if endurance_s is None or len(plain) == 1:
        return tour, None
    others = None if alternatives is None else alternatives()
    warm_up()  # compiled (or loaded) before the clock starts: the budget is the search's
    start = time.perf_counter()
    k = len(xy)
    objective = _Objective(xy, home_xy, altitude_rel_m, model, endurance_s)
    order = np.arange(k)
    best = np.zeros(k + 1)
    current = objective(order, best, 0)
    trial = best.copy()
    _, idx = cKDTree(xy).query(xy, k=min(NEIGHBOURS + 1, k))
    near = np.asarray(idx).reshape(k, -1)[:, 1:]
    rng = np.random.default_rng(seed)
    moves = 0
    improved = True
    out_of_time = False
    while improved and not out_of_time:
        improved = False
        for a in rng.permutation(k).tolist():
            pos = np.empty(k, dtype=np.int64)
            pos[order] = np.arange(k)
            for first, new in _moves(order, pos, near, a):
                trial[: first + 1] = best[: first + 1]
                value = objective(new, trial, first)
                if value < current - _EPS_S:
                    order, current = new, value
                    best, trial = trial, best
                    moves += 1
                    improved = True
                    break
                if time.perf_counter() - start > ORDER_SHARE * budget_s:
                    out_of_time = True
                    break
            if out_of_time:
                break
    searched = split_sorties(
        xy[order], home_xy, altitude_rel_m, model, endurance_s, [names[i] for i in order.tolist()]
    )
    routes, route_search = search_routes(
        xy,
        home_xy,
        altitude_rel_m,
        model,
        endurance_s,
        [order[s.first : s.stop] for s in searched],
        budget_s - (time.perf_counter() - start),
        seed,
        alternatives=others,
    )
    moved = np.any(route_search.stops_xy != xy, axis=1)
    xy = route_search.stops_xy
    order = np.concatenate(_by_bearing(routes, xy, home_xy))
    cut = split_sorties(
        xy[order], home_xy, altitude_rel_m, model, endurance_s, [names[i] for i in order.tolist()]
    )
    found = SortieOrder(
        tour_length_m=tour.length,
        plain_cut_sorties=len(plain),
        plain_cut_length_m=_total_length(plain),
        plain_cut_flight_time_s=_total_time(plain),
        order_flight_time_s=_total_time(searched),
        length_m=_total_length(cut),
        flight_time_s=_total_time(cut),
        moves=moves,
        routes=route_search,
        search_s=time.perf_counter() - start,
        budget_s=budget_s,
    )
    home = np.asarray(home_xy)
    path = np.vstack([home, xy[order], home])
    length = float(np.hypot(*np.diff(path, axis=0).T).sum())
    reordered = replace(
        tour,
        order=tuple(-1 if moved[i] else tour.order[i] for i in order.tolist()),
        points_xy=xy[order],
        sees=tour.sees[order],
        headings_deg=None if tour.headings_deg is None else tour.headings_deg[order],
        length=length,
        proven_optimal=tour.proven_optimal and length <= tour.length,
        notes=(
            *tour.notes,
            f"stops reordered for sorties: {found.plain_cut_flight_time_s / 60:.1f} -> "
            f"{found.flight_time_s / 60:.1f} min ({found.order_flight_time_s / 60:.1f} min "
            f"after {moves} moves of the order, then {route_search.rounds} rounds over "
            f"{route_search.sorties} sorties)",
        ),
    )
    return reordered, found


def _by_bearing(
    routes: list[IntArray], xy: FloatArray, home_xy: tuple[float, float]
) -> list[IntArray]:
    """The sorties in the order of the bearing from home of their stops' middle, so that the
    operator flies them round the site."""
    home = np.asarray(home_xy)
    angle = [math.atan2(*(xy[r].mean(axis=0) - home)[::-1]) for r in routes]
    return [routes[i] for i in np.argsort(angle, kind="stable").tolist()]


def _total_length(sorties: tuple[Sortie, ...]) -> float:
    return math.fsum(s.length_m for s in sorties)


def _total_time(sorties: tuple[Sortie, ...]) -> float:
    return math.fsum(s.flight_time_s for s in sorties)
