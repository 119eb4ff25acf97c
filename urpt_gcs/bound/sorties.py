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
``L >= 2 * integral_0^rho K(s) ds + M(rho)``; the bound is the largest of those and ``B``.

*Time.* A sortie's return leg is no longer than the rest of it, so at most half its length
is flown at the return speed, the rest at the cruise speed (each leg no faster than its
length over its speed): its time is at least ``ends + stops * stop + h * length`` with
``h = min(1 / cruise, (1 / cruise + 1 / return) / 2)`` and ``ends`` the take-off and the
landing. Legs also speed up and brake: a leg of at least ``delta`` (the length from which it
reaches the cruise speed) takes exactly ``c`` more than its length over the speed. Take
regions whose circles lie at least ``delta`` apart, ``Q`` of them: the stops that photograph
them are at least ``delta`` apart, and within a sortie the legs and stops from one such stop
to the next take at least one leg of their total length (a rest-to-rest leg's time is
subadditive: two legs flown one after the other, stopping between, are one way of flying
their sum). So the sorties' legs take at least ``(Q - K) * c`` beyond their length's share,
and the count above holds with ``Q * c`` added to the work and ``c`` to what each sortie
holds. The total flight time is at least
``K * ends + max(K, S) * stop + max(Q - K, 0) * c + h * L``, at the least over the counts
``K`` the bound allows.

Nothing here sees a raster: regions are centres, reaches and distances from home.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError, cKDTree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.regions import OuterStar

__all__ = [
    "DENSE_MAX_REGIONS",
    "THRESHOLDS",
    "SortieBound",
    "SortieBudget",
    "sortie_bound",
    "star_distances",
]

# Radii at which the count of far sorties is bounded (the regions' own distances from home,
# evenly through their order): more is tighter and costs one spanning tree each.
THRESHOLDS = 48
# Up to this many regions the spanning trees use every pair's distance; above, the widest
# reach for every region, whose tree lies in the centres' Delaunay triangulation.
DENSE_MAX_REGIONS = 400
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
    leg_from_m, leg_extra_s
        A leg at least ``leg_from_m`` long takes ``leg_extra_s`` more than its length over
        the cruise speed (speeding up and braking); infinite and 0 to leave that out.
    """

    endurance_s: float
    ends_s: float
    stop_s: float
    per_metre_s: float
    leg_from_m: float = math.inf
    leg_extra_s: float = 0.0

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
        leg_from, leg_extra = model.cruise_overhead()
        return cls(endurance_s, ends, model.stop_s, per_metre, leg_from, leg_extra)

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
        The radius whose count of far sorties gave ``length_m`` (0: the single-tour bound).
    """

    length_m: float
    flight_time_s: float
    sorties: int
    single_m: float
    radius_m: float


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
) -> SortieBound:
    """The lower bound of the module's text for sorties over regions inside circles.

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
    stop_r = np.sort(r[farthest[_apart(xy[farthest], reach[farthest], 0.0)]])
    spread_r = np.sort(r[farthest[_apart(xy[farthest], reach[farthest], budget.leg_from_m)]])
    counts = np.zeros(radii.size)
    trees = np.zeros(radii.size)
    for m, rho in enumerate(radii.tolist()):
        far = np.flatnonzero(r >= rho)
        if far.size == 0:
            continue
        trees[m] = pair.tree(far, r[far] - rho)
        work = max(trees[m], single_m) if rho == 0.0 else trees[m]
        stops = stop_r.size - int(np.searchsorted(stop_r, rho, side="left"))
        spread = spread_r.size - int(np.searchsorted(spread_r, rho, side="left"))
        counts[m] = _far_sorties(work, rho, stops, spread, budget)
    # A sortie that reaches past a radius reaches past every smaller one too; and every
    # sortie reaches the nearest region, so up to its distance all of them count.
    counts = np.maximum.accumulate(counts[::-1])[::-1]
    counts[radii <= r.min()] = counts[0]
    best, at = single_m, 0.0
    inside = 0.0
    for m in range(1, radii.size):
        inside += 2.0 * counts[m] * (radii[m] - radii[m - 1])
        if inside + trees[m] > best:
            best, at = inside + trees[m], float(radii[m])
    sorties = int(counts[0])
    stops, spread = stop_r.size, spread_r.size

    def total_s(k: int) -> float:
        return (
            k * budget.ends_s
            + max(k, stops) * budget.stop_s
            + max(spread - k, 0) * budget.leg_extra_s
            + budget.per_metre_s * best
        )

    # Linear in the count between these, rising past the last: its least is at one of them.
    time_s = min(total_s(k) for k in (sorties, stops, spread) if k >= sorties)
    return SortieBound(float(best), float(time_s), sorties, float(single_m), at)


def _far_sorties(work_m: float, rho: float, stops: int, spread: int, budget: SortieBudget) -> int:
    """How many sorties at least photograph the regions beyond ``rho``, which need
    ``work_m`` of flight outside the disc of that radius, ``stops`` stops and ``spread`` stops
    whose legs between them reach the cruise speed."""
    h, c = budget.per_metre_s, budget.leg_extra_s
    one_stop = budget.endurance_s - budget.ends_s - budget.stop_s - 2.0 * h * rho
    all_stops = budget.endurance_s - budget.ends_s - 2.0 * h * rho + c
    if one_stop <= 0.0:
        # No sortie can reach that far and photograph: no plan exists, and none is bounded.
        return 1
    work_s = stops * budget.stop_s + spread * c + h * work_m
    need = max(h * work_m / one_stop, work_s / all_stops, 1.0)
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
