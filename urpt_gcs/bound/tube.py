"""The tube bound: a lower bound of every flight that enters every region, from area alone.

Sweep a disc of radius ``s`` along a curve of length ``L``: it starts with area ``pi s^2``,
and moving its centre by ``d`` adds at most ``2 s d`` (the new lune lies in a ``2 s`` wide
band ``d`` long). So the points within ``s`` of the curve, its tube, cover at most
``pi s^2 + 2 s L``. Several closed curves from one home sweep on from where the last
ended, so the same holds for their total length (a fleet, or sorties, from one home).

A flight enters region ``i``, which lies within ``R_i`` of its centre ``c_i`` (the widest
reach of its outer star), at some point ``p``; the tube holds the disc of radius ``s``
about ``p``, hence the disc of radius ``s - R_i`` about ``c_i``. It holds the disc of radius
``s`` about home too. So for every ``s``::

    L >= (area of the union of those discs - pi s^2) / (2 s)

It counts every region at once and needs no tour; it is strongest where regions crowd
(many overlap, so the 1-tree's edges are all near zero), which is where the order search
over a few far apart is weakest.

The union's area is exact (Green's theorem over its boundary, which is made of arcs of the
circles: on each circle, the arcs no other disc covers), computed in time linear in the
pairs of discs that overlap, and lowered by a share far above its rounding.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray

__all__ = ["TUBE_MAX_PAIRS", "tube_bound", "union_area"]

# Ratios of the tube's radius to the regions' median reach, tried from the smallest up until
# the bound has fallen twice in a row past its best (it rises while the discs grow into the
# gaps between them and falls once they cover the site); the best is then refined between
# its neighbours.
_RATIOS = (1.1, 1.3, 1.6, 2.0, 2.5, 3.2, 4.0, 5.5, 8.0)
_FALLS = 2
_REFINE_STEPS = 4
# A radius whose discs overlap in more pairs than this is not tried, nor any larger (the
# pairs' arrays take some 90 bytes each).
TUBE_MAX_PAIRS = 2_000_000
# The union's area is lowered by this share: its rounding is many orders smaller.
_AREA_SLACK = 1e-7


def tube_bound(
    centres_xy: FloatArray, reach_m: FloatArray, depot_xy: tuple[float, float] | None = None
) -> tuple[float, float]:
    """The best tube bound over the radii tried, and that radius (0 and 0 if none is
    positive).

    Parameters
    ----------
    centres_xy
        Each region's centre, shape (n, 2).
    reach_m
        How far from its centre each region reaches at most.
    depot_xy
        Home, which every flight passes through, or None.
    """
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    reach = np.asarray(reach_m, dtype=np.float64).reshape(-1)
    if len(xy) == 0:
        return 0.0, 0.0
    if depot_xy is not None:
        # Home is a region of reach 0 that every flight enters.
        xy = np.vstack([xy, np.asarray(depot_xy, dtype=np.float64).reshape(1, 2)])
        reach = np.append(reach, 0.0)
    scale = float(np.median(reach))
    if scale <= 0.0:
        scale = max(float(reach.max()), 1.0)
    tried: dict[float, float] = {}

    def at(s: float) -> float:
        if s not in tried:
            area = union_area(xy, s - reach)
            # NaN (too many pairs to list) stays NaN.
            tried[s] = area if math.isnan(area) else max((area - math.pi * s * s) / (2.0 * s), 0.0)
        return tried[s]

    falls = 0
    for r in _RATIOS:
        value = at(r * scale)
        if math.isnan(value):
            break
        falls = falls + 1 if value < max(tried.values()) else 0
        if falls >= _FALLS:
            break
    ratios = [r for r in _RATIOS if r * scale in tried]
    values = [tried[r * scale] for r in ratios]
    k = int(np.nanargmax(values)) if np.isfinite(values).any() else 0
    lo = ratios[max(k - 1, 0)]
    hi = ratios[min(k + 1, len(ratios) - 1)]
    for r in np.linspace(lo, hi, _REFINE_STEPS + 2)[1:-1]:
        at(float(r) * scale)
    done = {at_s: v for at_s, v in tried.items() if math.isfinite(v)}
    if not done:
        return 0.0, 0.0
    s, best = max(done.items(), key=lambda item: item[1])
    if best <= 0.0:
        return 0.0, 0.0
    return best, s


def union_area(centres_xy: FloatArray, radius_m: FloatArray) -> float:
    """The area of the union of the discs (those of radius <= 0 left out), from below: exact
    but for rounding, lowered by a share far above it; NaN above :data:`TUBE_MAX_PAIRS`
    overlapping pairs."""
    xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(radius_m, dtype=np.float64).reshape(-1)
    keep = r > 0.0
    xy, r = xy[keep], np.ascontiguousarray(r[keep])
    n = len(r)
    if n == 0:
        return 0.0
    # About the discs' middle: far from the origin (a projected CRS's millions of metres) the
    # arcs' terms would be large and cancel.
    xy = xy - 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    tree = cKDTree(xy)
    reach = 2.0 * float(r.max())
    # Counted before they are listed: memory linear in the discs.
    if int(tree.query_ball_point(xy, reach, return_length=True).sum()) > 2 * TUBE_MAX_PAIRS + n:
        return math.nan
    pairs = tree.query_pairs(reach, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.hypot(xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1])
    meet = d < r[i] + r[j]
    i, j = i[meet], j[meet]
    a = np.concatenate([i, j]).astype(np.int64)
    b = np.concatenate([j, i]).astype(np.int64)
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    ptr = np.searchsorted(a, np.arange(n + 1)).astype(np.int64)
    area = float(_union_kernel(xy[:, 0].copy(), xy[:, 1].copy(), r, ptr, np.ascontiguousarray(b)))
    return max(area * (1.0 - _AREA_SLACK), 0.0)


@nb.njit(cache=True)
def _union_kernel(
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    ptr: npt.NDArray[np.int64],
    near: npt.NDArray[np.int64],
) -> float:
    """Green's theorem over the union's boundary: for each circle, the arcs no other disc
    covers, each adding ``(x dy - y dx) / 2`` along it (counter-clockwise about its centre;
    a hole's edge, run so, is clockwise about the hole, as the theorem wants)."""
    total = 0.0
    two_pi = 2.0 * math.pi
    for i in range(len(r)):
        count = ptr[i + 1] - ptr[i]
        lo = np.empty(2 * count + 1)
        hi = np.empty(2 * count + 1)
        m = 0
        inside = False
        for k in range(ptr[i], ptr[i + 1]):
            j = near[k]
            dx, dy = x[j] - x[i], y[j] - y[i]
            d = math.hypot(dx, dy)
            if d + r[i] <= r[j]:
                # Within disc j (a tie goes to the lower index, so one of two equal discs
                # stays): no arc of it bounds the union.
                if d + r[i] < r[j] or r[i] < r[j] or j < i:
                    inside = True
                    break
                continue
            if d + r[j] <= r[i]:
                continue
            c = (r[i] * r[i] + d * d - r[j] * r[j]) / (2.0 * r[i] * d)
            half = math.acos(min(max(c, -1.0), 1.0))
            mid = math.atan2(dy, dx)
            s0 = (mid - half) % two_pi
            s1 = s0 + 2.0 * half
            if s1 > two_pi:
                lo[m], hi[m] = s0, two_pi
                m += 1
                lo[m], hi[m] = 0.0, s1 - two_pi
                m += 1
            else:
                lo[m], hi[m] = s0, s1
                m += 1
        if inside:
            continue
        order = np.argsort(lo[:m])
        free_from = 0.0
        for q in order:
            if lo[q] > free_from:
                total += _arc(x[i], y[i], r[i], free_from, lo[q])
            free_from = max(free_from, hi[q])
        if free_from < two_pi:
            total += _arc(x[i], y[i], r[i], free_from, two_pi)
    return total


@nb.njit(cache=True)
def _arc(cx: float, cy: float, r: float, t0: float, t1: float) -> float:
    """``(x dy - y dx) / 2`` along the circle's arc from angle ``t0`` to ``t1``."""
    return (
        0.5
        * r
        * (r * (t1 - t0) + cx * (math.sin(t1) - math.sin(t0)) - cy * (math.cos(t1) - math.cos(t0)))
    )
