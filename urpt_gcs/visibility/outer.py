"""Outer stars on the DEM as the certificate's regions, and their tightening.

Every point of the flight plane that sees a target lies in the target's outer star
(:func:`urpt_gcs.visibility.regions.star_reach`, exact on the DEM's bilinear surface and the
camera). :func:`outer_regions` makes those stars the regions a flight must enter, for
:func:`urpt_gcs.bound.certificate.certify`; :func:`finer_stars` walks the stars a relaxed tour
meets near their edge again, finer.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound.certificate import Tighten
from urpt_gcs.bound.lower_bound import spread_order
from urpt_gcs.problem.regions import OuterStar, RegionSet
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import Camera
from urpt_gcs.visibility.stars import FINER_SPLIT, STAR_SECTORS, finer_wedges, star_reach

__all__ = [
    "WALKED_ALWAYS",
    "finer_stars",
    "outer_regions",
    "points_along",
    "star_holds",
    "star_polygon",
    "star_sectors",
    "warm_up",
]

# Up to this many targets (those the order search bounds, all of them) every star is walked
# on the DEM whatever the clock. Beyond, the stars are walked farthest apart first, in chunks
# of this many per worker, while the time allowed lasts (the first chunk always), and the
# rest keep their camera cone's disc (which holds every point that sees the target).
WALKED_ALWAYS = 150
_WALK_CHUNK = 16
# Sectors per outer star: the finest up to this many regions, then fewer, down to the least.
_FINE_UP_TO = 24
_LEAST_SECTORS = 180
# Tightening the stars where the relaxed tour meets them: a star it passes within this share
# of a sector's reach from the edge is walked again whole, every sector split in two, up to
# FINER_SPLIT times its first sectors; the stars closest to their edge first, as many as
# fit half the time left.
_NEAR_EDGE = 0.2
# Seconds a wedge's walk takes per band of half a cell (measured on the paper's terrains).
_BAND_S = 4e-7
# A relaxed tour meets a star to within this share of its reach (the bound's tolerance).
_TOUCH = 1e-3
# ... and this share of a sector's width from its edge counts in the neighbour too.
_TOUCH_EDGE = 0.05


def _walked(
    terrain: Terrain,
    xy: FloatArray,
    ground: FloatArray,
    camera: Camera,
    depot_xy: tuple[float, float] | None,
    sectors: int,
    workers: int | None,
    time_limit_s: float,
) -> tuple[FloatArray, FloatArray]:
    """Outer and inner reaches: walked for every star up to :data:`WALKED_ALWAYS` targets,
    else for the stars farthest apart first while the time allows, the cone's disc (and
    nothing known inside) for the rest."""
    started = time.perf_counter()
    cone = camera.cone_radius_m(ground)
    outer = np.repeat(np.asarray(cone, dtype=np.float64)[:, None], sectors, axis=1)
    inner = np.zeros_like(outer)
    first = spread_order(xy, cone, depot_xy, WALKED_ALWAYS)
    order = np.concatenate([first, np.setdiff1d(np.arange(len(xy)), first)]).astype(np.int64)
    chunk = _WALK_CHUNK * max(1, workers or 1)
    batches = [order] if len(xy) <= WALKED_ALWAYS else np.array_split(order, -(-len(xy) // chunk))
    for k, idx in enumerate(batches):
        if k > 0 and time.perf_counter() - started >= time_limit_s:
            break
        if idx.size:
            outer[idx], inner[idx] = star_reach(
                terrain, xy[idx], ground[idx], camera, sectors, workers
            )
    return outer, inner


def star_sectors(regions: int) -> int:
    """Sectors per outer star for a bound over ``regions`` regions."""
    if regions <= _FINE_UP_TO:
        return STAR_SECTORS
    return max(_LEAST_SECTORS, STAR_SECTORS * _FINE_UP_TO // regions // 8 * 8)


def outer_regions(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    depot_xy: tuple[float, float] | None,
    workers: int | None = 1,
    hold_m: float = 0.0,
    time_limit_s: float = math.inf,
) -> tuple[RegionSet, float]:
    """Every target's outer star as a region to enter, home as the depot, and the ratio of
    the stars' area to what is certainly seen.

    Up to :data:`WALKED_ALWAYS` targets every star is walked on the DEM; beyond, the stars
    farthest apart first while ``time_limit_s`` lasts, and those left keep the disc of the
    camera's cone about their target (nothing outside it sees the target; nothing is known
    seen inside).

    With ``hold_m`` > 0 the regions are where a stop sees its target from anywhere within
    ``hold_m`` of it (the plan's position tolerance): such a stop ``p`` at angle ``t`` from the
    star's centre has ``p + hold_m (cos t, sin t)`` seeing too, so ``|p - c| + hold_m`` is within
    the sector's reach, and every reach shrinks by ``hold_m``.

    A target whose star holds home is marked as holding the depot (the bound leaves it out):
    a flight from home may see it without ever crossing its region's edge.
    """
    xy = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    ground = np.asarray(ground_m, dtype=np.float64)
    sectors = star_sectors(len(xy))
    outer, inner = _walked(terrain, xy, ground, camera, depot_xy, sectors, workers, time_limit_s)
    if hold_m > 0.0:
        outer = np.maximum(outer - hold_m, 0.0)
        inner = np.minimum(np.maximum(inner - hold_m, 0.0), outer)
    stars = tuple(
        OuterStar((float(x), float(y)), outer[i], inner[i]) for i, (x, y) in enumerate(xy.tolist())
    )
    inside = None if depot_xy is None else tuple(star_holds(s, depot_xy) for s in stars)
    regions = RegionSet(
        polygons=tuple(star_polygon(s) for s in stars),
        depot_xy=depot_xy,
        outer=stars,
        depot_inside=inside,
        name="outer visibility stars",
    )
    seen = float(np.sum(inner**2))
    ratio = float(np.sum(outer**2)) / seen if seen > 0.0 else math.inf
    return regions, ratio


def finer_stars(
    terrain: Terrain, camera: Camera, workers: int | None = 1, hold_m: float = 0.0
) -> Tighten:
    """What tightens the outer stars of :func:`outer_regions` (made with the same terrain,
    camera and ``hold_m``) where a relaxed tour meets them: each star it passes near the
    edge (within :data:`_NEAR_EDGE` of a sector's reach, and farther out than the star is
    surely seen) is walked again whole by :func:`urpt_gcs.visibility.regions.finer_wedges`, every
    sector split in two, until it has :data:`FINER_SPLIT` times its first sectors. The stars
    still hold every point that sees their targets.

    Whole stars, not the sectors met: a star walked finer only there keeps its coarse
    sectors' corners beside them, the next relaxed tour moves onto one, and the order search
    splits its pieces around every such corner (the README's certificate section has the
    figures)."""
    first: dict[tuple[float, float], int] = {}
    step = terrain.cell_m / 2.0

    def tighten(regions: RegionSet, poly_xy: FloatArray, budget_s: float) -> RegionSet | None:
        stars = regions.outer
        if not stars:
            return None
        poly = np.asarray(poly_xy, dtype=np.float64).reshape(-1, 2)
        samples = points_along(poly, step)
        tree = cKDTree(samples)
        asked: list[tuple[float, int]] = []
        for i, star in enumerate(stars):
            n = star.reach_m.size
            if n >= first.setdefault(star.center_xy, n) * FINER_SPLIT:
                continue
            c = np.asarray(star.center_xy)
            far = float(star.reach_m.max()) / math.cos(math.pi / n) * (1.0 + _TOUCH)
            near = tree.query_ball_point(c, far)
            if not near:
                continue
            rel = samples[near] - c
            dist = np.hypot(*rel.T)
            f = np.arctan2(rel[:, 1], rel[:, 0]) % (2.0 * math.pi) / (2.0 * math.pi) * n
            j = np.minimum(np.floor(f).astype(np.int64), n - 1)
            least = np.full(n, np.inf)
            np.minimum.at(least, j, dist)
            # A point on the edge between two sectors lies in both (the star's polygon meets
            # a sector's neighbour there at the sector's reach).
            low, high = f - j < _TOUCH_EDGE, f - j > 1.0 - _TOUCH_EDGE
            np.minimum.at(least, (j[low] - 1) % n, dist[low])
            np.minimum.at(least, (j[high] + 1) % n, dist[high])
            inner = star.inner_m if star.inner_m is not None else np.zeros(n)
            reach = star.reach_m
            pick = (
                (least <= reach / math.cos(math.pi / n) * (1.0 + _TOUCH))
                & (least >= (1.0 - _NEAR_EDGE) * reach)
                & (least > inner)
            )
            if pick.any():
                asked.append((float(np.min(reach[pick] - least[pick])), i))
        if not asked:
            return None
        chosen: list[int] = []
        cost = 0.0
        for _, i in sorted(asked):
            walk = 2.0 * float(stars[i].reach_m.sum()) / step * _BAND_S
            if chosen and cost + walk > budget_s:
                break
            chosen.append(i)
            cost += walk
        count = np.array([stars[i].reach_m.size for i in chosen])
        which = np.repeat(chosen, count)
        sector = np.concatenate([np.arange(k) for k in count.tolist()])
        xy = np.array([stars[i].center_xy for i in chosen])[
            np.repeat(np.arange(len(chosen)), count)
        ]
        ground = terrain.sample(xy[:, 0], xy[:, 1])
        got = finer_wedges(
            terrain, xy, ground, camera, np.repeat(count, count), sector, workers, split=2, bands=1
        )
        if hold_m > 0.0:
            got = np.maximum(got - hold_m, 0.0)
        new = list(stars)
        for i in chosen:
            new[i] = _halved(stars[i], got[which == i])
        stars_t = tuple(new)
        inside = (
            None
            if regions.depot_xy is None
            else tuple(star_holds(s, regions.depot_xy) for s in stars_t)
        )
        return dataclasses.replace(
            regions,
            polygons=tuple(star_polygon(s) for s in stars_t),
            outer=stars_t,
            depot_inside=inside,
        )

    return tighten


def _halved(star: OuterStar, wedges: FloatArray) -> OuterStar:
    """The star with every sector split in two, each half's reach the least of the sector's
    and its wedge's (``wedges``: a row of two per sector)."""
    reach = np.minimum(np.repeat(star.reach_m, 2), wedges.ravel())
    inner = None if star.inner_m is None else np.minimum(np.repeat(star.inner_m, 2), reach)
    return OuterStar(star.center_xy, reach, inner)


def star_holds(star: OuterStar, xy: tuple[float, float]) -> bool:
    """Whether the point may lie in the star: within the reach of its sector or of either
    neighbour (a point on an edge between two sectors belongs to both)."""
    dx, dy = xy[0] - star.center_xy[0], xy[1] - star.center_xy[1]
    n = star.reach_m.size
    k = math.floor(math.atan2(dy, dx) % (2.0 * math.pi) / (2.0 * math.pi) * n) % n
    reach = max(float(star.reach_m[j % n]) for j in (k - 1, k, k + 1))
    return math.hypot(dx, dy) <= reach * (1.0 + 1e-9) + 1e-9


def star_polygon(star: OuterStar) -> Polygon:
    """A polygon holding the star: each sector's arc replaced by the tangents' corners."""
    n = star.reach_m.size
    edges = 2.0 * math.pi * np.arange(n + 1) / n
    r = np.maximum(star.reach_m, 1e-6) / math.cos(math.pi / n)
    t = np.column_stack([edges[:-1], edges[1:]]).ravel()
    rr = np.repeat(r, 2)
    cx, cy = star.center_xy
    poly = Polygon(np.column_stack([cx + rr * np.cos(t), cy + rr * np.sin(t)]))
    if poly.is_valid and poly.area > 0.0:
        return poly
    disc: Polygon = shapely.Point(cx, cy).buffer(float(r.max()))
    return disc


def points_along(poly: FloatArray, spacing_m: float) -> FloatArray:
    """Points along the closed polyline, in order, no more than ``spacing_m`` apart, every
    vertex among them."""
    ends = np.roll(poly, -1, axis=0)
    pieces = []
    for a, b in zip(poly, ends, strict=True):
        count = max(1, math.ceil(math.hypot(*(b - a)) / max(spacing_m, 1e-9)))
        f = np.arange(count)[:, None] / count
        pieces.append(a + f * (b - a))
    return np.vstack(pieces)


def warm_up(terrain: Terrain, target_xy: FloatArray, ground_m: float, camera: Camera) -> None:
    """Compile the star walks' kernels (or load them from numba's cache) by walking one
    target's star, coarse and finer, so that the time given to the walks is spent walking."""
    xy = np.asarray(target_xy, dtype=np.float64).reshape(1, 2)
    ground = np.array([ground_m], dtype=np.float64)
    star_reach(terrain, xy, ground, camera, 8)
    finer_wedges(terrain, xy, ground, camera, 8, [0], split=2)
