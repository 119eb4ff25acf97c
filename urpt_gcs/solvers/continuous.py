"""The continuous problem from regions alone: discretise, solve, refine, bound.

``solve_regions`` takes discs or polygons (and a depot) with no terrain, and returns the
shortest tour it finds that enters every region together with a certified lower bound for
*every* such tour, not only those through its candidate points:

1. discretise: candidate points on every region's boundary (and one inside), each covering
   every region it lies in -- a generalized TSP (:class:`urpt_gcs.problem.instance.Instance`);
2. solve it with the GTSP solvers (:mod:`urpt_gcs.solvers`);
3. refine the tour continuously with the order fixed (:mod:`urpt_gcs.solvers.refine`); for
   polygons, solve again with the refined points among the candidates and refine again;
   for discs, search the order continuously from many starts (:func:`_search_starts`);
4. bound it (:mod:`urpt_gcs.bound.lower_bound`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
import time
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.bound.lower_bound import Bound, lower_bound, tube_over, with_tube
from urpt_gcs.errors import PlanError
from urpt_gcs.problem.instance import Instance
from urpt_gcs.problem.regions import RegionSet
from urpt_gcs.solvers import disc_tour
from urpt_gcs.solvers.base import SolveSettings, Tour
from urpt_gcs.solvers.refine import closed_length, refine_touches
from urpt_gcs.solvers.registry import solve

__all__ = [
    "SAMPLES",
    "ContinuousTour",
    "nested_discs",
    "solve_regions",
    "stops",
    "touches",
]

# Boundary samples per region; for discs at most _DISC_SAMPLE_BUDGET in all (no fewer than
# _MIN_DISC_SAMPLES each).
SAMPLES = 24
_DISC_SAMPLE_BUDGET = 2400
_MIN_DISC_SAMPLES = 4
# Fraction of the time limit for the bound; the rest goes to solving and re-solving.
_BOUND_SHARE = 0.3
# Re-solves after the first solve, with the refined points among the candidates (polygons).
_ROUNDS = 3
# For discs: the share of the solve time for the one discrete solve; the continuous order
# search (:mod:`urpt_gcs.solvers.disc_tour`) has the rest.
_DISC_DISCRETE_SHARE = 0.15
# Above this many discs the order search keeps kicked tours up to _DRIFT longer than the
# shortest it met (record-to-record): from one start, strict descent stalls there.
_DRIFT_ABOVE = 200
_DRIFT = 0.002
# The order search runs from many starts: the discrete tour, then other starts, about
# _RESTART_S seconds each (the search from one start settles within seconds into one global
# shape). For the last _RUIN_PHASE of its time the shortest tour is ruined by area
# (:func:`disc_tour.region_ruin`, _REGION_SHARE of the discs) and searched about _RUIN_S
# seconds, the result kept if shorter: the shape is right there and parts of it are rebuilt.
# The figures behind these values are in benchmarks/README.md (bench cetsp).
_RESTART_S = 3.0
_RUIN_PHASE = 0.4
_RUIN_S = 2.0
_REGION_SHARE = 0.12
# Up to _DISCRETE_STARTS_UP_TO discs a restart starts from a discrete solve of the
# candidates with a fresh seed, given _DISCRETE_START of the restart's time; above, from a
# tour of the discs inserted in random order (:func:`disc_tour.insertion_tour`). The
# discrete solver reaches other global shapes than insertion and the order search do
# (benchmarks/README.md, bench cetsp).
_DISCRETE_STARTS_UP_TO = _DRIFT_ABOVE
_DISCRETE_START = 1.0 / 3.0
# Up to _DISCRETE_STARTS_UP_TO discs around a depot, one ruin in _DEPOT_MOVE_EVERY (the
# first of each thread's) moves the depot to another leg instead (:func:`disc_tour.depot_moved`;
# the search's own moves do not, and its escape needs longer searches than these). Its
# gain is not established (benchmarks/README.md, bench cetsp).
_DEPOT_MOVE_EVERY = 2
# Disc-segment pairs per block when a polyline's touches are found.
_BLOCK_ELEMENTS = 1 << 18


@dataclass(frozen=True, slots=True)
class ContinuousTour:
    """A tour entering every region, and how far at most it is from the shortest such tour.

    ``points_xy`` are the stops in order (from the depot and back, if there is one);
    ``touch_region[k]`` and ``touch_xy[k]`` say where the tour enters each region, in order.
    ``discrete_length`` is the best tour over the candidate points before refinement, and
    ``lower_bound`` is certified for every tour of the continuous problem.
    """

    points_xy: FloatArray
    touch_region: IntArray
    touch_xy: FloatArray
    length: float
    discrete_length: float
    lower_bound: float
    bound: Bound
    solver: str
    optimal_over_candidates: bool
    solve_s: float

    @property
    def gap(self) -> float:
        """``(length - lower_bound) / lower_bound``; infinite without a positive bound."""
        if self.lower_bound <= 0.0:
            return 0.0 if self.length <= 0.0 else math.inf
        return max(self.length - self.lower_bound, 0.0) / self.lower_bound


def touches(instance: Instance, tour: Tour) -> tuple[IntArray, FloatArray]:
    """The touches of a discrete tour: each region at the first stop that covers it."""
    assert tour.points_xy is not None
    seen = np.zeros(instance.n_targets, dtype=bool)
    seq: list[int] = []
    pts: list[FloatArray] = []
    for k in range(len(tour.order)):
        fresh = np.flatnonzero(tour.sees[k] & ~seen)
        seen[fresh] = True
        seq.extend(int(t) for t in fresh)
        pts.extend(tour.points_xy[k] for _ in fresh)
    return np.asarray(seq, dtype=np.int64), np.asarray(pts, dtype=np.float64).reshape(-1, 2)


def stops(points_xy: FloatArray) -> FloatArray:
    """The touch points with consecutive repeats merged."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 2:
        return pts
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-12
    return pts[keep]


def solve_regions(
    regions: RegionSet,
    settings: SolveSettings | None = None,
    solver: str = "auto",
    samples: int = SAMPLES,
    gap_target: float = 1e-4,
) -> ContinuousTour:
    """The shortest tour found that enters every region, with a certified lower bound.

    Parameters
    ----------
    regions
        Discs or polygons, and the depot if tours start and end there.
    settings
        Time limit (for the whole: solve, re-solves and bound) and seed.
    solver
        The GTSP solver for the candidate points (see :func:`urpt_gcs.solvers.solve`).
    samples
        Boundary candidates per region (for many discs fewer, see ``_DISC_SAMPLE_BUDGET``).
    gap_target
        The bound stops refining its pieces once the gap is below this.

    Returns
    -------
    ContinuousTour
        The tour, its length before and after refinement, and the bound.
    """
    settings = settings or SolveSettings()
    if regions.discs is not None:
        nested = nested_discs(regions.discs)
        if (nested >= 0).any():
            # A disc holding another is entered by every tour that enters the other: the
            # tours through the rest are the same tours, and their bound is a bound.
            kept = np.flatnonzero(nested < 0)
            fewer = dataclasses.replace(
                regions,
                discs=regions.discs[kept],
                outer=(),
                depot_inside=None
                if regions.depot_inside is None
                else tuple(regions.depot_inside[k] for k in kept),
            )
            return _with_nested(
                regions, kept, nested, solve_regions(fewer, settings, solver, samples, gap_target)
            )
    started = time.perf_counter()
    solve_budget = settings.time_limit_s * (1.0 - _BOUND_SHARE)
    if regions.discs is not None:
        # Fewer candidates on many discs: the order search does better from a tour the
        # GTSP solver could search well than from one over too many candidates.
        samples = max(_MIN_DISC_SAMPLES, min(samples, _DISC_SAMPLE_BUDGET // regions.n))
    base_xy, _ = regions.samples(samples)
    instance = regions.instance(base_xy)
    with_discs = regions.discs is not None
    rounds = 0 if with_discs else _ROUNDS
    share = _DISC_DISCRETE_SHARE if with_discs else 1.0
    discrete_budget = solve_budget * share
    first = solve(instance, solver, _share(settings, discrete_budget / (rounds + 1)))
    discrete = first.length
    seq, pts = touches(instance, first)
    pts = _refine(regions, seq, pts)
    best_len = closed_length(pts, regions.depot_xy)
    best_seq, best_pts = seq, pts
    for round_ in range(rounds):
        left = discrete_budget - (time.perf_counter() - started)
        if left <= 0.05:
            break
        inst = regions.instance(np.vstack([base_xy, best_pts]))
        rounds_left = rounds - round_
        tour = solve(inst, solver, _share(settings, left / rounds_left, seed_offset=round_ + 1))
        seq, pts = touches(inst, tour)
        pts = _refine(regions, seq, pts)
        length = closed_length(pts, regions.depot_xy)
        if length < best_len:
            best_len, best_seq, best_pts = length, seq, pts
    if with_discs:
        left = solve_budget - (time.perf_counter() - started)
        seq, pts = _search_starts(
            regions,
            best_seq,
            best_pts,
            left,
            settings.seed,
            settings.threads,
            instance if regions.n <= _DISCRETE_STARTS_UP_TO else None,
        )
        length = closed_length(pts, regions.depot_xy)
        if length < best_len:
            best_len, best_seq, best_pts = length, seq, pts
    best_pts = _inside_discs(regions, best_seq, best_pts)
    inside = regions.contains(best_pts, best_seq)
    if not inside.all() or np.unique(best_seq).size != regions.n:
        raise PlanError("internal check failed: a refined tour left a region; report this")
    left = max(settings.time_limit_s - (time.perf_counter() - started), 0.05)
    # The order search over every disc: its relaxed tour meets them all, so a tour may be
    # read off it (below); ``auto`` would bound large instances over a subset.
    bound = lower_bound(regions, best_len, left, gap_target, method="order")
    # The tube bound counts every region at once, in milliseconds: where regions crowd it is
    # far above the order search's over them all.
    bound = with_tube(bound, tube_over(regions), regions, best_len)
    # For discs the bound's search meets real tours: the shortest it met may beat ours.
    relaxed = _from_relaxed(regions, bound.relaxed_tour_xy)
    if relaxed is not None:
        length = closed_length(relaxed[1], regions.depot_xy)
        if length < best_len:
            best_len, (best_seq, best_pts) = length, relaxed
    left = settings.time_limit_s - (time.perf_counter() - started)
    searched = regions.n - (regions.depot_xy is None) >= disc_tour.MIN_SEARCHED
    if with_discs and searched and left >= _RUIN_S and best_len > bound.value * (1 + gap_target):
        # The bound stopped early (it could rise no further): its time left goes on ruining
        # areas of the shortest tour, which the bound holds for as it holds for every tour.
        seq, pts = _search_starts(
            regions, best_seq, best_pts, left, settings.seed + 1, settings.threads, ruins=True
        )
        pts = _inside_discs(regions, seq, pts)
        length = closed_length(pts, regions.depot_xy)
        if length < best_len and regions.contains(pts, seq).all():
            best_len, best_seq, best_pts = length, seq, pts
    return ContinuousTour(
        points_xy=stops(best_pts),
        touch_region=best_seq,
        touch_xy=best_pts,
        length=best_len,
        discrete_length=discrete,
        lower_bound=bound.value,
        bound=bound,
        solver=first.solver,
        optimal_over_candidates=first.proven_optimal,
        solve_s=time.perf_counter() - started,
    )


def nested_discs(discs: FloatArray) -> IntArray:
    """Per disc, a disc wholly inside it that holds no other (its index), or -1 where the
    disc holds none. Held means strictly, by a relative hair: a point of the inner disc lies
    inside the outer one whatever the rounding, and equal discs are kept both."""
    d = np.asarray(discs, dtype=np.float64)
    n = len(d)
    xy, r = d[:, :2], d[:, 2]
    slack = 1e-12 * (1.0 + float(np.abs(xy).max(initial=0.0)) + float(r.max(initial=0.0)))
    tree = cKDTree(xy)
    holds: list[IntArray] = []
    for i, near in enumerate(tree.query_ball_point(xy, r)):
        j = np.asarray(near, dtype=np.int64)
        j = j[j != i]
        inner = np.hypot(*(xy[j] - xy[i]).T) + r[j] <= r[i] - slack
        holds.append(j[inner])
    # Strictly held discs are smaller: the smallest first, each one that holds a disc takes
    # the innermost that disc leads to, which holds none.
    out = np.full(n, -1, dtype=np.int64)
    for i in np.argsort(r, kind="stable"):
        if holds[i].size:
            held = int(holds[i][0])
            out[i] = held if out[held] < 0 else out[held]
    return out


def _with_nested(
    regions: RegionSet, kept: IntArray, inside: IntArray, tour: ContinuousTour
) -> ContinuousTour:
    """The tour of the discs ``kept`` as a tour of them all: each disc that holds another
    touched where the disc it holds is (:func:`nested_discs`), and the whole checked."""
    seq = kept[tour.touch_region]
    at = {int(k): i for i, k in enumerate(seq.tolist())}
    holders: dict[int, list[int]] = {}
    for i in np.flatnonzero(inside >= 0).tolist():
        holders.setdefault(at[int(inside[i])], []).append(i)
    # Each touch, then the discs holding its disc, at the same point.
    places = [(int(k), i) for i, k in enumerate(seq.tolist())]
    order = [p for k, i in places for p in [(k, i), *((h, i) for h in holders.get(i, []))]]
    full_seq = np.asarray([k for k, _ in order], dtype=np.int64)
    full_xy = tour.touch_xy[np.asarray([i for _, i in order], dtype=np.int64)].reshape(-1, 2)
    if not regions.contains(full_xy, full_seq).all() or np.unique(full_seq).size != regions.n:
        raise PlanError("internal check failed: a disc holding another was left; report this")
    return dataclasses.replace(tour, touch_region=full_seq, touch_xy=full_xy)


def _inside_discs(regions: RegionSet, seq: IntArray, pts: FloatArray) -> FloatArray:
    """The touch points, each drawn onto its disc where rounding left it outside (on the rim,
    or discs far smaller than their coordinates, where a hair inside relative to the radius
    is below the coordinates' rounding): moved onto the radius a hair inside, or onto the
    centre where even that rounds outside. Polygons are left as they are."""
    if regions.discs is None:
        return pts
    out = regions.contains(pts, seq)
    if out.all():
        return pts
    pts = pts.copy()
    d = regions.discs[seq[~out]]
    away = pts[~out] - d[:, :2]
    far = np.maximum(np.hypot(away[:, 0], away[:, 1]), 1e-300)
    pulled = d[:, :2] + away * (d[:, 2] * (1.0 - 1e-9) / far)[:, None]
    still = np.hypot(*(pulled - d[:, :2]).T) > d[:, 2]
    pulled[still] = d[still, :2]
    pts[~out] = pulled
    return pts


def _from_relaxed(
    regions: RegionSet, polyline_xy: FloatArray | None
) -> tuple[IntArray, FloatArray] | None:
    """The touches of a closed polyline that meets every disc (the bound's shortest), or
    None where it misses one: each disc entered at the polyline's point nearest its centre,
    in the order the polyline (from the depot, if any) reaches them. Joining those points
    in that order is no longer than the polyline."""
    if regions.discs is None or polyline_xy is None or len(polyline_xy) < 2:
        return None
    poly = np.asarray(polyline_xy, dtype=np.float64)
    if regions.depot_xy is not None:
        home = np.hypot(*(poly - np.asarray(regions.depot_xy)).T)
        at = int(np.argmin(home))
        if home[at] > 1e-9 * (1.0 + float(np.abs(poly).max())):
            return None
        poly = np.roll(poly, -at, axis=0)
        poly[0] = regions.depot_xy
    a = poly
    d = np.roll(poly, -1, axis=0) - a
    ll = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    c, r = regions.discs[:, :2], regions.discs[:, 2]
    k = np.arange(len(c))
    seg, along = np.empty(len(c), dtype=np.int64), np.empty(len(c))
    pts, far = np.empty((len(c), 2)), np.empty(len(c))
    # Each centre's nearest point on every segment, a block of discs at a time (memory).
    step = max(1, _BLOCK_ELEMENTS // len(a))
    for lo in range(0, len(c), step):
        cc = c[lo : lo + step]
        t = np.clip(np.einsum("kij,ij->ki", cc[:, None, :] - a[None], d) / ll, 0.0, 1.0)
        near = a[None] + t[..., None] * d[None]
        dist = np.hypot(*(near - cc[:, None, :]).transpose(2, 0, 1))
        j = np.argmin(dist, axis=1)
        i = np.arange(len(cc))
        seg[lo : lo + step], along[lo : lo + step] = j, t[i, j]
        pts[lo : lo + step], far[lo : lo + step] = near[i, j], dist[i, j]
    if np.any(far > r * (1.0 + 1e-9)):
        return None
    order = np.lexsort((along, seg))
    seq = k[order].astype(np.int64)
    # On the rim to rounding: drawn inside.
    return seq, _inside_discs(regions, seq, pts[order])


def _refine(regions: RegionSet, seq: IntArray, pts: FloatArray) -> FloatArray:
    """Stops moved within their regions, the order fixed: per-stop moves, and for discs
    around a depot the exact positions (which per-stop moves approach only slowly)."""
    pts = refine_touches(regions, seq, pts)
    if regions.discs is None or regions.depot_xy is None:
        return pts
    exact = disc_tour.exact_positions(seq, pts, regions.discs, np.asarray(regions.depot_xy))
    if closed_length(exact, regions.depot_xy) < closed_length(pts, regions.depot_xy):
        return exact
    return pts


def _search_discs(
    regions: RegionSet, seq: IntArray, pts: FloatArray, seconds: float, seed: int
) -> tuple[IntArray, FloatArray]:
    """The disc tour improved by the continuous order search (:mod:`disc_tour`).

    Without a depot the tour is searched twice, each time from a stop held fixed in place of
    the depot: first the first stop, then the one half way round, so that both move once.
    """
    assert regions.discs is not None
    discs = regions.discs
    drift = _DRIFT if regions.n > _DRIFT_ABOVE else 0.0
    # A disc touched twice keeps its first touch.
    _, first = np.unique(seq, return_index=True)
    keep = np.sort(first)
    seq, pts = np.asarray(seq)[keep], np.asarray(pts)[keep]
    if regions.depot_xy is not None:
        depot = np.asarray(regions.depot_xy)
        return disc_tour.improve(seq, pts, discs, depot, seconds, seed, drift)
    for half in range(2):
        if len(seq) < 3:
            break
        k = 0 if half == 0 else len(seq) // 2
        seq, pts = np.roll(seq, -k), np.roll(pts, -k, axis=0)
        anchor = pts[0].copy()
        rest_seq, rest_pts = disc_tour.improve(
            seq[1:], pts[1:], discs, anchor, seconds / 2, seed, drift
        )
        seq = np.concatenate([seq[:1], rest_seq])
        pts = np.vstack([anchor[None, :], rest_pts])
    return seq, pts


def _search_starts(
    regions: RegionSet,
    seq: IntArray,
    pts: FloatArray,
    seconds: float,
    seed: int,
    threads: int = 1,
    instance: Instance | None = None,
    ruins: bool = False,
) -> tuple[IntArray, FloatArray]:
    """The disc tour searched (:func:`_search_discs`) for ``seconds``: from the given tour
    and from other starts in turn: discrete solves of ``instance`` (the candidates of the
    discrete problem) with fresh seeds where it is given, else insertion tours. Then from
    the shortest found with one area of it ruined at a time (:func:`_region_ruin`) or, on
    few discs around a depot, also with the depot moved (:func:`_depot_moved`). The
    shortest found (never longer than the given tour). With ``ruins`` the whole time goes
    to the ruins of the given tour and those found from it: no other start.

    With ``threads`` above 1 as many searches run side by side (the search's kernels release
    the GIL), each taking its own starts and ruining the shortest any has found."""
    # Without a depot one stop is held in its place and the others searched.
    if regions.n - (regions.depot_xy is None) < disc_tour.MIN_SEARCHED:
        return _search_discs(regions, seq, pts, seconds, seed)
    shared = _Shortest(regions, (seq, pts), seconds, instance)
    if ruins:
        shared.ruin_at = time.perf_counter()
        shared.offer((seq, pts))
    if threads == 1:
        _search_lane(shared, seed, 0, 1)
        return shared.best
    with ThreadPoolExecutor(max_workers=threads) as pool:
        runs = [pool.submit(_search_lane, shared, seed, k, threads) for k in range(threads)]
        try:
            # A lane's failure as soon as it happens, not once the lanes before it end.
            done, _ = wait(runs, return_when=FIRST_EXCEPTION)
            for run in [*done, *runs]:
                run.result()
        except BaseException:
            # Interrupted (Ctrl-C) or failed: the other lanes stop after their current search.
            shared.end = -math.inf
            raise
    return shared.best


class _Shortest:
    """The shortest disc tour the searches have found, shared between their threads, and
    when their restarts and their whole search end."""

    def __init__(
        self,
        regions: RegionSet,
        start: tuple[IntArray, FloatArray],
        seconds: float,
        instance: Instance | None = None,
    ):
        self.regions = regions
        self.instance = instance
        # Depot moves among the ruins (:func:`disc_tour.depot_moved`).
        self.depot_moves = regions.depot_xy is not None and regions.n <= _DISCRETE_STARTS_UP_TO
        self.start = start
        started = time.perf_counter()
        self.ruin_at = started + seconds * (1.0 - _RUIN_PHASE)
        self.end = started + seconds
        self.each = max(min(_RESTART_S, seconds / 4.0), 0.05)
        self.best = start
        self.length = math.inf
        self._lock = threading.Lock()

    def offer(self, found: tuple[IntArray, FloatArray]) -> None:
        length = closed_length(found[1], self.regions.depot_xy)
        with self._lock:
            if length < self.length:
                self.length, self.best = length, found


def _search_lane(shared: _Shortest, seed: int, lane: int, lanes: int) -> None:
    """One thread of :func:`_search_starts`: restarts (lane 0 first from the given tour)
    until the ruin phase, then ruins of the shortest found. A restart starts from a
    discrete solve where there are candidates, from an insertion tour otherwise; a ruin
    moves the depot (where that is on) or rebuilds an area."""
    regions = shared.regions
    each = shared.each
    rng = np.random.default_rng(seed if lane == 0 else [seed, lane])
    for k in itertools.count():
        left = min(shared.ruin_at, shared.end) - time.perf_counter()
        if k > 0 and left < each / 2.0:
            break
        r = k * lanes + lane
        seconds = min(each, max(left, 0.05))
        if left <= 0.0 and k == 0 and shared.length < math.inf:
            break  # (ruins only: the given tour is offered already)
        if r == 0:
            start = shared.start
        elif shared.instance is not None:
            took = time.perf_counter()
            start = _discrete_start(regions, shared.instance, seconds * _DISCRETE_START, rng)
            seconds = max(seconds - (time.perf_counter() - took), 0.05)
        else:
            start = _insertion_start(regions, rng)
        found = _search_discs(regions, *start, seconds, seed + r)
        shared.offer(found)
    each = min(_RUIN_S, each)
    for k in itertools.count():
        left = shared.end - time.perf_counter()
        if left < each / 2.0:
            break
        if shared.depot_moves and k % _DEPOT_MOVE_EVERY == 0:
            ruined = _depot_moved(regions, *shared.best, rng)
        else:
            ruined = _region_ruin(regions, *shared.best, rng)
        found = _search_discs(regions, *ruined, min(each, left), int(rng.integers(2**31)))
        shared.offer(found)


def _discrete_start(
    regions: RegionSet, instance: Instance, seconds: float, rng: np.random.Generator
) -> tuple[IntArray, FloatArray]:
    """The refined touches of a heuristic solve of the candidates, with a fresh seed."""
    settings = SolveSettings(time_limit_s=max(seconds, 0.05), seed=int(rng.integers(2**31)))
    tour = solve(instance, "heuristic", settings)
    seq, pts = touches(instance, tour)
    return seq, _refine(regions, seq, pts)


def _region_ruin(
    regions: RegionSet, seq: IntArray, pts: FloatArray, rng: np.random.Generator
) -> tuple[IntArray, FloatArray]:
    """The tour with one area's discs put back afresh (:func:`disc_tour.region_ruin`);
    without a depot the first stop stays where it is, in the depot's place."""
    assert regions.discs is not None
    if regions.depot_xy is not None:
        depot = np.asarray(regions.depot_xy, dtype=np.float64)
        return disc_tour.region_ruin(seq, pts, regions.discs, depot, _REGION_SHARE, rng)
    rest_seq, rest_pts = disc_tour.region_ruin(
        seq[1:], pts[1:], regions.discs, pts[0], _REGION_SHARE, rng
    )
    return np.concatenate([seq[:1], rest_seq]), np.vstack([pts[:1], rest_pts])


def _depot_moved(
    regions: RegionSet, seq: IntArray, pts: FloatArray, rng: np.random.Generator
) -> tuple[IntArray, FloatArray]:
    """The tour with its depot moved to another leg (:func:`disc_tour.depot_moved`)."""
    assert regions.discs is not None and regions.depot_xy is not None
    depot = np.asarray(regions.depot_xy, dtype=np.float64)
    return disc_tour.depot_moved(seq, pts, regions.discs, depot, rng)


def _insertion_start(regions: RegionSet, rng: np.random.Generator) -> tuple[IntArray, FloatArray]:
    """A tour of every disc by random insertion (:func:`disc_tour.insertion_tour`); without
    a depot it starts at the centre of a disc drawn at random."""
    assert regions.discs is not None
    everyone = np.arange(regions.n)
    if regions.depot_xy is not None:
        depot = np.asarray(regions.depot_xy, dtype=np.float64)
        return disc_tour.insertion_tour(regions.discs, everyone, depot, rng)
    first = int(rng.integers(regions.n))
    centre = regions.discs[first, :2]
    seq, pts = disc_tour.insertion_tour(regions.discs, np.delete(everyone, first), centre, rng)
    return np.concatenate([[first], seq]), np.vstack([centre, pts])


def _share(settings: SolveSettings, seconds: float, seed_offset: int = 0) -> SolveSettings:
    return SolveSettings(
        time_limit_s=max(seconds, 0.05),
        seed=(settings.seed + seed_offset) % 2**32,
        threads=settings.threads,
    )
