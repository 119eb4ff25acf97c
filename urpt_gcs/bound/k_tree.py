"""A Lagrangian K-tree bound of sorties from home: what the returns home add to the length.

Take any sorties from home, at least ``K`` of them, whose stops between them photograph
every target, with none that could be left out (leaving one out only shortens the flight,
and the rest still number at least ``K`` when ``K`` bounds every such flight). Each sortie
then photographs some region no other one does; give every region to one sortie that enters
it, each sortie at least one. Walked in flight order, a sortie's regions form a path from
home and back: its legs between consecutive regions are at least the gaps between their
enclosing circles, its first and last legs at least the regions' distances from home. So the
flight is at least a forest of ``k >= K`` paths over the regions (weighed by those gaps)
plus ``2 k`` legs from home to the paths' ends, a region at most twice (a path of one
region both ways). A minimum spanning forest of ``k`` trees (the minimum spanning tree less
its ``k - 1`` longest edges) is no longer than the paths, and the ``2 k`` shortest of those
legs no longer than theirs: the least over ``k`` bounds the flight.

In that structure every region meets two edges (a path's inside region two legs, its end
one leg and one leg home), so multipliers ``pi`` change nothing of it: weigh each gap
``g_ij + pi_i + pi_j``, each leg home ``h_i + pi_i``, and subtract ``2 sum pi``. Every
``pi`` gives a bound; a subgradient ascent (each region's degree less two) raises it, as
Held and Karp's does for one tour (``K = 1`` is their 1-tree with home the special node).

Dense in the regions (a matrix of their gaps), so for a few thousand at most. Nothing here
sees a raster: regions are centres, reaches and distances from home.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from scipy.sparse.csgraph import minimum_spanning_tree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.geometric import circle_gaps

__all__ = ["K_TREE_MAX_REGIONS", "k_tree_bound"]

# Regions beyond which the bound is not tried (its matrix of gaps is 8 bytes a pair).
K_TREE_MAX_REGIONS = 2000
# Subgradient rounds without a better bound before the step is halved, and the step below
# which the ascent stops.
_STALL = 30
_LEAST_STEP = 1e-4
# Rounding: the bound is lowered by this share of its size.
_ROUNDING = 1e-9


def _round(
    gaps: FloatArray, home: FloatArray, pi: FloatArray, at_least: int
) -> tuple[float, npt.NDArray[np.float64]]:
    """The bound at multipliers ``pi`` (least over the forests of ``at_least`` trees or
    more) and each region's degree in the structure that gives it."""
    n = home.size
    w = gaps + pi[:, None] + pi[None, :]
    # A spanning tree has n - 1 edges whatever their weights, so a shift keeps the tree and
    # its order; it keeps every weight above zero, which the sparse routine takes as none.
    shift = 1.0 - min(float(w.min()), 0.0)
    tree = minimum_spanning_tree(w + shift).tocoo()
    weight = np.asarray(tree.data, dtype=np.float64) - shift
    longest = np.argsort(-weight, kind="stable")
    drop = np.concatenate([[0.0], np.cumsum(weight[longest])])
    legs = np.concatenate([home + pi, home + pi])
    cheapest = np.argsort(legs, kind="stable")
    taken = np.concatenate([[0.0], np.cumsum(legs[cheapest])])
    ks = np.arange(at_least, n + 1)
    values = weight.sum() - drop[ks - 1] + taken[2 * ks] - 2.0 * pi.sum()
    pick = int(np.argmin(values))
    k = int(ks[pick])
    degree = np.zeros(n)
    kept = longest[k - 1 :]
    np.add.at(degree, tree.row[kept], 1.0)
    np.add.at(degree, tree.col[kept], 1.0)
    np.add.at(degree, np.concatenate([np.arange(n), np.arange(n)])[cheapest[: 2 * k]], 1.0)
    return float(values[pick]), degree


def k_tree_bound(
    centres_xy: FloatArray,
    reach_m: FloatArray,
    home_distance_m: FloatArray,
    at_least: int,
    upper_m: float,
    time_limit_s: float,
    recount: Callable[[float], int] | None = None,
) -> tuple[float, int]:
    """The best K-tree bound of the module's text found within ``time_limit_s`` (the first
    round always runs), 0 where it is not tried, and the count of sorties it holds for.

    Parameters
    ----------
    centres_xy, reach_m
        Per region, a circle that holds it.
    home_distance_m
        Per region, the least distance from home to its points.
    at_least
        How many sorties every flight needs at least (``K``).
    upper_m
        The length of a known flight: the ascent aims its steps below it and stops there.
    time_limit_s
        Seconds for the ascent.
    recount
        How many sorties a length proves (every flight being at least the bound, it needs
        at least that many): whenever the bound proves more than ``at_least``, the ascent
        goes on over that many, from the multipliers it has.
    """
    started = time.perf_counter()
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    reach = np.asarray(reach_m, dtype=np.float64)
    home = np.asarray(home_distance_m, dtype=np.float64)
    n = home.size
    if n == 0 or at_least < 1 or at_least > n or n > K_TREE_MAX_REGIONS:
        return 0.0, at_least
    gaps = circle_gaps(xy, reach)
    pi = np.zeros(n)
    best_pi = pi.copy()
    best, step_share, stall = -math.inf, 1.0, 0
    while True:
        value, degree = _round(gaps, home, pi, at_least)
        if value > best:
            best, best_pi[:], stall = value, pi, 0
            more = at_least if recount is None else min(recount(best), n)
            if more > at_least:
                # A longer bound over more sorties: the same multipliers, a fresh step.
                at_least, step_share = more, 1.0
                continue
        else:
            stall += 1
        if best >= upper_m or time.perf_counter() - started >= time_limit_s:
            break
        if stall >= _STALL:
            step_share *= 0.5
            stall = 0
            pi[:] = best_pi
            if step_share < _LEAST_STEP:
                break
            continue
        g = degree - 2.0
        norm = float(g @ g)
        if norm == 0.0:
            break  # every region meets two edges: the structure is a set of sorties
        aim = upper_m if math.isfinite(upper_m) else 1.05 * abs(best) + 1.0
        pi += step_share * max(aim - value, 1e-9 * abs(aim)) / norm * g
    return max(best - _ROUNDING * abs(best), 0.0), at_least
