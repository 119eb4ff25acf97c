"""Visibility: for each target, the region of the flight plane from which it is seen.

A target ``p`` (ground height ``z_p``) is seen from ``q`` on the plane at altitude ``H`` when
the angle between nadir and ``q -> p`` is at most the camera half-angle ``delta`` and the
segment ``q -> p`` clears the terrain. Along one azimuth, with ``h = H - z_p`` and ``s`` the
horizontal distance from ``p``, the segment to the plane point at ``s`` passes height
``z_p + s' h / s`` above distance ``s'``. It clears terrain ``z(s')`` for every ``s' < s`` iff
``s * slope(s') <= h`` with ``slope(s') = (z(s') - z_p) / s'``. So each terrain sample ``s'``
forbids every ``s > max(s', h / slope(s'))``, and the visible set is the interval ``[0, s*]``:

    s* = min(h tan(delta), min over samples of max(s', h / slope(s')))

Terrain beyond the drone (``s' >= s``) plays no part, so this stays exact when terrain
rises above the flight plane. Unknown ground (nodata, outside the DEM) forbids going past it.
Everything is vectorised over targets, azimuths and samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon

from urpt_gcs.errors import SettingsError
from urpt_gcs.segments import clear_of_terrain
from urpt_gcs.terrain import FloatArray, Terrain

BoolArray = npt.NDArray[np.bool_]

# Samples per ray-sweep chunk (targets x azimuths x steps), to bound memory.
_CHUNK_SAMPLES = 1_000_000


@dataclass(frozen=True, slots=True)
class Camera:
    """A nadir camera on a constant-altitude flight plane."""

    altitude_m: float
    fov_deg: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError(
                f"--fov {self.fov_deg} is outside (0, 90): give the camera half-angle in degrees"
            )
        if not math.isfinite(self.altitude_m):
            raise SettingsError(f"--altitude {self.altitude_m} is not a number")

    @property
    def tan_fov(self) -> float:
        return math.tan(math.radians(self.fov_deg))

    def cone_radius_m(self, ground_m: npt.ArrayLike) -> FloatArray:
        """Radius on the plane of the cone of a target at ground height ``ground_m``."""
        h = self.altitude_m - np.asarray(ground_m, dtype=np.float64)
        return np.maximum(h, 0.0) * self.tan_fov


@dataclass(frozen=True, slots=True)
class Region:
    """The visibility region of one target on the flight plane.

    ``reach_m[k]`` is ``s*`` along azimuth ``azimuth_rad[k]`` (counter-clockwise from east).
    ``polygon`` joins the boundary points by straight lines as the paper does; it is for
    display and bounds only, never to decide what a viewpoint sees.
    """

    target: int
    center_xy: tuple[float, float]
    ground_m: float
    cone_radius_m: float
    azimuth_rad: FloatArray
    reach_m: FloatArray
    polygon: Polygon

    def boundary_xy(self, inset_m: float = 0.0) -> FloatArray:
        """Boundary samples, each moved ``inset_m`` towards the target (not past it)."""
        r = np.maximum(self.reach_m - inset_m, 0.0)
        cx, cy = self.center_xy
        return np.column_stack(
            [cx + r * np.cos(self.azimuth_rad), cy + r * np.sin(self.azimuth_rad)]
        )


def azimuths(samples: int) -> FloatArray:
    """``samples`` evenly spaced azimuths in radians, counter-clockwise from east."""
    if samples < 3:
        raise SettingsError(f"--samples {samples} is below 3: use at least 3 azimuths")
    return np.arange(samples, dtype=np.float64) * (2.0 * math.pi / samples)


def _grid_crossings(
    terrain: Terrain, x0: FloatArray, y0: FloatArray, ux: FloatArray, uy: FloatArray, n: int
) -> FloatArray:
    """Distances along rays ``(x0, y0) + s (ux, uy)`` where they cross the lines through pixel
    centres, the breaks of the bilinear surface: the first ``n`` of each family, with
    ``inf`` where a ray runs parallel to a family. Shape ``broadcast(x0, ux) + (2n,)``."""
    inv = ~terrain.transform
    col0, row0 = terrain.pixel_coords(x0, y0)
    out = []
    for start, rate in (
        (col0, inv.a * np.asarray(ux) + inv.b * np.asarray(uy)),
        (row0, inv.d * np.asarray(ux) + inv.e * np.asarray(uy)),
    ):
        rate = np.asarray(rate, dtype=np.float64)[..., None]
        start = np.asarray(start, dtype=np.float64)[..., None]
        first = np.where(rate > 0, np.floor(start) + 1.0, np.ceil(start) - 1.0)
        lines = first + np.sign(rate) * np.arange(n, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = (lines - start) / rate
        out.append(np.where(np.abs(rate) > 1e-12, dist, np.inf))
    # The slope of the terrain right at the start: the limit of (z(s) - z(0)) / s.
    out.append(np.full((*out[0].shape[:-1], 1), 1e-3 * terrain.cell_m))
    return np.concatenate(np.broadcast_arrays(*out), axis=-1)


def ray_reach(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    azimuth_rad: FloatArray,
) -> FloatArray:
    """``s*`` for every target and azimuth, shape (targets, azimuths).

    The terrain is the DEM's bilinear surface. It is sampled along each ray where the ray
    crosses the lines through pixel centres (where that surface bends, so a wall's top edge
    is hit exactly) and every half cell in between.
    """
    step = terrain.cell_m / 2.0
    m = len(targets_xy)
    height = camera.altitude_m - ground_m  # (m,)
    cone = camera.cone_radius_m(ground_m)
    reach = np.zeros((m, len(azimuth_rad)), dtype=np.float64)
    cos_a, sin_a = np.cos(azimuth_rad), np.sin(azimuth_rad)
    longest = float(np.max(cone, initial=0.0))
    n_uniform = max(math.ceil(longest / step), 1)
    n_cross = math.ceil(longest / terrain.cell_m) + 2
    per_target = len(azimuth_rad) * (n_uniform + 2 * n_cross + 1)
    chunk = max(_CHUNK_SAMPLES // per_target, 1)
    uniform = np.arange(1, n_uniform + 1, dtype=np.float64) * step
    for lo in range(0, m, chunk):
        hi = min(lo + chunk, m)
        x0 = targets_xy[lo:hi, 0, None]
        y0 = targets_xy[lo:hi, 1, None]
        cross = _grid_crossings(terrain, x0, y0, cos_a[None, :], sin_a[None, :], n_cross)
        s = np.concatenate(
            [np.broadcast_to(uniform, (*cross.shape[:2], n_uniform)), cross], axis=-1
        )
        s = np.where((s > 0.0) & (s < cone[lo:hi, None, None]), s, np.inf)
        with np.errstate(invalid="ignore"):
            z = terrain.sample(
                x0[..., None] + cos_a[None, :, None] * s, y0[..., None] + sin_a[None, :, None] * s
            )  # (k, d, n)
        h = height[lo:hi, None, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (z - ground_m[lo:hi, None, None]) / s
            limit = np.where(slope > 0.0, np.maximum(s, h / slope), np.inf)
        limit = np.where(np.isnan(z), s, limit)
        # Samples at or beyond the cone cannot constrain a viewpoint inside it.
        limit = np.where(np.isfinite(s), limit, np.inf)
        reach[lo:hi] = np.minimum(limit.min(axis=2), cone[lo:hi, None])
    return reach


def visibility_regions(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    samples: int,
) -> tuple[Region, ...]:
    """The visibility region of every target.

    Parameters
    ----------
    terrain
        Elevations covering every target's cone.
    targets_xy
        (m, 2) target positions in the terrain's CRS.
    ground_m
        (m,) ground elevation at each target.
    camera
        Flight-plane altitude and camera half-angle.
    samples
        Number of azimuths ``d``.
    """
    az = azimuths(samples)
    reach = ray_reach(terrain, targets_xy, ground_m, camera, az)
    cone = camera.cone_radius_m(ground_m)
    regions = []
    for i, (x, y) in enumerate(targets_xy):
        r = reach[i]
        ring = np.column_stack([x + r * np.cos(az), y + r * np.sin(az)])
        poly = Polygon(ring)
        if not poly.is_valid or poly.is_empty:
            # Rays of zero reach pinch the star; keep what is left as one valid shape.
            fixed = shapely.make_valid(poly)
            polys = [g for g in getattr(fixed, "geoms", [fixed]) if isinstance(g, Polygon)]
            poly = max(polys, key=lambda g: g.area) if polys else Polygon()
        regions.append(
            Region(
                target=i,
                center_xy=(float(x), float(y)),
                ground_m=float(ground_m[i]),
                cone_radius_m=float(cone[i]),
                azimuth_rad=az,
                reach_m=r,
                polygon=poly,
            )
        )
    return tuple(regions)


def line_of_sight(
    terrain: Terrain,
    eye_xyz: FloatArray,
    target_xyz: FloatArray,
    workers: int | None = 1,
) -> BoolArray:
    """Whether each straight segment ``eye -> target`` clears the terrain.

    Exact on the DEM's bilinear surface (:func:`urpt_gcs.segments.clear_of_terrain`): blocked
    when the terrain rises above the segment anywhere, or the segment crosses unknown ground.
    """
    return clear_of_terrain(terrain, eye_xyz, target_xyz, workers)
