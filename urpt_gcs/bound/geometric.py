"""Geometric lower bounds of a planning instance: the disc packing and the depot's reach.

Every region a tour must enter lies inside the disc of its target's cone radius, so bounds
over those discs hold for every tour, over the instance's viewpoints or anywhere on the plane.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.instance import Instance

__all__ = [
    "DISC_PACKING_ALPHA",
    "circle_gaps",
    "depot_bound",
    "disc_packing_bound",
    "geometric_lower_bound",
    "greedy_disjoint",
    "stop_packing",
]

# Above this many depth points (where circles cross) the stop packing is left out.
PACKING_MAX_POINTS = 400_000
# Above this many circles the packing's weights are each circle's 1 / deepest depth instead of
# a linear programme's.
PACKING_LP_MAX_CIRCLES = 3000
# Membership slack (relative and absolute, metres): a point a hair outside a circle counts as
# in it, which can only lower the weights.
_IN_REL, _IN_ABS = 1e-9, 1e-6

# Tekdas et al.: a tour through k disjoint discs of radius r is at least k/2 * alpha * r (k >= 3).
DISC_PACKING_ALPHA = 0.4786


def circle_gaps(centres_xy: FloatArray, reach_m: FloatArray) -> FloatArray:
    """The dense matrix of gaps between circles (0 where they meet, and on the diagonal):
    no longer than the distance between any point of one and any point of the other. Each
    reach is taken a hair larger, so that rounding cannot make a gap too long."""
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    reach = np.asarray(reach_m, dtype=np.float64) * (1.0 + 1e-12) + 1e-12
    apart = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    gaps: FloatArray = np.maximum(apart - reach[:, None] - reach[None, :], 0.0)
    np.fill_diagonal(gaps, 0.0)
    return gaps


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


def stop_packing(centres_xy: FloatArray, reach_m: FloatArray) -> FloatArray:
    """Weights ``y >= 0`` of circles such that the circles through any one point weigh at
    most 1 together: then every set of points that meets every circle holds at least
    ``sum(y)`` of them (each point pays for at most 1), and at least ``sum(y[S])`` of them
    meet the circles ``S``.

    The circles holding a point ``p`` hold the whole intersection ``I`` of those circles'
    discs, a convex set. Where two circles bound ``I``, they cross (or touch) at a corner of
    it, which lies in every disc holding ``p``; where one circle alone bounds it, ``I`` is
    that disc, and its rightmost point lies in all of them. So it is enough to check the
    weights at every crossing of two circles and at every circle's rightmost point (a
    point a hair outside a circle counts as in it). The weights solve the linear programme
    ``max sum(y)`` over those checks; above :data:`PACKING_LP_MAX_CIRCLES` circles, each
    circle weighs 1 over the most circles through any of its checked points. The weights
    are scaled down until every check holds as computed. All zero above
    :data:`PACKING_MAX_POINTS` crossings.
    """
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(reach_m, dtype=np.float64)
    n = len(xy)
    if n == 0:
        return np.zeros(0)
    tree = cKDTree(xy)
    widest = float(r.max())
    pairs = tree.query_pairs(2.0 * widest * (1.0 + 1e-9) + 1e-9, output_type="ndarray")
    if 2 * len(pairs) > PACKING_MAX_POINTS:
        return np.zeros(n)
    i, j = pairs[:, 0], pairs[:, 1]
    delta = xy[j] - xy[i]
    d = np.hypot(*delta.T)
    cross = (d > 0.0) & (d <= r[i] + r[j]) & (d >= np.abs(r[i] - r[j]))
    i, j, delta, d = i[cross], j[cross], delta[cross], d[cross]
    u = delta / d[:, None]
    a = (r[i] ** 2 - r[j] ** 2 + d * d) / (2.0 * d)
    h = np.sqrt(np.maximum(r[i] ** 2 - a * a, 0.0))
    foot = xy[i] + a[:, None] * u
    normal = np.column_stack([-u[:, 1], u[:, 0]]) * h[:, None]
    points = np.vstack([foot + normal, foot - normal, xy + np.column_stack([r, np.zeros(n)])])
    near = cKDTree(points).sparse_distance_matrix(
        tree, widest * (1.0 + _IN_REL) + _IN_ABS, output_type="ndarray"
    )
    held = near["v"] <= r[near["j"]] * (1.0 + _IN_REL) + _IN_ABS
    row, col = near["i"][held].astype(np.int64), near["j"][held].astype(np.int64)
    checks = csr_matrix((np.ones(row.size), (row, col)), shape=(len(points), n))
    depth = np.asarray(checks.sum(axis=1)).ravel()
    deepest = np.zeros(n)
    np.maximum.at(deepest, col, depth[row])
    y = 1.0 / np.maximum(deepest, 1.0)
    if n <= PACKING_LP_MAX_CIRCLES:
        solved = linprog(
            -np.ones(n), A_ub=checks, b_ub=np.ones(len(points)), bounds=(0.0, 1.0), method="highs"
        )
        if solved.status == 0 and -solved.fun > y.sum():
            y = np.clip(np.asarray(solved.x, dtype=np.float64), 0.0, 1.0)
    most = float((checks @ y).max())
    if most > 1.0:
        y = y / most
    out: FloatArray = y * (1.0 - 1e-9)
    return out
