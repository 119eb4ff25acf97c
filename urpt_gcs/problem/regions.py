"""Regions on the plane, with no terrain: discs or polygons, each of which a tour must enter.

This is the continuous problem the planner and the CETSP benchmark share (the TSP with
neighbourhoods): the shortest closed tour, through the depot if there is one, that has a
point in every region. A region is known here only as a set of the plane: membership of
points, candidate points on it, and an *outer star* that contains it (a centre and, per
angular sector, the farthest reach of the region from that centre) from which the lower
bound builds its pieces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.instance import Instance

__all__ = ["STAR_SECTORS", "OuterStar", "RegionSet", "polygon_star"]

# Sectors of an outer star: fine enough that a piece's reach follows the region.
STAR_SECTORS = 64
# A disc's candidate points are pulled this far (relative) inside it, so that rounding never
# puts a boundary point outside.
_INSIDE = 1e-9


@dataclass(frozen=True, slots=True)
class OuterStar:
    """Where a region lies, sector by sector around ``center_xy``: its points at angle
    ``theta`` are within ``reach_m[k]`` of the centre, ``k = floor(theta / (2 pi) * K)``, and
    the region holds every point of sector ``k`` closer than ``inner_m[k]`` (so its boundary
    there lies between the two). ``inner_m`` None means nothing is known inside (all 0)."""

    center_xy: tuple[float, float]
    reach_m: FloatArray
    inner_m: FloatArray | None = None

    def __post_init__(self) -> None:
        if self.reach_m.ndim != 1 or self.reach_m.size < 1 or np.any(self.reach_m < 0.0):
            raise ValueError("OuterStar.reach_m must be a non-empty array of reaches >= 0")
        if self.inner_m is not None and (
            self.inner_m.shape != self.reach_m.shape
            or np.any(self.inner_m < 0.0)
            or np.any(self.inner_m > self.reach_m)
        ):
            raise ValueError("OuterStar.inner_m must be one reach per sector in [0, reach_m]")

    def _sectors(self, theta0: float, theta1: float) -> slice:
        n = self.reach_m.size
        k0 = math.floor(theta0 / (2.0 * math.pi) * n + 1e-9)
        k1 = math.ceil(theta1 / (2.0 * math.pi) * n - 1e-9)
        k0 = min(max(k0, 0), n - 1)
        return slice(k0, min(max(k1, k0 + 1), n))

    def inner_over(self, theta0: float, theta1: float) -> float:
        """The least inner reach over the angles ``[theta0, theta1]``."""
        if self.inner_m is None:
            return 0.0
        return float(self.inner_m[self._sectors(theta0, theta1)].min())

    def reach_over(self, theta0: float, theta1: float) -> float:
        """The largest reach over the angles ``[theta0, theta1]`` (radians, from 0 to 2 pi)."""
        return float(self.reach_m[self._sectors(theta0, theta1)].max())


@dataclass(frozen=True, slots=True)
class RegionSet:
    """The regions a tour must enter: discs ``(x, y, r)`` or polygons, and an optional depot.

    Exactly one of ``discs`` (an ``(n, 3)`` array) and ``polygons`` is given. ``outer`` holds,
    per region, a star that contains it; for discs and polygons it is computed from the shape
    itself (the default), a caller with more knowledge (the terrain) may pass its own, and
    then ``depot_inside``: which regions hold the depot (by default decided by ``contains``).
    """

    discs: FloatArray | None = None
    polygons: tuple[Polygon, ...] | None = None
    depot_xy: tuple[float, float] | None = None
    outer: tuple[OuterStar, ...] = field(default=())
    depot_inside: tuple[bool, ...] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if (self.discs is None) == (self.polygons is None):
            raise SettingsError("regions: give either discs or polygons")
        if self.discs is not None:
            d = np.asarray(self.discs, dtype=np.float64)
            if d.ndim != 2 or d.shape[1] != 3 or not np.all(np.isfinite(d)) or np.any(d[:, 2] < 0):
                raise SettingsError("regions: discs must be rows of finite x, y and radius >= 0")
            object.__setattr__(self, "discs", d)
            d.setflags(write=False)
        else:
            assert self.polygons is not None
            for k, p in enumerate(self.polygons):
                if p.is_empty or not p.is_valid or p.area <= 0.0:
                    raise SettingsError(f"regions: polygon {k} is empty or invalid; fix it")
        if self.n == 0:
            raise SettingsError("regions: there is no region to visit")
        if not self.outer:
            object.__setattr__(self, "outer", tuple(self._own_outer()))
        elif len(self.outer) != self.n:
            raise SettingsError("regions: give one outer star per region")

    @property
    def n(self) -> int:
        if self.discs is not None:
            return len(self.discs)
        assert self.polygons is not None
        return len(self.polygons)

    def _own_outer(self) -> list[OuterStar]:
        if self.discs is not None:
            return [
                OuterStar((float(x), float(y)), np.full(STAR_SECTORS, r), np.full(STAR_SECTORS, r))
                for x, y, r in self.discs.tolist()
            ]
        assert self.polygons is not None
        return [polygon_star(p) for p in self.polygons]

    def contains(self, points_xy: FloatArray, region: IntArray) -> BoolArray:
        """Whether ``points_xy[k]`` lies in region ``region[k]`` (boundary included)."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        idx = np.asarray(region, dtype=np.int64).ravel()
        if self.discs is not None:
            d = self.discs[idx]
            inside: BoolArray = np.hypot(pts[:, 0] - d[:, 0], pts[:, 1] - d[:, 1]) <= d[:, 2]
            return inside
        assert self.polygons is not None
        polys = np.asarray(self.polygons, dtype=object)[idx]
        out: BoolArray = shapely.intersects_xy(polys, pts[:, 0], pts[:, 1])
        return out

    def cover_pairs(self, points_xy: FloatArray) -> tuple[IntArray, IntArray]:
        """Every (point, region) pair where the point lies in the region."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        if self.discs is not None:
            tree = cKDTree(self.discs[:, :2])
            near = tree.query_ball_point(pts, r=float(self.discs[:, 2].max()) + 1e-12)
            pi = np.repeat(np.arange(len(pts)), [len(n) for n in near]).astype(np.int64)
            ri = np.fromiter((j for n in near for j in n), dtype=np.int64, count=len(pi))
        else:
            assert self.polygons is not None
            tree_p = shapely.STRtree(list(self.polygons))
            pi, ri = tree_p.query(shapely.points(pts), predicate="intersects")
            pi, ri = pi.astype(np.int64), ri.astype(np.int64)
        keep = self.contains(pts[pi], ri)
        return pi[keep], ri[keep]

    def samples(self, per_region: int) -> tuple[FloatArray, IntArray]:
        """Candidate points: ``per_region`` on each region's boundary, and an inner point."""
        if self.discs is not None:
            theta = 2.0 * np.pi * np.arange(per_region) / per_region
            d = self.discs
            r = d[:, 2:3] * (1.0 - _INSIDE)
            xs = d[:, 0:1] + r * np.cos(theta)[None, :]
            ys = d[:, 1:2] + r * np.sin(theta)[None, :]
            ring = np.column_stack([xs.ravel(), ys.ravel()])
            own = np.repeat(np.arange(self.n, dtype=np.int64), per_region)
            pts = np.vstack([d[:, :2], ring])
            return pts, np.concatenate([np.arange(self.n, dtype=np.int64), own])
        assert self.polygons is not None
        out, owner = [], []
        for k, poly in enumerate(self.polygons):
            ring = poly.exterior
            at = np.arange(per_region) / per_region * ring.length
            xy = shapely.get_coordinates(shapely.line_interpolate_point(ring, at))
            inner = shapely.get_coordinates(poly.representative_point())
            out.append(np.vstack([inner, xy]))
            owner.append(np.full(per_region + 1, k, dtype=np.int64))
        return np.vstack(out), np.concatenate(owner)

    def instance(self, points_xy: FloatArray) -> Instance:
        """The GTSP over candidate ``points_xy``: each point covers every region it lies in."""
        pi, ri = self.cover_pairs(points_xy)
        return Instance.from_cover_pairs(pi, ri, points_xy, self.n, depot_xy=self.depot_xy)


def polygon_star(poly: Polygon, center_xy: tuple[float, float] | None = None) -> OuterStar:
    """The outer star of a polygon: per sector, the farthest point of the polygon in it.

    The farthest point of a polygon piece from a point is one of its vertices, so the reach
    is exact for the sector (the piece is the polygon cut by the sector's wedge).
    """
    if center_xy is None:
        c = poly.centroid if poly.contains(poly.centroid) else poly.representative_point()
        center_xy = (float(c.x), float(c.y))
    cx, cy = center_xy
    coords = shapely.get_coordinates(poly)
    far = float(np.hypot(coords[:, 0] - cx, coords[:, 1] - cy).max()) * 2.0 + 1.0
    n = STAR_SECTORS
    wedges = []
    for k in range(n):
        a = np.linspace(2.0 * np.pi * k / n, 2.0 * np.pi * (k + 1) / n, 5)
        ring = [(cx, cy), *zip(cx + far * np.cos(a), cy + far * np.sin(a), strict=True)]
        wedges.append(Polygon(ring))
    wedge_arr = np.asarray(wedges, dtype=object)
    pieces = shapely.intersection(poly, wedge_arr)
    rims = shapely.intersection(poly.boundary, wedge_arr)
    center = shapely.Point(cx, cy)
    inside = poly.covers(center)
    reach = np.zeros(n)
    inner = np.zeros(n)
    for k, piece in enumerate(pieces):
        if not piece.is_empty:
            xy = shapely.get_coordinates(piece)
            reach[k] = float(np.hypot(xy[:, 0] - cx, xy[:, 1] - cy).max())
        # With the centre inside, the sector closer than the nearest boundary point holds no
        # boundary, so it lies inside the polygon.
        if inside and not rims[k].is_empty:
            inner[k] = min(float(center.distance(rims[k])), reach[k])
    return OuterStar(center_xy, reach, inner)
