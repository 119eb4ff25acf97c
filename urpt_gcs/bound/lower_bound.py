"""A certified lower bound for the continuous problem: every tour entering every region.

The bound :func:`lower_bound` reports by default is the branch and bound over visiting orders
of :mod:`urpt_gcs.bound.order_bound` (fixed-order relaxations over convex supersets of the
regions, each node certified by weak duality), over a subset far apart where the regions are
many; or the Lagrangian 1-tree of :mod:`urpt_gcs.bound.one_tree` over every region where the
order search stops short and the 1-tree is larger (small regions far apart); or the tube
bound of :mod:`urpt_gcs.bound.tube` over them all where it is larger (where regions crowd).
The older, weaker bounds (``method="pieces"``, ``"exact"`` or ``"lagrangian"``) relax the
regions into pieces (:mod:`urpt_gcs.bound.pieces`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from scipy.sparse.csgraph import minimum_spanning_tree
from shapely.geometry import Polygon

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import circle_gaps
from urpt_gcs.bound.one_tree import one_tree_bound
from urpt_gcs.bound.order_bound import order_bound
from urpt_gcs.bound.pieces import (
    EXACT_WORK,
    ROUND_ITERATIONS,
    exact_relaxed,
    exact_work,
    lagrangian,
    near_lists,
    skipped_regions,
    split,
    star_discs,
    start_pieces,
)
from urpt_gcs.bound.tube import tube_bound
from urpt_gcs.problem.regions import OuterStar, RegionSet

__all__ = [
    "EXACT_MAX_REGIONS",
    "ORDER_MAX_REGIONS",
    "RETURNS_MAX_REGIONS",
    "Bound",
    "lower_bound",
    "returns_bound",
    "sorties_through",
    "spread_order",
    "spread_subset",
    "subset_bound",
    "tube_over",
    "warm_up",
    "with_tube",
]

I64 = npt.NDArray[np.int64]

# Regions beside the depot from which the exact relaxed optimum is out of reach.
EXACT_MAX_REGIONS = 9
# Regions the order search of method "auto" takes at most: beyond, it bounds that many far
# apart (every tour enters those too) and the 1-tree bound covers them all.
ORDER_MAX_REGIONS = 150
# Regions up to which a plan's sortie bound also runs the order search with the depot's
# copies (:func:`returns_bound`): it branches on every region between two passes home.
RETURNS_MAX_REGIONS = 40
# Share of the time the 1-tree bound over every region takes when both run.
_ONE_TREE_SHARE = 0.25
# Up to ORDER_MAX_REGIONS regions, the 1-tree runs beside the order search only where the
# spanning tree of the gaps between the regions' discs is at least this share of that of
# their centres: where they crowd (a lower share) its relaxation, which gains the regions'
# whole width at every turn, is the weaker and the order search keeps all the time
# (benchmarks/README.md, "The certified bound on the classic CETSP instances").
_FAR_APART = 0.7


@dataclass(frozen=True, slots=True)
class Bound:
    """A certified lower bound, how it was reached, and the pieces it ended on."""

    value: float
    method: str
    rounds: int
    n_pieces: int
    seconds: float
    # The order search (:mod:`urpt_gcs.bound.order_bound`): nodes solved, left open, and
    # whether it finished (then ``value`` is, to the gap target, the optimum of the star
    # relaxation or the known tour's length).
    order_nodes: int = 0
    order_open: int = 0
    order_finished: bool = False
    # The shortest closed polyline the order search met that meets every set it bounded:
    # a tour of the problem itself for discs and for polygons bounded with exact_shapes.
    relaxed_tour_m: float = math.inf
    # That polyline's points, in order (None when the search met none).
    relaxed_tour_xy: FloatArray | None = None


def lower_bound(
    regions: RegionSet,
    upper: float,
    time_limit_s: float,
    gap_target: float = 1e-4,
    method: str = "auto",
    exact_shapes: bool = False,
) -> Bound:
    """A lower bound of every closed tour (through the depot, if any) entering every region.

    Parameters
    ----------
    regions
        The regions (their outer stars are what is bounded) and the depot.
    upper
        The length of a known tour: the bound never needs to pass it, and the Lagrangian's
        step sizes aim at it.
    time_limit_s
        Seconds to spend refining pieces; the first round always completes.
    gap_target
        Stop once ``(upper - bound) / bound`` is at most this.
    method
        ``order``: branch and bound over visiting orders (:func:`order_bound`); ``auto``:
        that (and where it stops short unfinished, the 1-tree bound over every region in the
        time left, the larger kept), and beyond :data:`ORDER_MAX_REGIONS` regions the larger
        of the order search over that many far apart and the 1-tree bound over all of them
        (:func:`~urpt_gcs.bound.one_tree.one_tree_bound`, alone: ``one-tree``); and with
        either, the tube bound over every region (:func:`~urpt_gcs.bound.tube.tube_bound`),
        the largest of them kept; ``exact`` or
        ``lagrangian`` for the relaxed piece problem (small instances); ``pieces``: exact
        for a few regions, else the Lagrangian and the exact optimum over a subset far apart.
    exact_shapes
        The polygons are the regions themselves, not only inside them: the order search
        bounds the polygons (tighter than their outer stars). Leave it False when the outer
        stars are the only sets known to hold the regions (regions on terrain).
    """
    if method in ("auto", "order", "one-tree"):
        warm_up()  # compiled outside the clock
    started = time.perf_counter()
    kept = int(np.count_nonzero(~skipped_regions(regions)))
    if method == "auto":
        tube = tube_over(regions)
        left = max(time_limit_s - (time.perf_counter() - started), 0.0)
        if kept <= ORDER_MAX_REGIONS:
            found = _order_then_one_tree(regions, upper, left, gap_target, exact_shapes)
        else:
            found = _all_regions(regions, upper, left, gap_target, exact_shapes, method)
        found = with_tube(found, tube, regions, upper)
        return replace(found, seconds=time.perf_counter() - started)
    if method == "order":
        return _order(regions, upper, time_limit_s, gap_target, exact_shapes)
    if method == "one-tree":
        return _all_regions(regions, upper, time_limit_s, gap_target, exact_shapes, method)
    pieces, boundary = start_pieces(regions)
    skip = skipped_regions(regions)
    stars: list[OuterStar | None] = [s for s, k in zip(regions.outer, skip, strict=True) if not k]
    if regions.depot_xy is not None:
        stars.append(None)
    m = len(stars)
    if m <= 1:
        return Bound(0.0, "single region", 0, pieces.n, 0.0)
    exact = m - 1 <= EXACT_MAX_REGIONS and exact_work(pieces, m) <= EXACT_WORK
    exact = method == "exact" or (exact and method == "pieces")
    mu = np.zeros(pieces.n)
    best = 0.0
    rounds = 0
    while True:
        if exact:
            value, used = exact_relaxed(pieces, m)
        else:
            mx, my, rho = pieces.circles()
            dreg, ptr, near = near_lists(pieces, m)
            start = np.searchsorted(pieces.region, np.arange(m + 1)).astype(np.int64)
            used = np.zeros(pieces.n, dtype=np.bool_)
            value = lagrangian(
                pieces.region, start, mx, my, rho, dreg, ptr, near, mu, upper,
                ROUND_ITERATIONS, used,
            )  # fmt: skip
        rounds += 1
        best = max(best, value)
        spent = time.perf_counter() - started
        # Without the exact optimum, half the time is kept for the subset bound.
        own_limit = time_limit_s if exact or method != "pieces" else 0.5 * time_limit_s
        if upper - best <= gap_target * best or spent >= own_limit or not used.any():
            break
        finer, parent = split(pieces, used, stars, boundary)
        if finer.n == pieces.n or (exact and exact_work(finer, m) > EXACT_WORK):
            break
        pieces = finer
        # A half keeps its parent's multiplier: the bound at the old multipliers can only rise.
        mu = np.ascontiguousarray(mu[parent])
    method = "exact" if exact else "lagrangian"
    if method == "pieces" and not exact:
        left = time_limit_s - (time.perf_counter() - started)
        sub = subset_bound(regions, upper, max(left, 0.0), gap_target)
        if sub.value > best:
            best, method = sub.value, f"subset of {EXACT_MAX_REGIONS}"
        rounds += sub.rounds
    return Bound(min(best, upper), method, rounds, pieces.n, time.perf_counter() - started)


def tube_over(regions: RegionSet) -> float:
    """The tube bound (:func:`~urpt_gcs.bound.tube.tube_bound`) over every region's
    enclosing disc, and the depot."""
    cx, cy, cr = star_discs(regions)
    tube, _ = tube_bound(np.column_stack([cx, cy]), cr, regions.depot_xy)
    return tube


def with_tube(found: Bound, tube_m: float, regions: RegionSet, upper: float) -> Bound:
    """``found``, or the tube bound ``tube_m`` over every region where it is larger (never
    past the known tour ``upper``)."""
    if tube_m <= found.value:
        return found
    return replace(found, value=min(tube_m, upper), method=f"tube over all {regions.n}")


def spread_subset(regions: RegionSet, k: int) -> list[int]:
    """``k`` regions far apart (farthest-point order by the distance between enclosing
    discs), starting from the one farthest from the depot (or from region 0); regions that
    hold the depot are left out."""
    cx, cy, cr = star_discs(regions)
    return spread_order(
        np.column_stack([cx, cy]), cr, regions.depot_xy, k, skipped_regions(regions)
    )


def spread_order(
    xy: FloatArray,
    radius_m: FloatArray,
    depot_xy: tuple[float, float] | None,
    k: int,
    skip: npt.NDArray[np.bool_] | None = None,
) -> list[int]:
    """``k`` of the discs (centres ``xy``, radii ``radius_m``) far apart: farthest-point
    order by the gap between discs, starting from the disc farthest from the depot (or from
    disc 0), those ``skip`` marks left out."""
    cx, cy = xy[:, 0], xy[:, 1]
    cr = np.asarray(radius_m, dtype=np.float64)
    skip = np.zeros(len(cr), dtype=np.bool_) if skip is None else skip
    if depot_xy is not None:
        gap = np.hypot(cx - depot_xy[0], cy - depot_xy[1]) - cr
    else:
        gap = np.hypot(cx - cx[0], cy - cy[0]) - cr - cr[0]
    gap = np.where(skip, -np.inf, gap)
    chosen: list[int] = []
    for _ in range(min(k, int(np.count_nonzero(~skip)))):
        j = int(np.argmax(gap))
        chosen.append(j)
        d = np.hypot(cx - cx[j], cy - cy[j]) - cr - cr[j]
        gap = np.minimum(gap, d)
        gap[chosen] = -np.inf
    return chosen


def subset_bound(
    regions: RegionSet, upper: float, time_limit_s: float, gap_target: float = 1e-4
) -> Bound:
    """The relaxed optimum over a few regions far apart: every tour enters those too."""
    sub = _subset(regions, spread_subset(regions, EXACT_MAX_REGIONS))
    return lower_bound(sub, upper, time_limit_s, gap_target, method="pieces")


def _subset(regions: RegionSet, chosen: list[int]) -> RegionSet:
    """The regions ``chosen`` (none holding the depot), with the same depot."""
    return RegionSet(
        discs=None if regions.discs is None else regions.discs[chosen],
        polygons=None if regions.polygons is None else tuple(regions.polygons[i] for i in chosen),
        depot_xy=regions.depot_xy,
        outer=tuple(regions.outer[i] for i in chosen),
        depot_inside=tuple(False for _ in chosen),
        name=regions.name,
    )


def _all_regions(
    regions: RegionSet,
    upper: float,
    time_limit_s: float,
    gap_target: float,
    exact_shapes: bool,
    method: str,
) -> Bound:
    """The 1-tree bound over every region and, for ``auto``, the order search over
    :data:`ORDER_MAX_REGIONS` of them far apart: the larger (both hold, so does it)."""
    started = time.perf_counter()
    share = 1.0 if method == "one-tree" else _ONE_TREE_SHARE
    found = _one_tree(regions, upper, share * time_limit_s, gap_target)
    kept = int(np.count_nonzero(~skipped_regions(regions)))
    if method == "auto" and upper - found.value > gap_target * found.value:
        chosen = sorted(spread_subset(regions, ORDER_MAX_REGIONS))
        sub = _subset(regions, chosen)
        left = max(time_limit_s - (time.perf_counter() - started), 0.0)
        order = _order(sub, upper, left, gap_target, exact_shapes)
        if order.value > found.value:
            found = replace(order, method=f"order over {len(chosen)} of {kept} far apart")
        else:
            found = replace(
                found,
                order_nodes=order.order_nodes,
                order_open=order.order_open,
                relaxed_tour_m=order.relaxed_tour_m,
                relaxed_tour_xy=order.relaxed_tour_xy,
            )
    return replace(found, seconds=time.perf_counter() - started)


def _one_tree(regions: RegionSet, upper: float, time_limit_s: float, gap_target: float) -> Bound:
    """The 1-tree bound over every region's pieces (the first round whatever the clock)."""
    pieces, _ = start_pieces(regions)
    m = int(pieces.region[-1]) + 1
    value, rounds = one_tree_bound(pieces, m, upper, time_limit_s, gap_target)
    kept = m - (regions.depot_xy is not None)
    return Bound(min(value, upper), f"one-tree over all {kept}", rounds, pieces.n, 0.0)


def _order_then_one_tree(
    regions: RegionSet, upper: float, time_limit_s: float, gap_target: float, exact_shapes: bool
) -> Bound:
    """The order search over every region; where it stops short of the gap target without
    finishing, the 1-tree over them all in the time left (at least its share), the larger
    kept. Over small regions far apart (where tours barely bend at each) the 1-tree is
    Held-Karp's bound on nearly points, which the order search reaches only by finishing."""
    started = time.perf_counter()
    if not _far_apart(regions):
        return _order(regions, upper, time_limit_s, gap_target, exact_shapes)
    found = _order(regions, upper, (1.0 - _ONE_TREE_SHARE) * time_limit_s, gap_target, exact_shapes)
    if found.order_finished or upper - found.value <= gap_target * found.value:
        return found
    left = max(time_limit_s - (time.perf_counter() - started), 0.0)
    tree = _one_tree(regions, upper, left, gap_target)
    if tree.value > found.value:
        return replace(found, value=tree.value, method=tree.method, rounds=tree.rounds)
    return found


def _far_apart(regions: RegionSet) -> bool:
    """Whether the regions kept lie far apart for their size: the spanning tree of the gaps
    between their enclosing discs is at least :data:`_FAR_APART` of the spanning tree of
    their centres (quadratic in the regions: for the few the order search takes)."""
    cx, cy, cr = star_discs(regions)
    kept = ~skipped_regions(regions)
    xy = np.column_stack([cx[kept], cy[kept]])
    if regions.depot_xy is not None:
        xy = np.vstack([xy, regions.depot_xy])
    r = np.append(cr[kept], 0.0) if regions.depot_xy is not None else cr[kept]
    if len(r) < 3:
        return False
    centres = circle_gaps(xy, np.zeros(len(r)))
    # A hair above zero: the spanning tree leaves out edges of weight 0 as missing.
    gaps = circle_gaps(xy, r) + 1e-12 * (1.0 + centres.max())
    np.fill_diagonal(gaps, 0.0)
    whole = float(minimum_spanning_tree(centres).sum())
    return whole > 0.0 and float(minimum_spanning_tree(gaps).sum()) >= _FAR_APART * whole


def sorties_through(regions: RegionSet, upper: float) -> Callable[[int, float], float] | None:
    """For :func:`urpt_gcs.bound.sorties.sortie_bound`: the bound of flights of at least
    ``k`` sorties from the depot by :func:`returns_bound`, given ``seconds``; None beyond
    :data:`RETURNS_MAX_REGIONS` regions or without a depot."""
    kept = int(np.count_nonzero(~skipped_regions(regions)))
    if regions.depot_xy is None or kept > RETURNS_MAX_REGIONS:
        return None

    def bound(k: int, seconds: float) -> float:
        return returns_bound(regions, upper, seconds, k - 1).value if k >= 2 else 0.0

    return bound


def returns_bound(regions: RegionSet, upper: float, time_limit_s: float, returns: int) -> Bound:
    """A lower bound of every closed flight from the depot entering every region that comes
    back to the depot ``returns`` times on the way, none of its ``returns + 1`` sorties
    empty: the order search over the outer stars with the depot's copies
    (:func:`~urpt_gcs.bound.order_bound.order_bound`'s ``returns``). Holds when stopped by
    the clock; for a few tens of regions (it branches on every region between two passes
    through the depot).

    Raises
    ------
    ValueError
        Without a depot.
    """
    if regions.depot_xy is None:
        raise ValueError("returns_bound: the regions have no depot")
    warm_up()
    found = _order(regions, upper, time_limit_s, 1e-4, False, returns)
    return replace(found, method=f"order with {returns} return{'s' * (returns != 1)} home")


def _order(
    regions: RegionSet,
    upper: float,
    time_limit_s: float,
    gap_target: float,
    exact_shapes: bool,
    returns: int = 0,
) -> Bound:
    started = time.perf_counter()
    skip = skipped_regions(regions)
    kept = np.flatnonzero(~skip)
    stars: list[OuterStar | None] = [regions.outer[i] for i in kept]
    shapes: list[Polygon | None] | None = None
    if exact_shapes and regions.polygons is not None:
        shapes = [regions.polygons[i] for i in kept]
    if regions.depot_xy is not None:
        stars.append(None)
        if shapes is not None:
            shapes.append(None)
    found = order_bound(
        stars, regions.depot_xy, upper, time_limit_s, gap_target, shapes, returns=returns
    )
    return Bound(
        found.value, "order", 0, 0, time.perf_counter() - started,
        found.nodes, found.open_nodes, found.finished, found.leaf_length, found.leaf_xy,
    )  # fmt: skip


# Set once the warm-up has begun: its own bounds must not start it again.
_WARMING: list[bool] = []


def warm_up() -> None:
    """Compile the bound's kernels, or load them from numba's cache, on tiny instances, so
    that a bound's time limit is spent bounding: the order search over a few triangles (stars
    that are not discs take kernels of their own), and the 1-tree over one more disc than
    :data:`ORDER_MAX_REGIONS` (the size from which it runs)."""
    if _WARMING:
        return
    _WARMING.append(True)
    rng = np.random.default_rng(0)
    corners = rng.random((4, 1, 2)) * 200.0 + np.array([[0.0, 0.0], [9.0, 1.0], [2.0, 8.0]])
    triangles = tuple(Polygon(c) for c in corners)
    # Searched to the end, whatever the compiling costs, so that every kernel it runs is met.
    lower_bound(RegionSet(polygons=triangles, depot_xy=(0.0, 0.0)), 2000.0, 60.0)
    n = ORDER_MAX_REGIONS + 1
    discs = np.column_stack([rng.random((n, 2)) * 100.0 * math.sqrt(n), np.full(n, 2.0)])
    lower_bound(RegionSet(discs=discs, depot_xy=(0.0, 0.0)), 2.0 * float(discs.sum()), 0.0)
