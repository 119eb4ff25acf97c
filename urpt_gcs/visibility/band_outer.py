"""Where a target can be seen from inside the height band, at most: its outer star.

A point at horizontal distance ``d`` from a target at ground height ``g`` that sees it in
the camera's cone has ``d <= (z - g) tan``, and inside the band its height ``z`` is at most
the ceiling over the surface right below it. So along every sector around the target the
reach is at most the fixed point of ``r = (S_k(r) + ceiling - g) tan``, where ``S_k(r)`` is
the highest surface in the sector within ``r``: from the plane over the highest terrain read
(every point of the band lies under it) the reach only shrinks, sector by sector. A GSD cap
bounds the distance from the lens, so the reach never passes it either.

The highest surface in a sector is bounded from the DEM's corners: the bilinear surface at a
point never passes the four corners around it, which all lie within one cell (in each grid
direction) of the cell centre nearest the point; so the maximum of the 3 x 3 corners around
every centre within ``0.71`` cells of the sector bounds the surface there. Unknown ground
counts as the highest terrain read.

These stars are what the band's certificate bounds (the tour's stops never leave them);
they are not used to decide what any viewpoint sees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.regions import OuterStar, RegionSet
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.outer import star_holds, star_polygon
from urpt_gcs.visibility.regions import Camera

__all__ = ["BandOuter", "band_outer"]

# Sectors per star.
_SECTORS = 32
# How far, in cells, a point may lie from the cell centre nearest it (half the diagonal),
# with a hair to spare.
_NEAREST_CELLS = 0.71
# Rounds of the fixed point at most (each only shrinks the reach).
_ROUNDS = 30


@dataclass(frozen=True, slots=True)
class BandOuter:
    """Every target's outer star in the band, as regions to enter from home.

    Attributes
    ----------
    regions
        The stars (reduced by the position tolerance the stops hold) and home as the depot.
    radius_m
        Each star's widest reach (before the tolerance): no viewpoint that sees the target
        lies farther.
    lowest_m, highest_m
        The lowest and highest DEM corner within that radius: any viewpoint that sees the
        target is at least the band's floor over the first and at most its ceiling over
        the second.
    """

    regions: RegionSet
    radius_m: FloatArray
    lowest_m: FloatArray
    highest_m: FloatArray


def band_outer(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    ceiling_m: float,
    top_m: float,
    depot_xy: tuple[float, float] | None,
    hold_m: float = 0.0,
) -> BandOuter:
    """The targets' outer stars inside the band (see the module's description).

    Parameters
    ----------
    terrain
        The DEM window read for the plane at the ceiling over ``top_m``.
    targets_xy, ground_m
        The targets and the ground under them.
    camera
        Its cone's half-angle and GSD distance count (the frame's corner cone for a frame).
    ceiling_m
        The band's ceiling above the surface.
    top_m
        The highest terrain of the operating area.
    depot_xy
        Home.
    hold_m
        The tolerance every stop sees its targets from: a stop's point ``hold_m`` farther
        out sees too, so the regions are the stars less ``hold_m``.
    """
    z = np.asarray(terrain.elevation_m, dtype=np.float64)
    known = np.where(np.isnan(z), top_m, z)
    high = maximum_filter(known, size=3, mode="nearest")
    low = minimum_filter(np.where(np.isnan(z), -np.inf, z), size=3, mode="nearest")
    rows, cols = z.shape
    transform = terrain.transform
    tan = camera.tan_fov
    far = camera.max_distance_m
    cell = terrain.cell_m
    slack = _NEAREST_CELLS * cell
    reaches, radius, lowest, highest = [], [], [], []
    for (tx, ty), g in zip(
        np.asarray(targets_xy).tolist(), np.asarray(ground_m).tolist(), strict=True
    ):
        r0 = max(top_m + ceiling_m - g, 0.0) * tan
        if math.isfinite(far):
            r0 = min(r0, far)
        col, row = terrain.pixel_coords(np.array([tx]), np.array([ty]))
        span = math.ceil(1.5 * (r0 + slack) / cell) + 2
        c0, c1 = max(int(col[0]) - span, 0), min(int(col[0]) + span + 1, cols)
        r_0, r_1 = max(int(row[0]) - span, 0), min(int(row[0]) + span + 1, rows)
        cc, rr = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r_0, r_1) + 0.5)
        u, v = cc.ravel(), rr.ravel()
        x = transform.a * u + transform.b * v + transform.c
        y = transform.d * u + transform.e * v + transform.f
        dx, dy = x - tx, y - ty
        dist = np.hypot(dx, dy)
        near = np.maximum(dist - slack, 0.0)
        inside = near <= r0
        h = high[r_0:r_1, c0:c1].ravel()[inside]
        lo = low[r_0:r_1, c0:c1].ravel()[inside]
        near, dist, dx, dy = near[inside], dist[inside], dx[inside], dy[inside]
        reach = _sector_reach(near, dist, dx, dy, h, r0, slack, ceiling_m - g, tan)
        widest = float(reach.max())
        within = near <= widest
        radius.append(widest)
        highest.append(float(h[within].max()) if within.any() else top_m)
        lowest.append(float(lo[within].min()) if within.any() else -math.inf)
        reaches.append(reach)
    stars = tuple(
        OuterStar((float(x), float(y)), np.maximum(r - hold_m, 0.0))
        for (x, y), r in zip(np.asarray(targets_xy).tolist(), reaches, strict=True)
    )
    inside_depot = None if depot_xy is None else tuple(star_holds(s, depot_xy) for s in stars)
    regions = RegionSet(
        polygons=tuple(star_polygon(s) for s in stars),
        depot_xy=depot_xy,
        outer=stars,
        depot_inside=inside_depot,
        name="outer stars in the band",
    )
    return BandOuter(regions, np.array(radius), np.array(lowest), np.array(highest))


def _sector_reach(
    near: FloatArray,
    dist: FloatArray,
    dx: FloatArray,
    dy: FloatArray,
    high: FloatArray,
    start_m: float,
    slack_m: float,
    lift_m: float,
    tan: float,
) -> FloatArray:
    """Each sector's reach: the fixed point of ``r = (S(r) + lift) tan`` from ``start_m``,
    ``S(r)`` the highest corner bound of the centres within ``r`` (less their slack) of the
    target whose slack reaches into the sector."""
    k = _SECTORS
    width = 2.0 * math.pi / k
    angle = np.arctan2(dy, dx) % (2.0 * math.pi)
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = np.where(dist > slack_m, np.arcsin(np.minimum(slack_m / dist, 1.0)), math.pi)
    first = np.floor((angle - spread) / width).astype(np.int64)
    last = np.floor((angle + spread) / width).astype(np.int64)
    out = np.empty(k)
    for sector in range(k):
        # A centre counts for the sector when its angular spread overlaps it (modulo a turn).
        member = np.zeros(len(near), dtype=bool)
        for shift in (-k, 0, k):
            member |= (first <= sector + shift) & (last >= sector + shift)
        member |= spread >= math.pi
        order = np.argsort(near[member])
        d_sorted = near[member][order]
        running = np.maximum.accumulate(high[member][order]) if order.size else np.zeros(0)
        r = start_m
        for _ in range(_ROUNDS):
            count = int(np.searchsorted(d_sorted, r, side="right"))
            top = running[count - 1] if count else -math.inf
            nxt = min(r, max(top + lift_m, 0.0) * tan) if math.isfinite(top) else 0.0
            if nxt >= r - 1e-9:
                break
            r = nxt
        out[sector] = r
    return out
