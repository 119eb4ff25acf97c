"""Geometric lower bounds of a planning instance: the disc packing and the depot's reach.

Every region a tour must enter lies inside the disc of its target's cone radius, so bounds
over those discs hold for every tour, over the instance's viewpoints or anywhere on the plane.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.instance import Instance

__all__ = [
    "DISC_PACKING_ALPHA",
    "depot_bound",
    "disc_packing_bound",
    "geometric_lower_bound",
    "greedy_disjoint",
]

# Tekdas et al.: a tour through k disjoint discs of radius r is at least k/2 * alpha * r (k >= 3).
DISC_PACKING_ALPHA = 0.4786


def greedy_disjoint(centers_xy: FloatArray, radius_m: float) -> list[int]:
    """A maximal set of pairwise disjoint discs of one radius (greedy in index order,
    deterministic): a disc is taken unless one already taken lies within twice the radius.
    Neighbours come from a k-d tree, with a hair of slack so that rounding never lets two
    discs that touch count as disjoint."""
    pts = np.asarray(centers_xy, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return []
    tree = cKDTree(pts)
    taken = np.zeros(len(pts), dtype=bool)
    reach = 2.0 * radius_m * (1.0 + 1e-9) + 1e-9
    for i, near in enumerate(tree.query_ball_point(pts, reach)):
        if not taken[near].any():
            taken[i] = True
    return [int(i) for i in np.flatnonzero(taken)]


def disc_packing_bound(targets_xy: FloatArray, cone_radius_m: FloatArray) -> float:
    """The paper's bound ``k/2 * alpha * R`` from k disjoint outer discs of radius R.

    Every region lies inside the disc of its own cone radius, hence inside the disc of radius
    ``R = max`` cone radius around its target; a tour visiting every region visits these
    discs. Valid for k >= 3 disjoint discs, else 0.
    """
    if len(targets_xy) == 0:
        return 0.0
    radius = float(np.max(cone_radius_m))
    k = len(greedy_disjoint(targets_xy, radius))
    return 0.5 * k * DISC_PACKING_ALPHA * radius if k >= 3 else 0.0


def depot_bound(
    depot_xy: tuple[float, float], targets_xy: FloatArray, cone_radius_m: FloatArray
) -> float:
    """Twice the distance from the depot to the farthest region's enclosing disc."""
    if len(targets_xy) == 0:
        return 0.0
    d = np.hypot(targets_xy[:, 0] - depot_xy[0], targets_xy[:, 1] - depot_xy[1])
    return float(2.0 * np.max(np.maximum(d - cone_radius_m, 0.0)))


def geometric_lower_bound(instance: Instance) -> float:
    """The best geometric lower bound for an instance with geometry (else 0)."""
    g = instance.geometry
    if g is None:
        return 0.0
    cone = g.cone_radius_m
    bound = disc_packing_bound(g.targets_xy, cone)
    if instance.depot_xy is not None:
        bound = max(bound, depot_bound(instance.depot_xy, g.targets_xy, cone))
    return bound
