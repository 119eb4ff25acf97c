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
A compiled kernel walks every target's rays, over as many threads as asked for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely
from numba import njit
from shapely.geometry import Polygon

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.site.camera import Frame
from urpt_gcs.site.terrain import Terrain, bilinear_at
from urpt_gcs.visibility.segments import clear_of_terrain, in_threads

__all__ = [
    "DEFAULT_HEADINGS",
    "Camera",
    "Region",
    "azimuths",
    "in_frame",
    "line_of_sight",
    "ray_reach",
    "visibility_regions",
]

# Below this many targets per thread a thread pool costs more than it saves.
_MIN_PARALLEL_TARGETS = 64


# Headings each candidate viewpoint is offered at, by default: a frame looks the same turned
# by 180 degrees, so these span every distinct orientation in steps of 45 degrees.
DEFAULT_HEADINGS = 4


@dataclass(frozen=True, slots=True)
class Camera:
    """A nadir camera on a constant-altitude flight plane.

    Without a ``frame`` it is the cone of half-angle ``fov_deg``. With one it is that frame
    turned by the vehicle's heading, and ``fov_deg`` is the half-angle to the frame's corner:
    the cone that holds the frame at every heading. ``gsd_cm`` caps the distance from the
    lens to what a photo counts as seen (a frame camera only). Headings are degrees clockwise
    from grid north of the planning CRS; a frame camera is offered at ``headings`` of them.
    """

    altitude_m: float
    fov_deg: float
    frame: Frame | None = None
    gsd_cm: float | None = None
    headings: int = 1

    def __post_init__(self) -> None:
        # The messages name the settings; the CLI shows their flags (SettingsError.naming).
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError.about(
                "{fov_deg} {value} is outside (0, 90): give the camera half-angle in degrees",
                value=self.fov_deg,
            )
        if not math.isfinite(self.altitude_m):
            raise SettingsError.about("{altitude_m} {value} is not a number", value=self.altitude_m)
        if self.gsd_cm is not None:
            if self.frame is None:
                raise SettingsError.about(
                    "{gsd_cm} needs the camera's pixels: give {camera} NAME or {sensor}, "
                    "{focal} and {image}"
                )
            if not (math.isfinite(self.gsd_cm) and 0.0 < self.gsd_cm <= 1000.0):
                raise SettingsError.about(
                    "{gsd_cm} {value} cm is out of range: give 0 to 1000 cm", value=self.gsd_cm
                )
        if not 1 <= self.headings <= 180:
            raise SettingsError.about(
                "{headings} {value} is out of range: give 1 to 180", value=self.headings
            )

    @classmethod
    def framed(
        cls,
        altitude_m: float,
        frame: Frame,
        gsd_cm: float | None = None,
        headings: int = DEFAULT_HEADINGS,
    ) -> Camera:
        """A frame camera; its ``fov_deg`` is the half-angle to the frame's corner."""
        fov = math.degrees(math.atan(frame.diagonal_tan))
        return cls(altitude_m, fov, frame, gsd_cm, headings)

    @property
    def tan_fov(self) -> float:
        return math.tan(math.radians(self.fov_deg))

    @property
    def max_distance_m(self) -> float:
        """The farthest a target may be from the lens (the GSD cap; inf without one)."""
        if self.frame is None or self.gsd_cm is None:
            return math.inf
        return self.frame.distance_for_gsd_m(self.gsd_cm)

    @property
    def heading_choices_deg(self) -> FloatArray:
        """The headings a candidate viewpoint is offered at (one, 0, for the cone)."""
        k = self.headings if self.frame is not None else 1
        out: FloatArray = np.arange(k, dtype=np.float64) * (180.0 / k)
        return out

    def cone_radius_m(self, ground_m: npt.ArrayLike) -> FloatArray:
        """Radius on the plane of what may see a target at ground height ``ground_m``: the
        cone (the frame's corner at any heading), within the GSD distance of it."""
        h = np.maximum(self.altitude_m - np.asarray(ground_m, dtype=np.float64), 0.0)
        cone: FloatArray = h * self.tan_fov
        far = self.max_distance_m
        if math.isfinite(far):
            within = np.sqrt(np.maximum(far * far - h * h, 0.0))
            cone = np.where(h <= far, np.minimum(cone, within), 0.0)
        return cone

    def in_view(
        self,
        eye_xy: FloatArray,
        target_xy: FloatArray,
        ground_m: FloatArray,
        heading_deg: FloatArray | None = None,
        within_m: float = 0.0,
    ) -> BoolArray:
        """Whether each target lies in the picture taken from ``eye_xy[k]`` (terrain aside);
        with ``within_m``, in the picture taken from every point of the plane within
        ``within_m`` of it.

        The cone and the GSD distance; for a frame camera, inside the frame turned by
        ``heading_deg[k]`` (needed then). The disc is held exactly, not sampled: see
        :meth:`view_margin_m`.
        """
        ok: BoolArray = self.view_margin_m(eye_xy, target_xy, ground_m, heading_deg) >= within_m
        return ok

    def view_margin_m(
        self,
        eye_xy: FloatArray,
        target_xy: FloatArray,
        ground_m: FloatArray,
        heading_deg: FloatArray | None = None,
    ) -> FloatArray:
        """How far each eye may move on the plane, in any direction, with its target still
        in the picture (terrain aside); negative: the target is out of it by that much.

        What a photo from the eye holds at the target's height is the circle of
        :meth:`cone_radius_m` about the eye, and for a frame camera the rectangle of half-sides
        ``h tan`` across and along ``heading_deg[k]``: both symmetric about the eye, so the
        disc of radius ``r`` around the eye sees the target iff the disc of radius ``r``
        around the target lies inside the footprint, iff the target is ``r`` inside the
        circle (``R - d >= r``) and ``r`` inside each pair of the rectangle's sides.
        """
        eye = np.asarray(eye_xy, dtype=np.float64).reshape(-1, 2)
        tgt = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
        ground = np.asarray(ground_m, dtype=np.float64).reshape(-1)
        dx, dy = tgt[:, 0] - eye[:, 0], tgt[:, 1] - eye[:, 1]
        margin: FloatArray = self.cone_radius_m(ground) - np.hypot(dx, dy)
        if self.frame is None:
            return margin
        if heading_deg is None:
            raise ValueError("a frame camera needs the heading of every photo")
        h = np.maximum(self.altitude_m - ground, 0.0)
        psi = np.radians(np.asarray(heading_deg, dtype=np.float64))
        along = dx * np.sin(psi) + dy * np.cos(psi)
        across = dx * np.cos(psi) - dy * np.sin(psi)
        margin = np.minimum(margin, h * self.frame.half_tan_across - np.abs(across))
        out: FloatArray = np.minimum(margin, h * self.frame.half_tan_along - np.abs(along))
        return out

    def least_half_width_m(self, ground_m: npt.ArrayLike) -> FloatArray:
        """The narrowest half-extent of what one photo sees around its centre, per target:
        the cone's radius, or for a frame its short half-side (within the GSD distance)."""
        cone = self.cone_radius_m(ground_m)
        if self.frame is None:
            return cone
        h = np.maximum(self.altitude_m - np.asarray(ground_m, dtype=np.float64), 0.0)
        short = h * min(self.frame.half_tan_across, self.frame.half_tan_along)
        out: FloatArray = np.minimum(cone, short)
        return out


def in_frame(
    frame: Frame,
    dx_m: npt.ArrayLike,
    dy_m: npt.ArrayLike,
    height_m: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    tolerance_m: float = 0.0,
) -> BoolArray:
    """Whether a point ``(dx, dy)`` (east, north of the camera) ``height_m`` below it lies
    inside the frame of a nadir photo taken at ``heading_deg`` (clockwise from north):
    within the half-width across the heading and the half-height along it."""
    dx, dy = np.asarray(dx_m, dtype=np.float64), np.asarray(dy_m, dtype=np.float64)
    h = np.asarray(height_m, dtype=np.float64)
    psi = np.radians(np.asarray(heading_deg, dtype=np.float64))
    along = dx * np.sin(psi) + dy * np.cos(psi)
    across = dx * np.cos(psi) - dy * np.sin(psi)
    ok: BoolArray = (np.abs(across) <= h * frame.half_tan_across + tolerance_m) & (
        np.abs(along) <= h * frame.half_tan_along + tolerance_m
    )
    return ok


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
        raise SettingsError.about(
            "{samples} {value} is below 3: use at least 3 azimuths", value=samples
        )
    return np.arange(samples, dtype=np.float64) * (2.0 * math.pi / samples)


@njit(cache=True)
def _limit(z, col0, row0, dcol, drow, s, ground, height):  # type: ignore[no-untyped-def]
    """The farthest plane distance the terrain sample at ``s`` allows (``s`` itself over
    unknown ground, ``inf`` when the sample is below the target)."""
    value = bilinear_at(z, col0 + dcol * s, row0 + drow * s)
    if math.isnan(value):
        return s
    slope = (value - ground) / s
    if slope > 0.0:
        return max(s, height / slope)
    return np.inf


@njit(cache=True, nogil=True)
def _reach_kernel(z, col0, row0, ground, height, cone, dcol, drow, step, start_s, reach):  # type: ignore[no-untyped-def]
    """``s*`` of targets ``k`` (pixel coordinates ``col0, row0``) along rays whose pixel
    rates per metre are ``dcol[a], drow[a]``, into ``reach[k, a]``.

    The samples along a ray are every ``step`` metres, every crossing of a line through pixel
    centres (where the bilinear surface bends) and ``start_s`` (the slope at the start). Each
    sample at ``s`` allows no more than some distance of at least ``s``, so once a family of
    samples passes the best limit so far, none of its later samples can lower it.
    """
    for k in range(col0.shape[0]):
        for a in range(dcol.shape[0]):
            best = cone[k]
            if start_s < best:
                best = min(
                    best,
                    _limit(z, col0[k], row0[k], dcol[a], drow[a], start_s, ground[k], height[k]),
                )
            i = 1
            while i * step < best:
                s = i * step
                best = min(
                    best, _limit(z, col0[k], row0[k], dcol[a], drow[a], s, ground[k], height[k])
                )
                i += 1
            for family in range(2):
                start = col0[k] if family == 0 else row0[k]
                rate = dcol[a] if family == 0 else drow[a]
                if abs(rate) <= 1e-12:
                    continue
                line = math.floor(start) + 1.0 if rate > 0 else math.ceil(start) - 1.0
                sign = 1.0 if rate > 0 else -1.0
                while True:
                    s = (line - start) / rate
                    if s >= best:
                        break
                    best = min(
                        best, _limit(z, col0[k], row0[k], dcol[a], drow[a], s, ground[k], height[k])
                    )
                    line += sign
            reach[k, a] = best


def ray_reach(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    azimuth_rad: FloatArray,
    workers: int | None = 1,
) -> FloatArray:
    """``s*`` for every target and azimuth, shape (targets, azimuths).

    The terrain is the DEM's bilinear surface. It is sampled along each ray where the ray
    crosses the lines through pixel centres (where that surface bends, so a wall's top edge
    is hit exactly) and every half cell in between; a compiled kernel walks each ray outwards
    and stops as soon as no farther sample can matter. ``workers`` threads share the targets
    (None: every core).
    """
    targets_xy = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    ground = np.ascontiguousarray(ground_m, dtype=np.float64)
    m = len(targets_xy)
    reach = np.zeros((m, len(azimuth_rad)), dtype=np.float64)
    if m == 0 or len(azimuth_rad) == 0:
        return reach
    height = camera.altitude_m - ground
    cone = np.ascontiguousarray(camera.cone_radius_m(ground))
    inv = ~terrain.transform
    cos_a, sin_a = np.cos(azimuth_rad), np.sin(azimuth_rad)
    dcol = np.ascontiguousarray(inv.a * cos_a + inv.b * sin_a)
    drow = np.ascontiguousarray(inv.d * cos_a + inv.e * sin_a)
    col0, row0 = terrain.pixel_coords(targets_xy[:, 0], targets_xy[:, 1])
    col0, row0 = np.ascontiguousarray(col0), np.ascontiguousarray(row0)
    step = terrain.cell_m / 2.0
    start_s = 1e-3 * terrain.cell_m
    z = terrain.elevation_m

    def run(lo: int, hi: int) -> None:
        _reach_kernel(
            z,
            col0[lo:hi],
            row0[lo:hi],
            ground[lo:hi],
            height[lo:hi],
            cone[lo:hi],
            dcol,
            drow,
            step,
            start_s,
            reach[lo:hi],
        )

    in_threads(run, m, workers, _MIN_PARALLEL_TARGETS, 4)
    return reach


def visibility_regions(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    samples: int,
    workers: int | None = 1,
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
    workers
        Threads for the ray walk (None: every core).
    """
    az = azimuths(samples)
    reach = ray_reach(terrain, targets_xy, ground_m, camera, az, workers)
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

    Exact on the DEM's bilinear surface
    (:func:`urpt_gcs.visibility.segments.clear_of_terrain`): blocked when the terrain rises
    above the segment anywhere, or the segment crosses unknown ground.
    """
    return clear_of_terrain(terrain, eye_xyz, target_xyz, workers)
