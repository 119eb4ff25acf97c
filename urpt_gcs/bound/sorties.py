"""A lower bound for what is flown when the flight is cut into sorties under an endurance.

Every sortie flies from home and back on one battery. Joined at home the sorties are one
closed flight, so the single-tour bound holds for their total; but it knows nothing of the
returns home. :func:`sortie_bound` adds what the endurance forces:

*How many sorties reach far out.* Let ``r_i`` be the least distance from home to a point of
region ``i`` (its outer star: every point that sees the target lies in it), and take a
radius ``rho``. The sorties that photograph some region with ``r_i >= rho`` fly, outside the
disc of radius ``rho`` around home, pieces that start and end on its circle; shrink the disc
to one node and those pieces, with the straight lines between their points, connect the
disc to a point of every such region, so together they are at least the minimum spanning
tree ``M(rho)`` over the disc node and those regions (between two regions, the distance of
their enclosing circles; from a region to the disc, ``r_i - rho``). Each such sortie spends
at least ``2 rho`` inside the disc, getting out to its circle and back, and at most its
length budget ``D`` in all, so there are at least ``M(rho) / (D - 2 rho)`` of them; with its
time (below) counted instead of its length, stops and all, at least
``(S(rho) * stop + h * M(rho)) / (E - ends - 2 h rho)``, with ``S(rho)`` stops at least, one
per region of a set that no point sees two of. At ``rho = 0`` the single-tour bound ``B``
replaces ``M``: the sorties joined at home are one closed flight.

*Their length.* Sortie ``j`` reaching ``R_j`` from home flies at least ``2 min(R_j, rho)``
inside the disc; summed, ``2 * integral_0^rho #{j : R_j >= s} ds``, and the count at ``s``
is at least that of any larger radius, and up to the nearest region's distance it is every
sortie. With what the pieces outside need, for every ``rho``:
``L >= 2 * integral_0^rho K(s) ds + M(rho)``; the bound is the largest of those, ``B``, and
where two sorties or more are needed the K-tree bound (:mod:`urpt_gcs.bound.k_tree`: a
spanning forest of that many trees over the regions and twice as many legs home, raised by
multipliers as Held and Karp raise a 1-tree).

*Time.* A sortie's return leg is no longer than the rest of it, so at most half its length
is flown at the return speed, the rest at the cruise speed (each leg no faster than its
length over its speed): its time is at least ``ends + stops * stop + h * length`` with
``h = min(1 / cruise, (1 / cruise + 1 / return) / 2)`` and ``ends`` the take-off and the
landing. The return leg starts at a stop, in some region, so it is also no longer than
``far``, the farthest any region's circle reaches from home: ``K`` sorties fly at most
``min(L / 2, K * far)`` of their length at the return speed, and ``h * L`` is raised to
``L / cruise - min(L / 2, K * far) * (1 / cruise - 1 / return)`` where that is more.
The stops are at least ``S``: weights on the regions' circles such that the circles
through any one point weigh at most 1 together (:func:`~urpt_gcs.bound.geometric.stop_packing`)
sum to at most the number of stops, and those of the regions beyond a radius to at most the
stops that photograph them. Legs also speed up and brake: a leg of length ``d`` takes
``f(d)`` more than its length over the cruise speed, ``f(d) = c`` exactly from the length
``delta`` at which it reaches the cruise speed, and ``F(g)``, the least of ``f`` over lengths
of at least ``g``, for every leg of at least ``g``. Take stops at least ``g`` apart,
``Q_g`` of them at least: within a sortie the legs and stops from one such stop to the next
take at least one leg of their total length (a rest-to-rest leg's time is subadditive: two
legs flown one after the other, stopping between, are one way of flying their sum). Such
stops are those of regions whose circles lie at least ``g`` apart; or, walking each sortie,
its first stop and then every stop at least ``g`` from the last one taken: every stop is
then within ``g`` of one taken, so those taken meet every region's circle widened by ``g``,
and the packing of the widened circles counts them. So the sorties' legs take at
least ``(Q_g - K) * F(g)`` beyond their length's share, for each of a few gaps ``g`` up to
``delta``, and the count above holds with ``Q_g * F(g)`` added to the work and ``F(g)`` to
what each sortie holds. The total flight time is at least
``K * ends + max(K, S) * stop + max_g max(Q_g - K, 0) * F(g) + h * L``, at the least over the
counts ``K`` the bound allows.

Nothing here sees a raster: regions are centres, reaches and distances from home.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError, cKDTree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import PACKING_LP_MAX_CIRCLES, stop_packing
from urpt_gcs.bound.k_tree import k_tree_bound
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.regions import OuterStar

__all__ = [
    "CHAIN_GAPS",
    "DENSE_MAX_REGIONS",
    "SORTIES_SHARE",
    "THRESHOLDS",
    "SortieBound",
    "SortieBudget",
    "least_extra_s",
    "sortie_bound",
    "star_distances",
]

# Share of a plan's bound stage the K-tree bound of sorties takes at least, after the bound
# of one flight (which keeps its whole time: the stage runs over by up to this share where
# two sorties or more are proven).
SORTIES_SHARE = 0.15
# Radii at which the count of far sorties is bounded (the regions' own distances from home,
# evenly through their order): more is tighter and costs one spanning tree each.
THRESHOLDS = 48
# Up to this many regions the spanning trees use every pair's distance; above, the widest
# reach for every region, whose tree lies in the centres' Delaunay triangulation.
DENSE_MAX_REGIONS = 400
# The gaps, as shares of the length from which a leg reaches the cruise speed, at which the
# stops far apart are counted for what their legs spend speeding up and braking: the best
# gap depends on how the regions lie, and each costs one greedy pass over them.
CHAIN_GAPS = (1.0 / 16.0, 1.0 / 8.0, 1.0 / 4.0, 1.0 / 2.0, 3.0 / 4.0, 1.0)
# Steps of the least leg overhead's search between a gap and the cruise length.
_EXTRA_STEPS = 512
# Rounding slack: a count within this of an integer is not rounded up past it.
_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class SortieBudget:
    """What one sortie may spend, from the flight model and the endurance.

    Attributes
    ----------
    endurance_s
        Flight time of one sortie at most.
    ends_s
        What every sortie spends on the take-off and the landing.
    stop_s
        What every stop costs on top of its legs.
    per_metre_s
        Least time per metre flown over a whole sortie (see the module's text).
    chains
        Pairs ``(g, F)``: every leg at least ``g`` long takes at least ``F`` more than its
        length over the cruise speed (speeding up and braking); none to leave that out.
    cruise_per_metre_s, return_per_metre_s
        Least time per metre of a survey leg and of the leg home (0: only ``per_metre_s``
        is counted).
    """

    endurance_s: float
    ends_s: float
    stop_s: float
    per_metre_s: float
    chains: tuple[tuple[float, float], ...] = ()
    cruise_per_metre_s: float = 0.0
    return_per_metre_s: float = 0.0

    @classmethod
    def of(cls, model: FlightModel, altitude_rel_m: float, endurance_s: float) -> SortieBudget:
        """The budget of sorties flown at ``altitude_rel_m`` above home.

        Parameters
        ----------
        model
            The vehicle's flight model.
        altitude_rel_m
            The flight plane above home: the take-off climbs and the landing descends it.
        endurance_s
            Flight time of one sortie at most.

        Returns
        -------
        SortieBudget
            The budget.
        """
        cruise = 1.0 / model.cruise_m_s
        per_metre = min(cruise, 0.5 * (cruise + 1.0 / model.return_m_s))
        ends = model.takeoff_s(altitude_rel_m) + model.landing_s(altitude_rel_m)
        leg_from, _ = model.cruise_overhead()
        chains = tuple((g * leg_from, least_extra_s(model, g * leg_from)) for g in CHAIN_GAPS)
        return cls(
            endurance_s, ends, model.stop_s, per_metre, chains, cruise, 1.0 / model.return_m_s
        )

    @property
    def length_m(self) -> float:
        """The longest sortie with one stop."""
        return max(self.endurance_s - self.ends_s - self.stop_s, 0.0) / self.per_metre_s


@dataclass(frozen=True, slots=True)
class SortieBound:
    """A lower bound of every set of sorties from home, each within the budget, whose stops
    between them photograph every target.

    Attributes
    ----------
    length_m
        Their total length at least.
    flight_time_s
        Their total flight time at least, as the flight model counts it.
    sorties
        How many sorties at least.
    single_m
        The single-tour bound it started from.
    radius_m
        The radius whose count of far sorties gave ``length_m`` (0: the single-tour bound or
        the K-tree's).
    stops
        How many stops at least.
    spread
        Per gap, ``(Q, F)``: stops at least that far apart, and what each chain of legs
        between two of them spends beyond its length's share.
    ends_s, stop_s
        What each sortie spends on its take-off and landing, and each stop.
    length_s
        The least time of ``length_m`` at the speeds, however it is flown.
    cruise_length_s, return_saving_s, far_m
        ``length_m`` at the cruise speed, what each metre flown home saves on it, and how
        far from home any sortie's leg home starts at most.
    """

    length_m: float
    flight_time_s: float
    sorties: int
    single_m: float
    radius_m: float
    stops: int = 0
    spread: tuple[tuple[int, float], ...] = ()
    ends_s: float = 0.0
    stop_s: float = 0.0
    length_s: float = 0.0
    cruise_length_s: float = 0.0
    return_saving_s: float = 0.0
    far_m: float = math.inf

    def length_time_s(self, count: int) -> float:
        """The least time of the length over ``count`` sorties, each flying at most its leg
        home (at most ``far_m``, and at most half of it) at the return speed."""
        home = min(0.5 * self.length_m, count * self.far_m)
        return max(self.length_s, self.cruise_length_s - self.return_saving_s * home)

    def total_s(self, count: int) -> float:
        """The least total flight time of ``count`` sorties (of at least
        :attr:`sorties`), by the module's text."""
        return (
            count * self.ends_s
            + max(count, self.stops) * self.stop_s
            + max((max(q - count, 0) * extra for q, extra in self.spread), default=0.0)
            + self.length_time_s(count)
        )

    def least_s(self, at_least: int) -> float:
        """The least total flight time of any number of sorties from ``at_least`` (and from
        :attr:`sorties`) up: every term is convex and piecewise linear in the count, and the
        sum rises past its last corner, so it is least at the first count or next to a
        corner (the length's time bends where the legs home reach half the length, and
        where it meets its least)."""
        first = max(at_least, self.sorties)
        bends: list[float] = [float(self.stops), *(float(q) for q, _ in self.spread)]
        slope = self.return_saving_s * self.far_m
        if 0.0 < slope < math.inf:
            bends += [
                0.5 * self.length_m / self.far_m,
                (self.cruise_length_s - self.length_s) / slope,
            ]
        corners = {first, *(f(b) for b in bends for f in (math.floor, math.ceil))}
        return min(self.total_s(k) for k in corners if k >= first)


def least_extra_s(model: FlightModel, gap_m: float) -> float:
    """A lower bound of what a level leg at least ``gap_m`` long takes beyond its length
    over the cruise speed.

    From the cruise length on it is the cruise overhead exactly. Below, the lengths from
    ``gap_m`` up are cut into steps: a leg's time only grows with its length, so on a step
    ``[a, b]`` the leg takes at least ``leg_s(a) - b / cruise`` beyond its length's share.

    Parameters
    ----------
    model
        The vehicle's flight model.
    gap_m
        The least length of the legs.

    Returns
    -------
    float
        Seconds, never negative.
    """
    leg_from, extra = model.cruise_overhead()
    if not math.isfinite(leg_from) or gap_m >= leg_from:
        return float(extra)
    d = np.linspace(max(gap_m, 0.0), leg_from, _EXTRA_STEPS + 1)
    steps = np.asarray(model.leg_s(d[:-1])) - d[1:] / model.cruise_m_s
    return float(max(min(float(steps.min()), extra), 0.0))


def star_distances(stars: tuple[OuterStar, ...], home_xy: tuple[float, float]) -> FloatArray:
    """The least distance from home to a point of each star, sector by sector.

    A sector spans the angles ``[t0, t1]`` around the centre ``c`` out to its reach ``R``.
    With home at distance ``d`` and angle ``phi`` from ``c``, and ``a`` the angle from ``phi``
    to the sector (0 inside it), the sector's points at distance ``s`` from ``c`` are at least
    ``sqrt(d^2 + s^2 - 2 s d cos a)`` from home: the least over ``s`` in ``[0, R]`` is at
    ``s = min(d cos a, R)`` when ``cos a > 0``, else at the centre.

    Parameters
    ----------
    stars
        The regions' outer stars.
    home_xy
        Home.

    Returns
    -------
    FloatArray
        One distance per star.
    """
    out = np.empty(len(stars))
    hx, hy = home_xy
    for i, star in enumerate(stars):
        cx, cy = star.center_xy
        d = math.hypot(hx - cx, hy - cy)
        k = star.reach_m.size
        if d == 0.0:
            out[i] = 0.0
            continue
        phi = math.atan2(hy - cy, hx - cx) % (2.0 * math.pi)
        t0 = 2.0 * math.pi * np.arange(k) / k
        t1 = t0 + 2.0 * math.pi / k
        inside = (phi >= t0) & (phi <= t1)
        gap = np.minimum(_angle(phi - t0), _angle(phi - t1))
        a = np.where(inside, 0.0, gap)
        cos_a = np.cos(a)
        s = np.clip(d * cos_a, 0.0, star.reach_m)
        dist2 = d * d + s * s - 2.0 * s * d * cos_a
        out[i] = math.sqrt(max(float(dist2.min()), 0.0))
    # A hair under the exact figure, so that rounding cannot make a distance too large.
    return np.maximum(out * (1.0 - 1e-12) - 1e-9, 0.0)


def _angle(x: FloatArray) -> FloatArray:
    """The absolute angle of ``x`` folded into ``[0, pi]``."""
    y = np.abs(np.asarray(x)) % (2.0 * math.pi)
    out: FloatArray = np.minimum(y, 2.0 * math.pi - y)
    return out


def sortie_bound(
    centres_xy: FloatArray,
    reach_m: FloatArray,
    home_distance_m: FloatArray,
    single_m: float,
    budget: SortieBudget,
    upper_m: float = math.inf,
    time_limit_s: float = 0.0,
    returns_bound: Callable[[int, float], float] | None = None,
) -> SortieBound:
    """The lower bound of the module's text for sorties over regions inside circles; where
    at least two sorties are needed, also the K-tree bound of their length
    (:func:`~urpt_gcs.bound.k_tree.k_tree_bound`), the larger kept.

    Parameters
    ----------
    centres_xy, reach_m
        Per region, a circle that holds it: every point that photographs the region's
        target lies within ``reach_m`` of its centre.
    home_distance_m
        Per region, the least distance from home to its points (at most that to its circle).
    single_m
        A lower bound of every closed flight from home that photographs every target.
    budget
        What one sortie may spend.
    upper_m
        The length of a known flight, where the K-tree's ascent aims and stops.
    time_limit_s
        Seconds for the K-tree's ascent (its first round always runs), and for
        ``returns_bound``.
    returns_bound
        Where given, ``returns_bound(k, seconds)`` bounds every closed flight from home that
        photographs every target in at least ``k`` sorties, none of them empty (as
        :func:`~urpt_gcs.bound.lower_bound.returns_bound` does over the regions themselves):
        where two sorties or more are proven it takes half the time, over the count the
        K-tree leaves, and the larger is kept.

    Returns
    -------
    SortieBound
        The bound. With no regions, the single-tour bound and no sortie.
    """
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    reach = np.asarray(reach_m, dtype=np.float64)
    r = np.asarray(home_distance_m, dtype=np.float64)
    n = len(xy)
    if n == 0:
        return SortieBound(single_m, 0.0, 0, single_m, 0.0)
    order = np.argsort(r, kind="stable")
    picks = np.unique(np.linspace(0, n - 1, min(THRESHOLDS, n)).round().astype(np.int64))
    radii = np.concatenate([[0.0], r[order[picks]]])
    radii = np.unique(radii)
    pair = _PairDistances(xy, reach)
    # Regions apart, chosen farthest first: those beyond any radius are apart too.
    farthest = np.argsort(-r, kind="stable")
    apart_r = np.sort(r[farthest[_apart(xy[farthest], reach[farthest], 0.0)]])
    weights = stop_packing(xy, reach)
    by_r = np.argsort(r, kind="stable")
    weight_r, beyond_w = r[by_r], np.cumsum(weights[by_r][::-1])[::-1]
    chains = [
        (
            np.sort(r[farthest[_apart(xy[farthest], reach[farthest], gap)]]),
            np.cumsum(stop_packing(xy, reach + gap)[by_r][::-1])[::-1]
            if n <= PACKING_LP_MAX_CIRCLES
            else np.zeros(n),
            extra,
        )
        for gap, extra in budget.chains
        if extra > 0.0
    ]

    def beyond(rho: float) -> tuple[float, list[tuple[int, float]]]:
        """Stops at least, and per gap the regions apart, beyond ``rho``."""
        first = int(np.searchsorted(weight_r, rho, side="left"))
        packed = float(beyond_w[first]) if first < beyond_w.size else 0.0
        apart = apart_r.size - int(np.searchsorted(apart_r, rho, side="left"))
        spread = [
            (
                max(
                    far_r.size - int(np.searchsorted(far_r, rho, side="left")),
                    math.ceil(float(widened[first]) - _EPS) if first < widened.size else 0,
                ),
                extra,
            )
            for far_r, widened, extra in chains
        ]
        return max(float(apart), packed), spread

    counts = np.zeros(radii.size)
    trees = np.zeros(radii.size)
    for m, rho in enumerate(radii.tolist()):
        far = np.flatnonzero(r >= rho)
        if far.size == 0:
            continue
        trees[m] = pair.tree(far, r[far] - rho)
        work = max(trees[m], single_m) if rho == 0.0 else trees[m]
        stops_far, spread_far = beyond(rho)
        counts[m] = _far_sorties(work, rho, stops_far, spread_far, budget)
    # A sortie that reaches past a radius reaches past every smaller one too; and every
    # sortie reaches the nearest region, so up to its distance all of them count.
    counts = np.maximum.accumulate(counts[::-1])[::-1]
    tree = 0.0
    if counts[0] >= 2:
        # The K-tree over the count proven; its length, a bound of every flight, may prove
        # more sorties, and more sorties a longer K-tree.
        stops_all, spread_all = beyond(0.0)

        def recount(length_m: float) -> int:
            return _far_sorties(max(length_m, single_m), 0.0, stops_all, spread_all, budget)

        started = time.perf_counter()
        share = time_limit_s if returns_bound is None else 0.5 * time_limit_s
        tree, k = k_tree_bound(xy, reach, r, int(counts[0]), upper_m, share, recount)
        counts[0] = max(counts[0], k)
        if returns_bound is not None:
            left = max(time_limit_s - (time.perf_counter() - started), 0.0)
            homes = min(returns_bound(int(counts[0]), left), upper_m)
            tree = max(tree, homes)
            counts[0] = max(counts[0], recount(homes))
    counts[radii <= r.min()] = counts[0]
    best, at = max(single_m, tree), 0.0
    inside = 0.0
    for m in range(1, radii.size):
        inside += 2.0 * counts[m] * (radii[m] - radii[m - 1])
        if inside + trees[m] > best:
            best, at = inside + trees[m], float(radii[m])
    packed, spread = beyond(0.0)
    out = SortieBound(
        length_m=float(best),
        flight_time_s=0.0,
        sorties=int(counts[0]),
        single_m=float(single_m),
        radius_m=at,
        stops=math.ceil(packed - _EPS),
        spread=tuple(spread),
        ends_s=budget.ends_s,
        stop_s=budget.stop_s,
        length_s=budget.per_metre_s * float(best),
        cruise_length_s=budget.cruise_per_metre_s * float(best),
        return_saving_s=max(budget.cruise_per_metre_s - budget.return_per_metre_s, 0.0),
        far_m=float(np.max(r + 2.0 * reach)),
    )
    return dataclasses.replace(out, flight_time_s=float(out.least_s(out.sorties)))


def _far_sorties(
    work_m: float, rho: float, stops: float, spread: list[tuple[int, float]], budget: SortieBudget
) -> int:
    """How many sorties at least photograph the regions beyond ``rho``, which need
    ``work_m`` of flight outside the disc of that radius and ``stops`` stops, with per gap
    ``(Q, F)`` the stops that far apart and what each chain between them spends beyond its
    length's share."""
    h = budget.per_metre_s
    one_stop = budget.endurance_s - budget.ends_s - budget.stop_s - 2.0 * h * rho
    if one_stop <= 0.0:
        # No sortie can reach that far and photograph: no plan exists, and none is bounded.
        return 1
    holds = budget.endurance_s - budget.ends_s - 2.0 * h * rho
    need = max(h * work_m / one_stop, (stops * budget.stop_s + h * work_m) / holds, 1.0)
    for q, extra in spread:
        need = max(need, (stops * budget.stop_s + q * extra + h * work_m) / (holds + extra))
    return math.ceil(need - _EPS)


class _PairDistances:
    """Minimum spanning trees over the disc node and regions, by their enclosing circles."""

    def __init__(self, xy: FloatArray, reach: FloatArray) -> None:
        self.xy = xy
        self.reach = reach
        self.dense = len(xy) <= DENSE_MAX_REGIONS
        if self.dense:
            d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
            self.w = np.maximum(d - reach[:, None] - reach[None, :], 0.0)

    def tree(self, idx: np.ndarray, to_disc_m: FloatArray) -> float:
        """The minimum spanning tree over node 0 (the disc) and regions ``idx``, with
        ``to_disc_m`` from each to the disc. Every weight is raised by one for the sparse
        routine (which reads a zero as no edge) and the tree lowered by as much after: every
        spanning tree has as many edges."""
        k = idx.size
        to_disc = np.maximum(np.asarray(to_disc_m, dtype=np.float64), 0.0)
        if self.dense:
            w = np.empty((k + 1, k + 1))
            w[0, 0] = 0.0
            w[0, 1:] = w[1:, 0] = to_disc
            w[1:, 1:] = self.w[np.ix_(idx, idx)]
            w += 1.0
            np.fill_diagonal(w, 0.0)
            tree = minimum_spanning_tree(w)
        else:
            rows, cols, vals = self._sparse_edges(idx)
            rows = np.concatenate([rows + 1, np.zeros(k, dtype=np.int64)])
            cols = np.concatenate([cols + 1, np.arange(1, k + 1)])
            vals = np.concatenate([vals, to_disc]) + 1.0
            tree = minimum_spanning_tree(coo_matrix((vals, (rows, cols)), shape=(k + 1, k + 1)))
        total = float(tree.sum()) - k
        # A hair under, so that rounding cannot make it too large.
        return max(total * (1.0 - 1e-12) - 1e-9 * (k + 1), 0.0)

    def _sparse_edges(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, FloatArray]:
        """Edges of the centres' Delaunay triangulation, each weighing the distance less
        twice the widest reach: a weight that only grows with the distance, so the Euclidean
        tree (which lies in the triangulation) is the least one for it too."""
        pts = self.xy[idx]
        widest = float(self.reach[idx].max())
        k = idx.size
        if k < 3:
            a, b = np.triu_indices(k, 1)
        else:
            try:
                triangulation = Delaunay(pts)
                simplices = triangulation.simplices
            except QhullError:  # collinear or repeated centres: every pair
                a, b = np.triu_indices(k, 1)
            else:
                # Qhull leaves repeated centres out of every triangle: each joins the one it
                # repeats (or the nearest vertex), by an edge of its own length.
                twins = np.asarray(triangulation.coplanar, dtype=np.int64).reshape(-1, 3)[:, [0, 2]]
                e = np.vstack(
                    [simplices[:, [0, 1]], simplices[:, [1, 2]], simplices[:, [0, 2]], twins]
                )
                e = np.unique(np.sort(e, axis=1), axis=0)
                a, b = e[:, 0], e[:, 1]
        d = np.hypot(*(pts[a] - pts[b]).T)
        return a.astype(np.int64), b.astype(np.int64), np.maximum(d - 2.0 * widest, 0.0)


def _apart(xy: FloatArray, reach: FloatArray, gap_m: float) -> list[int]:
    """A set of regions whose circles lie more than ``gap_m`` apart (greedy, in the given
    order): the points that photograph two of them are more than ``gap_m`` apart (with
    ``gap_m`` 0: no point photographs two of them). None with an infinite gap."""
    if len(xy) == 0 or not math.isfinite(gap_m):
        return []
    tree = cKDTree(xy)
    widest = float(reach.max())
    taken: list[int] = []
    is_taken = np.zeros(len(xy), dtype=bool)
    for i in range(len(xy)):
        near = tree.query_ball_point(xy[i], reach[i] + widest + gap_m + 1e-6)
        clash = False
        for j in near:
            if is_taken[j] and math.hypot(*(xy[i] - xy[j])) <= reach[i] + reach[j] + gap_m + 1e-9:
                clash = True
                break
        if not clash:
            is_taken[i] = True
            taken.append(i)
    return taken
