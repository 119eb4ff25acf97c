"""Refinement on the terrain: with the order fixed, move every stop to shorten the tour.

The solver's stops are candidate viewpoints: boundary samples of the visibility regions. The
shortest flight enters the regions anywhere, so each stop is moved, in turn, within the
region of everything it must see (the intersection of those targets' true regions), to
shorten its two legs. A move is kept only when it shortens the tour, the stop still sees
every target it is counted for from anywhere within ``tolerance_m`` of it and as the mission
writes it (:func:`~urpt_gcs.flight.margin.sees_around`: in the picture from the whole disc,
exactly, and in sight on the DEM's bilinear surface from the stop and points of the disc's
rim), and both new legs (and, with a depot, the leg straight home, which a flight cut into
sorties may fly) clear the terrain by ``min_clearance_m`` over known ground. The result is
never longer than the tour given.

First, a target counted at several stops is kept at the first of them only, and a stop left
with nothing to see is dropped where the leg that skips it clears: fewer targets per stop
leave it more room to move.

The search is a pattern search per stop: towards the straight line between its neighbours
(where the two legs are shortest), and around it at a step that halves when nothing around
helps. Stops that are not neighbours move together, so every check of a sweep is one call.
It alternates with 2-opt on the order of the moved stops (each new leg checked too), until
2-opt finds nothing.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.flight.margin import Site, Written, sees_around
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.outer import points_along
from urpt_gcs.visibility.segments import segment_profile

# Fractions of the way to the line between the neighbours, tried each sweep.
_TOWARDS = (1.0, 0.5, 0.25, 0.125, 0.0625)
# Directions of the pattern around a stop.
_DIRECTIONS = 12
# The pattern's first step, as a share of the stop's smallest cone radius, and its last:
# a stop is placed to within this of the best nearby, far finer than any vehicle holds a
# waypoint; every halving below it costs the sweeps of a whole tour.
_FIRST_STEP = 0.25
_LAST_STEP_M = 0.05
# Sweeps at most (a sweep that moves nothing halves every step, so this is never reached
# on a tour of sane size).
_MAX_SWEEPS = 400
# Rounds of moving the stops and 2-opt on their order.
_ROUNDS = 4
# A move must shorten the tour by at least this much (metres) to count: smaller gains only
# keep the sweeps going.
_MIN_GAIN_M = 0.01


@dataclass(frozen=True, slots=True)
class Refinement:
    """How refinement changed the tour: its length before and after, moves and sweeps."""

    before_m: float
    after_m: float
    moves: int
    sweeps: int
    seconds: float

    @property
    def shortened_pct(self) -> float:
        if self.before_m <= 0.0:
            return 0.0
        return 100.0 * (self.before_m - self.after_m) / self.before_m


def _closed_length(points: FloatArray, depot: FloatArray | None) -> float:
    path = points if depot is None else np.vstack([depot, points, depot])
    if depot is None and len(points) > 1:
        path = np.vstack([points, points[:1]])
    return float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0


def _neighbours(
    points: FloatArray, k: np.ndarray, depot: FloatArray | None
) -> tuple[FloatArray, FloatArray]:
    n = len(points)
    prev = points[(k - 1) % n].copy()
    nxt = points[(k + 1) % n].copy()
    if depot is not None:
        prev[k == 0] = depot
        nxt[k == n - 1] = depot
    return prev, nxt


def _toward_line(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """The point of segment ``a b`` nearest to each ``p``."""
    d = b - a
    ll = np.einsum("ij,ij->i", d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(ll > 0.0, np.einsum("ij,ij->i", p - a, d) / ll, 0.0)
    out: FloatArray = a + np.clip(t, 0.0, 1.0)[:, None] * d
    return out


def _feasible(
    site: Site,
    cand: FloatArray,
    sees: BoolArray | sparse.csr_array,
    heading: FloatArray | None,
    a: FloatArray,
    b: FloatArray,
    depot: FloatArray | None,
) -> BoolArray:
    """Which candidate stops (each with its row of targets to see, its heading and its
    neighbours ``a``, ``b``) pass every check of a move. With a depot the leg straight home
    is checked too: a flight cut into sorties may fly it."""

    # The cheap checks first and the costly ones only for the stops still standing: which
    # targets are in the camera's view from the whole disc (arithmetic), then the short legs
    # to the neighbours, then the lines of sight (the stop's own first, its rim after), and
    # the long leg home last. The checks are the same; most candidates fail the first ones.
    def legs(idx: IntArray) -> BoolArray:
        return _legs_clear(site, [a[idx], cand[idx]], [cand[idx], b[idx]])

    ok = sees_around(site, cand, sees, heading, legs)
    if depot is not None and ok.any():
        ok[ok] = _legs_clear(site, [cand[ok]], [np.tile(depot, (int(ok.sum()), 1))])
    return ok


def flies_from(
    site: Site, cand: FloatArray, sees: BoolArray | sparse.csr_array, depot: FloatArray
) -> BoolArray:
    """Whether a stop could be flown from each candidate (a cone camera): it sees every
    target of its row of ``sees`` from anywhere within the tolerance and as written,
    and its leg straight home clears the terrain (a sortie may end there)."""
    ok = sees_around(site, cand, sees, None)
    if ok.any():
        ok[ok] = _legs_clear(site, [cand[ok]], [np.tile(depot, (int(ok.sum()), 1))])
    return ok


def _legs_clear(site: Site, starts: list[FloatArray], ends: list[FloatArray]) -> BoolArray:
    """Per stop, whether its legs (``starts[j][i]`` to ``ends[j][i]`` for every ``j``) keep
    the clearance over terrain that is read."""
    n = len(starts[0])
    if site.fill is not None:
        site.fill(np.vstack(starts), np.vstack(ends))
    h = np.full(len(starts) * n, site.camera.altitude_m)
    start = np.column_stack([np.vstack(starts), h])
    end = np.column_stack([np.vstack(ends), h])
    prof = segment_profile(site.terrain, start, end, site.workers)
    legs_ok = (prof.unknown_fraction == 0.0) & (prof.excess_m <= -site.min_clearance_m)
    out: BoolArray = legs_ok.reshape(len(starts), n).all(axis=0)
    return out


def refine_tour(
    site: Site,
    tour: Tour,
    depot_xy: tuple[float, float] | None,
    time_limit_s: float,
) -> tuple[Tour, Refinement]:
    """The tour with its stops moved to shorten it, every move checked on the terrain.

    Parameters
    ----------
    site
        Terrain, targets, camera and the checks' margins.
    tour
        The tour to refine; ``tour.sees`` says what each stop must keep seeing.
    depot_xy
        Home, where the tour starts and ends (None: a closed cycle).
    time_limit_s
        Seconds the search may take; every sweep started is finished.

    Returns
    -------
    tuple
        The refined tour (never longer) and what refinement did.
    """
    started = time.perf_counter()
    if tour.points_xy is None or len(tour.points_xy) == 0:
        length = tour.length
        return tour, Refinement(length, length, 0, 0, 0.0)
    depot = None if depot_xy is None else np.asarray(depot_xy, dtype=np.float64)
    before = _closed_length(np.asarray(tour.points_xy, dtype=np.float64), depot)
    keep, sees = _thin(site, tour, depot)
    pts = np.array(tour.points_xy[keep], dtype=np.float64)
    n = len(pts)
    heading = None if tour.headings_deg is None else np.asarray(tour.headings_deg, np.float64)
    if heading is not None:
        heading = heading[keep]
    cone = site.camera.least_half_width_m(site.ground_m)
    smallest = np.array([cone[row].min() if row.any() else 0.0 for row in sees])
    step = _FIRST_STEP * smallest
    # Stops moved together are never neighbours: alternate ones, and the last on its own
    # when a closed cycle has an odd number.
    colour = np.arange(n) % 2
    if depot is None and n % 2 == 1 and n > 1:
        colour[-1] = 2
    groups = [np.flatnonzero(colour == c) for c in range(3) if (colour == c).any()]
    if depot is None and n <= 2:
        groups = [np.array([k]) for k in range(n)]
    perm = np.arange(n)
    moves = sweeps = 0
    for _ in range(_ROUNDS):
        m, w = _pattern_search(site, pts, sees, heading, depot, step, groups, started, time_limit_s)
        moves, sweeps = moves + m, sweeps + w
        # With the stops moved, a new order may be shorter: 2-opt, each new leg checked.
        if not _two_opt(site, pts, sees, heading, perm, depot):
            break
        # Look around the stops again, close by: they moved little.
        step = np.minimum(_FIRST_STEP * smallest[perm], 16.0 * _LAST_STEP_M)
    after = _closed_length(pts, depot)
    if after >= before:
        return tour, Refinement(before, before, 0, sweeps, time.perf_counter() - started)
    old_xy = tour.points_xy[keep][perm]
    refined = dataclasses.replace(
        tour,
        order=tuple(
            v if np.array_equal(pts[i], old_xy[i]) else -1
            for i, v in enumerate(np.asarray(tour.order)[keep][perm].tolist())
        ),
        points_xy=pts,
        sees=sees,
        headings_deg=heading,
        length=after,
        lower_bound=min(tour.lower_bound, after),
        notes=(*tour.notes, f"stops moved within their regions: {before:.1f} m -> {after:.1f} m"),
    )
    return refined, Refinement(before, after, moves, sweeps, time.perf_counter() - started)


def tour_along(
    site: Site,
    polyline_xy: FloatArray,
    depot_xy: tuple[float, float] | None,
    like: Tour,
) -> Tour | None:
    """A tour read off a closed polyline that meets every target's region (the certified
    bound's shortest relaxed tour): each target is seen from the polyline's sample nearest
    its nadir that sees it, the stops in the polyline's order, so the tour is no longer than
    the polyline. Where no sample sees a target (the polyline grazes its outer star, a hair
    wider than what is seen) the sample nearest the nadir is moved towards it until it does.
    None when a stop or leg fails the checks refinement applies (a frame camera, whose
    stops need headings, is not read off a polyline). ``like`` gives the tour's solver
    and bound."""
    if like.headings_deg is not None:
        return None
    poly = np.asarray(polyline_xy, dtype=np.float64).reshape(-1, 2)
    depot = None if depot_xy is None else np.asarray(depot_xy, dtype=np.float64)
    if depot is not None:
        # Start where the polyline passes nearest home (it passes through it).
        at = int(np.argmin(np.hypot(*(poly - depot).T)))
        poly = np.roll(poly, -at, axis=0)
    least = float(site.camera.least_half_width_m(site.ground_m).min())
    around = float(np.hypot(*np.diff(np.vstack([poly, poly[:1]]), axis=0).T).sum())
    samples = points_along(poly, max(_ALONG_SHARE * least, around / _ALONG_MOST))
    m = len(site.targets_xy)
    cone = site.camera.cone_radius_m(site.ground_m)
    # Per target its nearest samples, nearest first; those in its cone (the nearest at least).
    dist, nearest = cKDTree(samples).query(site.targets_xy, k=min(_NEAREST, len(samples)))
    dist, nearest = dist.reshape(m, -1), nearest.reshape(m, -1)
    key = np.empty(m, dtype=np.int64)
    stops = np.empty((m, 2))
    for t in range(m):
        near = nearest[t, : max(int(np.searchsorted(dist[t], cone[t])), 1)]
        row = np.zeros((len(near), m), dtype=bool)
        row[:, t] = True
        seen = np.flatnonzero(sees_around(site, samples[near], row, None))
        if seen.size:
            k = int(near[seen[0]])
            stops[t] = samples[k]
        else:
            # The sample needing the least move towards the nadir to see the target.
            moved = _towards_seen(site, samples[near], t)
            j = int(np.argmin(np.hypot(*(moved - samples[near]).T)))
            k, stops[t] = int(near[j]), moved[j]
        # Targets seen from one sample share a stop; a stop moved off it is its own.
        key[t] = k * (m + 1) + (0 if seen.size else t + 1)
    keys, first, group = np.unique(key, return_index=True, return_inverse=True)
    sees = np.zeros((len(keys), m), dtype=bool)
    sees[group.ravel(), np.arange(m)] = True
    pts = stops[first]
    prev, nxt = _neighbours(pts, np.arange(len(pts)), depot)
    if not _feasible(site, pts, sees, None, prev, nxt, depot).all():
        return None
    length = _closed_length(pts, depot)
    return dataclasses.replace(
        like,
        order=(-1,) * len(pts),
        length=length,
        lower_bound=min(like.lower_bound, length),
        proven_optimal=False,
        points_xy=pts,
        sees=sees,
        notes=(*like.notes, f"stops read off the bound's relaxed tour: {length:.1f} m"),
    )


def refine_along(
    site: Site,
    polyline_xy: FloatArray,
    depot_xy: tuple[float, float] | None,
    like: Tour,
    time_limit_s: float,
) -> tuple[Tour, Refinement] | None:
    """The tour read off the polyline (:func:`tour_along`), refined (:func:`refine_tour`);
    None when none could be read."""
    along = tour_along(site, polyline_xy, depot_xy, like)
    return None if along is None else refine_tour(site, along, depot_xy, time_limit_s)


# Samples along a polyline a tour is read from: this share of the least cone radius apart.
_ALONG_SHARE = 0.002
# Samples along the polyline at most, and per target the nearest of them tried at most.
_ALONG_MOST = 50_000
_NEAREST = 1024
# Halvings towards the nadir for a stop read off a polyline that does not see its target: at
# most this many, each start's until what it brackets is this short (metres).
_TOWARDS_STEPS = 40
_TOWARDS_TO_M = 1e-3


def _towards_seen(site: Site, start: FloatArray, target: int) -> FloatArray:
    """For each start, the point of its way to the target's nadir nearest it found to see
    the target (halving: along an azimuth what is seen is an interval from the nadir)."""
    c = site.targets_xy[target]
    row = np.zeros((len(start), len(site.targets_xy)), dtype=bool)
    row[:, target] = True
    way = np.hypot(*(c - start).T)
    lo = np.zeros(len(start))  # share of the way travelled that fails
    hi = np.ones(len(start))  # share that sees (the nadir is taken to)
    for _ in range(_TOWARDS_STEPS):
        todo = np.flatnonzero((hi - lo) * way > _TOWARDS_TO_M)
        if todo.size == 0:
            break
        mid = 0.5 * (lo[todo] + hi[todo])
        ok = sees_around(site, start[todo] + mid[:, None] * (c - start[todo]), row[todo], None)
        hi[todo] = np.where(ok, mid, hi[todo])
        lo[todo] = np.where(ok, lo[todo], mid)
    out: FloatArray = start + hi[:, None] * (c - start)
    return out


def _pattern_search(
    site: Site,
    pts: FloatArray,
    sees: BoolArray,
    heading: FloatArray | None,
    depot: FloatArray | None,
    step: FloatArray,
    groups: list[np.ndarray],
    started: float,
    time_limit_s: float,
) -> tuple[int, int]:
    """Move the stops (``pts``, in place) until every step is down to a centimetre; return
    the moves made and the sweeps taken."""
    before = _closed_length(pts, depot)
    theta = np.arange(_DIRECTIONS) * (2.0 * math.pi / _DIRECTIONS)
    ring = np.column_stack([np.cos(theta), np.sin(theta)])
    # The rows of the candidates' stops are taken many times over: sparse, they cost what
    # the stops see, not the whole width of the targets.
    rows = sparse.csr_array(sees)
    moves = sweeps = 0
    while sweeps < _MAX_SWEEPS and time.perf_counter() - started < time_limit_s:
        sweeps += 1
        gained = 0.0
        for k in groups:
            k = k[step[k] >= _LAST_STEP_M]
            if k.size == 0:
                continue
            a, b = _neighbours(pts, k, depot)
            p = pts[k]
            q = _toward_line(p, a, b)
            tries = [p + f * (q - p) for f in _TOWARDS]
            tries += [p + step[k][:, None] * d for d in ring]
            cand = np.stack(tries, axis=1)  # (stops, tries, 2)
            old = np.hypot(*(p - a).T) + np.hypot(*(p - b).T)
            new = np.hypot(*(cand - a[:, None]).transpose(2, 0, 1)) + np.hypot(
                *(cand - b[:, None]).transpose(2, 0, 1)
            )
            value = np.where(new < old[:, None] - _MIN_GAIN_M, new, np.inf)
            # Each stop's best try first, all stops at once; the rest only where it fails:
            # the same pick as checking them all, most of the checks saved.
            ok = np.zeros(value.shape, dtype=bool)
            for batch in _best_then_rest(value):
                found = np.any(ok, axis=1, keepdims=True)
                si, ti = np.nonzero(batch & ~found)
                if si.size:
                    ok[si, ti] = _feasible(
                        site,
                        cand[si, ti],
                        rows[k[si]],
                        None if heading is None else heading[k[si]],
                        a[si],
                        b[si],
                        depot,
                    )
            value = np.where(ok, value, np.inf)
            pick = value.argmin(axis=1)
            moved = np.isfinite(value[np.arange(k.size), pick])
            for j in np.flatnonzero(moved):
                pts[k[j]] = cand[j, pick[j]]
                gained += float(old[j] - value[j, pick[j]])
            moves += int(moved.sum())
            # Nothing around helped: look closer next time.
            step[k[~moved]] *= 0.5
        if gained <= 1e-9 * max(before, 1.0) and bool(np.all(step < _LAST_STEP_M)):
            break
    return moves, sweeps


def _best_then_rest(value: FloatArray) -> tuple[BoolArray, BoolArray]:
    """Two masks of the finite tries: each row's least, then the others."""
    finite = np.isfinite(value)
    best = np.zeros_like(finite)
    rows = np.flatnonzero(finite.any(axis=1))
    best[rows, value[rows].argmin(axis=1)] = True
    return best, finite & ~best


def _two_opt(
    site: Site,
    pts: FloatArray,
    sees: BoolArray,
    heading: FloatArray | None,
    perm: np.ndarray,
    depot: FloatArray | None,
) -> bool:
    """Reverse stretches of the tour (``pts`` and what goes with each stop, in place) while
    that shortens it and both new legs clear the terrain; whether anything changed."""
    n = len(pts)
    changed = False
    moved = np.arange(n)  # the stop now at each place, numbered as before
    h = site.camera.altitude_m
    first = 0 if depot is not None else 1
    for _ in range(n):
        improved = False
        for i in range(first, n - 1):
            # Reversing stops i..j swaps the legs (a, b), (c, d) for (a, c), (b, d).
            j = np.arange(i + 1, n)
            if depot is not None:
                a = pts[i - 1] if i > 0 else depot
                d = np.vstack([pts, depot])[j + 1]
            else:
                a = pts[i - 1]
                d = pts[(j + 1) % n]
            b, c = pts[i], pts[j]
            gain = (
                math.hypot(*(b - a))
                + np.hypot(*(d - c).T)
                - np.hypot(*(c - a).T)
                - np.hypot(*(d - b[None, :]).T)
            )
            if gain.size == 0 or gain.max() <= _MIN_GAIN_M:
                continue
            best = int(gain.argmax())
            start = np.array([[a[0], a[1], h], [b[0], b[1], h]])
            end = np.array([[c[best][0], c[best][1], h], [d[best][0], d[best][1], h]])
            if site.fill is not None:
                site.fill(start[:, :2], end[:, :2])
            prof = segment_profile(site.terrain, start, end, site.workers)
            if not bool(
                np.all(prof.unknown_fraction == 0.0)
                and np.all(prof.excess_m <= -site.min_clearance_m)
            ):
                continue
            k = int(j[best])
            for arr in (pts, moved, perm, heading):
                if arr is not None:
                    arr[i : k + 1] = arr[i : k + 1][::-1].copy()
            improved = changed = True
        if not improved:
            break
    if changed:
        # The rows of what each stop sees follow once, not with every reversal.
        sees[:] = sees[moved]
    return changed


def _thin(site: Site, tour: Tour, depot: FloatArray | None) -> tuple[np.ndarray, BoolArray]:
    """Which stops to keep and what each must see: a target counted at several stops only at
    the first, and a stop left with nothing to see dropped where the leg that skips it clears
    the terrain (never longer, by the triangle inequality). Fewer targets per stop leave
    more room to move."""
    assert tour.points_xy is not None
    counted = tour.sees.any(axis=0)
    first = np.argmax(tour.sees, axis=0)
    sees = np.zeros_like(tour.sees, dtype=bool)
    sees[first[counted], np.flatnonzero(counted)] = True
    keep = np.ones(len(sees), dtype=bool)
    pts = np.asarray(tour.points_xy, dtype=np.float64)
    h = site.camera.altitude_m
    for k in np.flatnonzero(~sees.any(axis=1)).tolist():
        kept = np.flatnonzero(keep)
        j = int(np.searchsorted(kept, k))
        earlier, later = kept[:j], kept[j + 1 :]
        if depot is not None:
            a = pts[earlier[-1]] if earlier.size else depot
            b = pts[later[0]] if later.size else depot
        else:
            rest = np.concatenate([later, earlier])
            if rest.size < 2:
                continue
            a, b = pts[rest[-1]], pts[rest[0]]
        if site.fill is not None:
            site.fill(a[None, :], b[None, :])
        prof = segment_profile(site.terrain, [[a[0], a[1], h]], [[b[0], b[1], h]], site.workers)
        if prof.unknown_fraction[0] == 0.0 and prof.excess_m[0] <= -site.min_clearance_m:
            keep[k] = False
    return np.flatnonzero(keep), sees[keep]


def written_grid(
    to_latlon: Callable[[FloatArray], FloatArray],
    to_xy: Callable[[FloatArray], FloatArray],
    step_deg: float = 1e-7,
) -> Written:
    """The position a mission writes for each point: lat/lon rounded to ``step_deg``."""

    def written(xy: FloatArray) -> FloatArray:
        ll = to_latlon(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return to_xy(np.round(ll / step_deg) * step_deg)

    return written


__all__ = [
    "Refinement",
    "Site",
    "flies_from",
    "refine_along",
    "refine_tour",
    "tour_along",
    "written_grid",
]
