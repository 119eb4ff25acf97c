"""A fleet: K closed tours from their homes that between them see every target, the longest
flight (the makespan) as short as it can be made (its lower bound is
:mod:`urpt_gcs.solvers.fleet_bound`'s).

Each vehicle has its own instance (its layer's viewpoints and cover sets, its home as the
depot) and its own flight model; a tour's time is the single-vehicle estimate, its stops cut
into sorties within the vehicle's endurance where needed. The search starts from the naive
split (:mod:`urpt_gcs.solvers.fleet_split`: the single-vehicle tour cut into K contiguous
pieces of balanced time, each re-solved on its vehicle's layer) and then moves stops off the
vehicle that lands last: a stop is taken out, the targets only it saw are put on another
vehicle (the cheapest insertion of a viewpoint of that vehicle's layer seeing each), and the
move is kept when both new flights are shorter than the old longest one. When no move helps,
every vehicle's GTSP is re-solved on its targets (the ordinary solvers, a short budget each);
if that shortens any flight, the moves go on. Every value compared is the time of a real
tour over the vehicles' own candidates. A vehicle may be given a start delay (its offset):
its flight then ends that much later, and the makespan the search shortens, like the naive
split it starts from, counts it.

A vehicle whose every share would only land the fleet later (far slower than the others, or
too short an endurance to reach the targets) is left idle: the fleet never lands later than
the one of its vehicles that flies the single tour alone the soonest. Only a target that no
vehicle can reach within its endurance makes the fleet infeasible.

Nothing here sees a raster: only instances, points, distances and the flight model.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray, IntArray, unique_ints
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.problem.instance import Covers, Geometry, Instance
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.fleet_split import (
    Vehicle,
    naive_split,
    reach_split,
    reachable,
    refuse_unreachable,
    unreachable,
)
from urpt_gcs.solvers.registry import choose, prepare, solve

__all__ = [
    "SINGLE_SHARE",
    "FleetTours",
    "Vehicle",
    "naive_split",
    "naive_tours",
    "reachable",
    "refuse_unreachable",
    "restrict",
    "solve_fleet",
    "unreachable",
    "with_home",
]

# A move must shorten the flights it changes by this much to be kept.
_EPS_S = 1e-6
# Share of the time limit the single-vehicle tour may take; the rest goes to the fleet search.
SINGLE_SHARE = 0.4
# Where else the single tour is cut open for the search's start (shares of its stops), and
# the share of the search's time that may go to it.
_ROTATIONS = (1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6)
_ROTATION_SHARE = 0.25
# How many of the best cuts the search descends from, within this share of its time.
_STARTS = 3
_STARTS_SHARE = 0.6
# Budget of one vehicle's GTSP re-solve within the search, seconds.
_RESOLVE_S = 0.3


@dataclass(frozen=True, slots=True)
class FleetTours:
    """The fleet's tours: per vehicle, viewpoints of its own instance in flight order, the
    targets it is counted for and its flight time (none and 0 for a vehicle left idle).
    ``naive_times_s`` are the naive split's pieces flown as cut (on the reference instance's
    viewpoints; where no cut fits, the start :func:`reach_split` gave), ``start_times_s``
    the same pieces re-solved on each vehicle's own layer, where the search starts."""

    orders: tuple[tuple[int, ...], ...]
    targets: tuple[tuple[int, ...], ...]
    times_s: tuple[float, ...]
    naive_times_s: tuple[float, ...]
    start_times_s: tuple[float, ...]
    moves: int
    resolves: int
    search_s: float
    offsets_s: tuple[float, ...] = ()

    @property
    def idle(self) -> tuple[int, ...]:
        """The vehicles (from 0) given nothing to fly."""
        return tuple(k for k, order in enumerate(self.orders) if not order)

    @property
    def makespan_s(self) -> float:
        """When the last vehicle lands, its start delay included."""
        return _last_landing_s(self.offsets_s or None, self.times_s)

    @property
    def naive_makespan_s(self) -> float:
        """The same for the naive split, with the same start delays."""
        return _last_landing_s(self.offsets_s or None, self.naive_times_s)


def _last_landing_s(offsets_s: Sequence[float] | None, times_s: Sequence[float]) -> float:
    """When the last of flights of these times lands, each started after its offset (none:
    all at once); a vehicle with no flight (time 0, idle) does not take off."""
    offsets = offsets_s if offsets_s is not None else [0.0] * len(times_s)
    return max((o + t for o, t in zip(offsets, times_s, strict=True) if t > 0.0), default=0.0)


def restrict(instance: Instance, targets: Sequence[int]) -> tuple[Instance, IntArray]:
    """The instance over ``targets`` only (renumbered 0..len-1 in the given order), and the
    original index of each viewpoint it keeps (those that see one of them)."""
    keep_t = np.asarray(targets, dtype=np.int64)
    if keep_t.size == 0:
        raise ValueError("restrict needs at least one target")
    new_of = np.full(instance.n_targets, -1, dtype=np.int64)
    new_of[keep_t] = np.arange(keep_t.size)
    vp, tg = instance.covers.pairs()
    mask = new_of[tg] >= 0
    kept = unique_ints(vp[mask])
    vp_new = np.searchsorted(kept, vp[mask])
    covers = Covers.from_pairs(vp_new, new_of[tg[mask]], kept.size, keep_t.size)
    g = instance.geometry
    geometry = (
        None
        if g is None
        else Geometry(
            targets_xy=g.targets_xy[keep_t],
            ground_m=g.ground_m[keep_t],
            altitude_m=g.altitude_m,
            fov_deg=g.fov_deg,
            terrain_max_m=g.terrain_max_m,
        )
    )
    oracle = instance.oracle
    sub_oracle = None
    if oracle is not None:

        def sub_oracle(points_xy: FloatArray) -> npt.NDArray[np.bool_]:
            assert oracle is not None
            return oracle(points_xy)[:, keep_t]

    depot_distance = None if instance.depot_distance is None else instance.depot_distance[:, kept]
    owner = None if instance.owner is None else new_of[instance.owner[kept]]
    sub = Instance(
        covers=covers,
        distance=None if instance.distance is None else instance.distance[np.ix_(kept, kept)],
        depot_distance=depot_distance,
        points_xy=None if instance.points_xy is None else instance.points_xy[kept],
        depot_xy=instance.depot_xy,
        owner=owner,
        geometry=geometry,
        oracle=sub_oracle,
        name=instance.name,
        heading_deg=None if instance.heading_deg is None else instance.heading_deg[kept],
    )
    return sub, kept


def with_home(instance: Instance, home_xy: tuple[float, float]) -> Instance:
    """The same viewpoints with another depot (a vehicle of the same layer at another home)."""
    assert instance.points_xy is not None
    pts = instance.points_xy
    to_home = np.hypot(pts[:, 0] - home_xy[0], pts[:, 1] - home_xy[1])
    return Instance(
        covers=instance.covers,
        depot_distance=np.vstack([to_home, to_home]),
        points_xy=pts,
        depot_xy=(float(home_xy[0]), float(home_xy[1])),
        owner=instance.owner,
        geometry=instance.geometry,
        oracle=instance.oracle,
        name=instance.name,
        heading_deg=instance.heading_deg,
    )


class _Route:
    """One vehicle's stops (viewpoints of its instance, in flight order) and its time."""

    def __init__(self, vehicle: Vehicle, order: list[int], offset_s: float = 0.0) -> None:
        self.vehicle = vehicle
        inst = vehicle.instance
        assert inst.points_xy is not None
        self.points = inst.points_xy
        self.order = order
        self.offset_s = offset_s
        self.time_s = vehicle.time_s(self.points[order])

    @property
    def finish_s(self) -> float:
        """When it lands, from the first take-off: its start delay and its flight (0 for a
        vehicle left idle)."""
        return self.offset_s + self.time_s if self.order else 0.0

    def seen(self) -> npt.NDArray[np.bool_]:
        return self.vehicle.instance.covers.seen(self.order)


def _viewpoints_by_target(instance: Instance) -> list[IntArray]:
    vp, tg = instance.covers.pairs()
    by = np.argsort(tg, kind="stable")
    bounds = np.searchsorted(tg[by], np.arange(instance.n_targets + 1))
    return [vp[by[bounds[t] : bounds[t + 1]]] for t in range(instance.n_targets)]


def _insert(route: _Route, order: list[int], candidates: IntArray) -> list[int]:
    """``order`` with the candidate of least added distance at its cheapest place."""
    home = np.asarray(route.vehicle.home_xy)
    path = np.vstack([home, route.points[order], home]) if order else np.vstack([home, home])
    a, b = path[:-1], path[1:]
    c = route.points[candidates]
    ab = np.hypot(*(b - a).T)
    ac = np.hypot(c[:, None, 0] - a[None, :, 0], c[:, None, 1] - a[None, :, 1])
    cb = np.hypot(c[:, None, 0] - b[None, :, 0], c[:, None, 1] - b[None, :, 1])
    added = ac + cb - ab[None, :]
    i, pos = np.unravel_index(int(np.argmin(added)), added.shape)
    return [*order[:pos], int(candidates[i]), *order[pos:]]


def solve_fleet(
    vehicles: Sequence[Vehicle],
    single_order: Sequence[int],
    reference: Instance,
    solver: str,
    settings: SolveSettings,
    offsets_s: Sequence[float] | None = None,
) -> FleetTours:
    """Tours for the fleet of least makespan found within ``settings.time_limit_s``.

    Parameters
    ----------
    vehicles
        The fleet; every instance covers the same targets, in the same numbering.
    single_order
        The single-vehicle tour (viewpoints of ``reference``), the start of the search.
    reference
        The instance the single-vehicle tour was solved on.
    solver
        The GTSP solver for each vehicle's re-solve (any that returns instance viewpoints;
        ``auto`` picks per vehicle).
    settings
        The search's time limit and seed.
    offsets_s
        Each vehicle's start delay, counted in the makespan (None: all start at once).
    """
    started = time.perf_counter()
    deadline = started + settings.time_limit_s
    offsets = [0.0] * len(vehicles) if offsets_s is None else [float(o) for o in offsets_s]
    if len(offsets) != len(vehicles):
        raise ValueError("solve_fleet needs one offset per vehicle")

    def finish(times: Sequence[float]) -> float:
        return _last_landing_s(offsets, times)

    refuse_unreachable(vehicles)
    by_target = [_viewpoints_by_target(v.instance) for v in vehicles]
    # The tour is a cycle: it is cut open at a few other stops too; the search descends from
    # the best few cuts in turn and goes on from the best it reaches. A start is, per
    # vehicle, its targets and its stops on its own viewpoints.
    order = list(single_order)
    starts: list[tuple[float, list[list[int]], list[list[int]]]] = []
    naive_times: list[float] | None = None
    for r in (0.0, *_ROTATIONS) if len(vehicles) > 1 else (0.0,):
        if r and time.perf_counter() - started > _ROTATION_SHARE * settings.time_limit_s:
            break
        shift = int(r * len(order))
        if r and shift == 0:
            continue
        try:
            pieces, times, cut = naive_split(
                vehicles, order[shift:] + order[:shift], reference, offsets
            )
        except SettingsError:
            continue  # no cut from there fits every endurance
        naive_times = times if naive_times is None else naive_times
        own = [
            _carried(v, c, reference, by_target[k])
            for k, (v, c) in enumerate(zip(vehicles, cut, strict=True))
        ]
        starts.append((finish(times), pieces, own))
    if not starts:
        # No cut of the tour fits, yet the vehicles between them reach every target.
        own = reach_split(vehicles, _first_seen(reference, order), offsets)
        reached = [
            _Route(v, o, offsets[k]) for k, (v, o) in enumerate(zip(vehicles, own, strict=True))
        ]
        owners = _owners(reached)
        pieces = [[int(t) for t in np.flatnonzero(owners == k)] for k in range(len(reached))]
        naive_times = [r.time_s for r in reached]
        starts.append((finish(naive_times), pieces, own))
    assert naive_times is not None
    starts.sort(key=lambda c: c[0])
    resolves = 0

    def resolve(k: int, targets: list[int], budget_s: float) -> list[int]:
        nonlocal resolves
        resolves += 1
        sub, kept = restrict(vehicles[k].instance, targets)
        name = choose(sub, solver)
        prepare(name)
        tour = solve(sub, name, dataclasses.replace(settings, time_limit_s=budget_s))
        if any(v < 0 for v in tour.order):
            raise SettingsError.about(
                "{solver} {value} places its own stops, which a fleet cannot share out: "
                "use {solver} auto, exact, heuristic or ortools",
                value=solver,
            )
        return [int(kept[v]) for v in tour.order]

    budget = max(0.05, min(_RESOLVE_S, settings.time_limit_s / (4 * len(vehicles))))

    def begin(pieces: list[list[int]], own: list[list[int]]) -> list[_Route]:
        routes = []
        for k, vehicle in enumerate(vehicles):
            route = _Route(vehicle, resolve(k, pieces[k], budget) if pieces[k] else [], offsets[k])
            # The piece as cut, on the vehicle's own viewpoints, if that is quicker: the
            # solvers shorten the length, not the time with its stops, and have little time.
            if own[k]:
                as_cut = _Route(vehicle, own[k], offsets[k])
                if as_cut.time_s < route.time_s:
                    route = as_cut
            routes.append(route)
        return routes

    def descend(routes: list[_Route], until: float, long_round: bool) -> tuple[int, bool]:
        """Moves and re-solves, longest flight first, until neither helps (or ``until``);
        a long round instead shares the time left out over one re-solve of each."""
        moves, improved_any = 0, False
        while time.perf_counter() < until:
            moved = 0 if long_round else _move_stops(routes, by_target, until)
            moves += moved
            improved = False
            turn = sorted(range(len(routes)), key=lambda k: -routes[k].finish_s)
            for n, k in enumerate(turn):
                left = until - time.perf_counter()
                if left <= 0.0:
                    break
                mine = _own_targets(routes, k)
                if not mine:
                    continue
                spend = max(budget, left / (len(turn) - n)) if long_round else budget
                found = resolve(k, mine, spend)
                t = routes[k].vehicle.time_s(routes[k].points[found])
                if t < routes[k].time_s - _EPS_S:
                    routes[k].order, routes[k].time_s = found, t
                    improved = True
            improved_any |= improved or moved > 0
            if long_round or not (improved or moved):
                break
        return moves, improved_any

    starts = starts[:_STARTS]
    short_until = started + _STARTS_SHARE * settings.time_limit_s
    routes: list[_Route] = []
    start_times: tuple[float, ...] = ()
    moves = 0
    for n, (_, pieces_n, own_n) in enumerate(starts):
        now = time.perf_counter()
        if n > 0 and now >= short_until:
            break
        trial = begin(pieces_n, own_n)
        if n == 0:
            start_times = tuple(r.time_s for r in trial)
        until = now + max(short_until - now, 0.0) / (len(starts) - n)
        moved, _ = descend(trial, max(until, now + budget), long_round=False)
        moves += moved
        if not routes or max(r.finish_s for r in trial) < max(r.finish_s for r in routes):
            routes = trial
    # The time left: a long round of re-solves, then moves again while they help.
    while time.perf_counter() < deadline:
        _, improved = descend(routes, deadline, long_round=True)
        if not improved:
            break
        moved, _ = descend(routes, deadline, long_round=False)
        moves += moved
    routes = _no_later_than_alone(routes, order, reference, by_target)
    return _tours(routes, naive_times, start_times, moves, resolves, started, offsets)


def _tours(
    routes: list[_Route],
    naive_times: Sequence[float],
    start_times: Sequence[float],
    moves: int,
    resolves: int,
    started: float,
    offsets: Sequence[float],
) -> FleetTours:
    """The routes as the fleet's tours, each target counted for one vehicle."""
    owners = _owners(routes)
    return FleetTours(
        orders=tuple(tuple(r.order) for r in routes),
        targets=tuple(
            tuple(int(t) for t in np.flatnonzero(owners == k)) for k in range(len(routes))
        ),
        times_s=tuple(r.time_s for r in routes),
        naive_times_s=tuple(naive_times),
        start_times_s=tuple(start_times),
        moves=moves,
        resolves=resolves,
        search_s=time.perf_counter() - started,
        offsets_s=tuple(offsets),
    )


def naive_tours(
    vehicles: Sequence[Vehicle],
    single_order: Sequence[int],
    reference: Instance,
    offsets_s: Sequence[float] | None = None,
) -> FleetTours:
    """The naive split itself as the fleet's tours: the single-vehicle tour cut into K
    contiguous pieces of earliest last landing (:func:`naive_split`, the start delays
    counted), each piece carried onto its vehicle's own viewpoints and flown in the cut's
    order, nothing searched.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        No cut of this tour fits every vehicle's endurance.
    """
    offsets = [0.0] * len(vehicles) if offsets_s is None else [float(o) for o in offsets_s]
    started = time.perf_counter()
    _, times, cut = naive_split(vehicles, single_order, reference, offsets)
    routes = [
        _Route(v, _carried(v, c, reference, _viewpoints_by_target(v.instance)), offsets[k])
        for k, (v, c) in enumerate(zip(vehicles, cut, strict=True))
    ]
    return _tours(routes, times, [r.time_s for r in routes], 0, 0, started, offsets)


def _no_later_than_alone(
    routes: list[_Route], single: list[int], reference: Instance, near: list[list[IntArray]]
) -> list[_Route]:
    """``routes``, or the single tour flown by the one vehicle that lands it earliest (the
    others idle) if that lands sooner than the last of ``routes``."""
    alone = [
        _Route(r.vehicle, _carried(r.vehicle, single, reference, near[k]), r.offset_s)
        for k, r in enumerate(routes)
    ]
    k = min(range(len(alone)), key=lambda k: alone[k].finish_s)
    if alone[k].finish_s >= max(r.finish_s for r in routes) - _EPS_S:
        return routes
    return [alone[k] if j == k else _Route(r.vehicle, [], r.offset_s) for j, r in enumerate(routes)]


def _first_seen(reference: Instance, order: list[int]) -> list[int]:
    """The targets in the order the tour first sees them."""
    first = np.argmax(reference.covers.dense(order), axis=0)
    return [int(t) for t in np.argsort(first, kind="stable")]


def _carried(
    vehicle: Vehicle, stops: list[int], reference: Instance, near: list[IntArray]
) -> list[int]:
    """Stops of ``reference`` in flight order carried onto the vehicle's own viewpoints:
    for each target a stop sees that the route does not yet, the vehicle's viewpoint of that
    target nearest the stop (the stops themselves where the instances are the same)."""
    if vehicle.instance.points_xy is reference.points_xy:
        return list(stops)
    inst = vehicle.instance
    assert inst.points_xy is not None and reference.points_xy is not None
    covers = reference.covers
    order: list[int] = []
    have = np.zeros(inst.n_targets, dtype=bool)
    for stop in stops:
        at = reference.points_xy[stop]
        for t in covers.target[covers.ptr[stop] : covers.ptr[stop + 1]].tolist():
            if have[t]:
                continue
            options = near[t]
            d = np.hypot(*(inst.points_xy[options] - at).T)
            v = int(options[int(np.argmin(d))])
            order.append(v)
            have |= inst.covers.seen([v])
    return order


def _owners(routes: list[_Route]) -> IntArray:
    """Which vehicle each target is counted for: the first whose stops see it, except that
    a vehicle left with none takes one it sees from a vehicle that has several."""
    seen = np.vstack([r.seen() for r in routes])
    if not seen.any(axis=0).all():
        raise PlanError("internal check failed: the fleet's tours miss a target; report this")
    owners: IntArray = np.argmax(seen, axis=0).astype(np.int64)
    for k in range(len(routes)):
        counts = np.bincount(owners, minlength=len(routes))
        if counts[k] == 0:
            spare = np.flatnonzero(seen[k] & (counts[owners] > 1))
            if spare.size:
                owners[spare[0]] = k
    return owners


def _own_targets(routes: list[_Route], k: int) -> list[int]:
    return [int(t) for t in np.flatnonzero(_owners(routes) == k)]


# Stops of another vehicle nearest a stop of the last to land, tried for a swap with it.
_SWAP_NEAREST = 6


def _lost(route: _Route, stop: int, rest: list[int], elsewhere: npt.NDArray[np.bool_]) -> list[int]:
    """The targets ``stop`` sees that neither ``rest`` nor ``elsewhere`` does."""
    covers = route.vehicle.instance.covers
    left = covers.seen(rest) | elsewhere
    return [int(t) for t in covers.target[covers.ptr[stop] : covers.ptr[stop + 1]] if not left[t]]


def _taking(route: _Route, order: list[int], targets: list[int], near: list[IntArray]) -> list[int]:
    """``order`` with a viewpoint inserted, at least added distance, for each target it does
    not see yet."""
    covers = route.vehicle.instance.covers
    have = covers.seen(order)
    for t in targets:
        if not have[t]:
            order = _insert(route, order, near[t])
            have = covers.seen(order)
    return order


def _seen_except(routes: list[_Route], skip: set[int]) -> npt.NDArray[np.bool_]:
    out = np.zeros(routes[0].vehicle.instance.n_targets, dtype=bool)
    for k, r in enumerate(routes):
        if k not in skip:
            out |= r.seen()
    return out


def _move_stops(routes: list[_Route], by_target: list[list[IntArray]], deadline: float) -> int:
    """Move a stop off the vehicle that lands last, or swap one of its stops with a nearby
    stop of another vehicle, while that shortens it without making the other's flight as
    long; the number of moves made. A vehicle whose last stop moves is left idle."""
    moves = 0
    while time.perf_counter() < deadline:
        c = int(np.argmax([r.finish_s for r in routes]))
        worst, critical = routes[c].finish_s, routes[c]
        best: tuple[float, int, list[int], list[int]] | None = None
        for i, stop in enumerate(critical.order):
            rest = critical.order[:i] + critical.order[i + 1 :]
            rest_s = (
                critical.offset_s + critical.vehicle.time_s(critical.points[rest]) if rest else 0.0
            )
            if rest_s >= worst - _EPS_S:
                continue
            lost = _lost(critical, stop, rest, _seen_except(routes, {c}))
            for j, other in enumerate(routes):
                if j == c:
                    continue
                order = _taking(other, list(other.order), lost, by_target[j])
                value = max(rest_s, other.offset_s + other.vehicle.time_s(other.points[order]))
                if value < worst - _EPS_S and (best is None or value < best[0]):
                    best = (value, j, rest, order)
        if best is None:
            best = _best_swap(routes, c, by_target, deadline)
        if best is None:
            return moves
        _, j, mine, theirs = best
        for k, order in ((c, mine), (j, theirs)):
            routes[k].order = order
            routes[k].time_s = routes[k].vehicle.time_s(routes[k].points[order])
        moves += 1
    return moves


def _best_swap(
    routes: list[_Route], c: int, by_target: list[list[IntArray]], deadline: float
) -> tuple[float, int, list[int], list[int]] | None:
    """The best swap of a stop of vehicle ``c`` with one of the nearest stops of another
    vehicle that shortens ``c`` without making the other as long, or None."""
    critical = routes[c]
    worst = critical.finish_s
    best: tuple[float, int, list[int], list[int]] | None = None
    for j, other in enumerate(routes):
        if j == c or not other.order:
            continue
        elsewhere = _seen_except(routes, {c, j})
        theirs_xy = other.points[other.order]
        for i, stop in enumerate(critical.order):
            if time.perf_counter() >= deadline:
                return best
            mine_rest = critical.order[:i] + critical.order[i + 1 :]
            d = np.hypot(*(theirs_xy - critical.points[stop]).T)
            for u_pos in np.argsort(d)[:_SWAP_NEAREST].tolist():
                u = other.order[u_pos]
                their_rest = other.order[:u_pos] + other.order[u_pos + 1 :]
                lost_mine = _lost(
                    critical,
                    stop,
                    mine_rest,
                    elsewhere | other.vehicle.instance.covers.seen(their_rest),
                )
                lost_theirs = _lost(
                    other,
                    u,
                    their_rest,
                    elsewhere | critical.vehicle.instance.covers.seen(mine_rest),
                )
                mine = _taking(critical, mine_rest, lost_theirs, by_target[c])
                if not mine:
                    continue
                mine_s = critical.offset_s + critical.vehicle.time_s(critical.points[mine])
                if mine_s >= worst - _EPS_S:
                    continue
                theirs = _taking(other, their_rest, lost_mine, by_target[j])
                if not theirs:
                    continue
                value = max(mine_s, other.offset_s + other.vehicle.time_s(other.points[theirs]))
                if value < worst - _EPS_S and (best is None or value < best[0]):
                    best = (value, j, mine, theirs)
    return best
