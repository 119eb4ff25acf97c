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

import itertools
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
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
from urpt_gcs.visibility.segments import clear_of_terrain, resolve_workers

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
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError(
                f"--fov {self.fov_deg} is outside (0, 90): give the camera half-angle in degrees"
            )
        if not math.isfinite(self.altitude_m):
            raise SettingsError(f"--altitude {self.altitude_m} is not a number")
        if self.gsd_cm is not None:
            if self.frame is None:
                raise SettingsError(
                    "--gsd needs the camera's pixels: give --camera NAME or --sensor, --focal "
                    "and --image"
                )
            if not (math.isfinite(self.gsd_cm) and 0.0 < self.gsd_cm <= 1000.0):
                raise SettingsError(f"--gsd {self.gsd_cm} cm is out of range: give 0 to 1000 cm")
        if not 1 <= self.headings <= 180:
            raise SettingsError(f"--headings {self.headings} is out of range: give 1 to 180")

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
    ) -> BoolArray:
        """Whether each target lies in the picture taken from ``eye_xy[k]`` (terrain aside).

        The cone and the GSD distance; for a frame camera, inside the frame turned by
        ``heading_deg[k]`` (needed then).
        """
        eye = np.asarray(eye_xy, dtype=np.float64).reshape(-1, 2)
        tgt = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
        ground = np.asarray(ground_m, dtype=np.float64).reshape(-1)
        dx, dy = tgt[:, 0] - eye[:, 0], tgt[:, 1] - eye[:, 1]
        ok: BoolArray = np.hypot(dx, dy) <= self.cone_radius_m(ground)
        if self.frame is None:
            return ok
        if heading_deg is None:
            raise ValueError("a frame camera needs the heading of every photo")
        h = np.maximum(self.altitude_m - ground, 0.0)
        ok &= in_frame(self.frame, dx, dy, h, heading_deg)
        return ok

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
        raise SettingsError(f"--samples {samples} is below 3: use at least 3 azimuths")
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


def _in_threads(
    run: Callable[[int, int], None], count: int, workers: int | None, least: int, parts: int
) -> None:
    """``run(lo, hi)`` over ``0 .. count`` in ``parts`` ranges per thread, a thread per
    ``least`` items at most (one range when a single thread is used)."""
    threads = min(resolve_workers(workers), max(count // least, 1))
    if threads <= 1:
        run(0, count)
        return
    bounds = np.linspace(0, count, parts * threads + 1).astype(np.intp).tolist()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for future in [pool.submit(run, lo, hi) for lo, hi in itertools.pairwise(bounds)]:
            future.result()


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

    _in_threads(run, m, workers, _MIN_PARALLEL_TARGETS, 4)
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


# Sectors of the outer star each target's region is bounded by: the pieces of the lower
# bound follow it to half a degree.
STAR_SECTORS = 720


@njit(cache=True)
def _box_range(z, col0, row0, a, b, d, e, s0, s1, t0, t1, scale):  # type: ignore[no-untyped-def]
    """Over the bounding box of the annular sector ``s0 <= s <= s1, t0 <= t <= t1`` around
    pixel ``(col0, row0)``: the least and greatest height of the bilinear surface and a
    bound of its slope (metres per metre). ``(-inf, inf, inf)`` when the box reaches
    unknown ground (nodata or off the grid), NaNs when it lies wholly off the grid."""
    c0, c1 = math.cos(t0), math.cos(t1)
    n0, n1 = math.sin(t0), math.sin(t1)
    xs = (s0 * c0, s0 * c1, s1 * c0, s1 * c1)
    ys = (s0 * n0, s0 * n1, s1 * n0, s1 * n1)
    x_lo, x_hi = min(xs), max(xs)
    y_lo, y_hi = min(ys), max(ys)
    # The arc's extreme points where it crosses an axis direction.
    for q in range(5):
        ang = q * 0.5 * math.pi
        if t0 <= ang <= t1:
            x_lo, x_hi = min(x_lo, s1 * math.cos(ang)), max(x_hi, s1 * math.cos(ang))
            y_lo, y_hi = min(y_lo, s1 * math.sin(ang)), max(y_hi, s1 * math.sin(ang))
    c_lo, c_hi, r_lo, r_hi = np.inf, -np.inf, np.inf, -np.inf
    for x in (x_lo, x_hi):
        for y in (y_lo, y_hi):
            c = col0 + a * x + b * y
            r = row0 + d * x + e * y
            c_lo, c_hi = min(c_lo, c), max(c_hi, c)
            r_lo, r_hi = min(r_lo, r), max(r_hi, r)
    rows, cols = z.shape
    if c_lo > cols - 0.5 or r_lo > rows - 0.5 or c_hi < -0.5 or r_hi < -0.5:
        # Wholly off the grid: a line of sight through it runs over unknown ground.
        return np.nan, np.nan, np.nan
    if c_lo < -0.5 or r_lo < -0.5 or c_hi > cols - 0.5 or r_hi > rows - 0.5:
        return -np.inf, np.inf, np.inf
    # Along each axis the bilinear surface is linear between lines through pixel centres,
    # so over the box it is least and greatest at the box's corners and where those lines
    # cross it or its edges.
    lo, hi = np.inf, -np.inf
    nc = math.floor(c_hi) - math.floor(c_lo) + 2
    nr = math.floor(r_hi) - math.floor(r_lo) + 2
    for jr in range(nr):
        r = r_lo if jr == 0 else (r_hi if jr == nr - 1 else math.floor(r_lo) + jr)
        for ic in range(nc):
            c = c_lo if ic == 0 else (c_hi if ic == nc - 1 else math.floor(c_lo) + ic)
            v = bilinear_at(z, c, r)
            if math.isnan(v):
                return -np.inf, np.inf, np.inf
            lo, hi = min(lo, v), max(hi, v)
    # Within a cell the slope along columns is at most the larger difference of its two
    # rows' nodes (and likewise along rows); beyond the outermost centres it is zero.
    gc, gr = 0.0, 0.0
    for j in range(max(math.floor(r_lo), 0), min(math.floor(r_hi), rows - 2) + 1):
        for i in range(max(math.floor(c_lo), 0), min(math.floor(c_hi), cols - 2) + 1):
            gc = max(gc, abs(z[j, i + 1] - z[j, i]), abs(z[j + 1, i + 1] - z[j + 1, i]))
            gr = max(gr, abs(z[j + 1, i] - z[j, i]), abs(z[j + 1, i + 1] - z[j, i + 1]))
    return lo, hi, math.sqrt(gc * gc + gr * gr) * scale


# A band that may end the reach is walked again in this many slices (the reach a band
# gives is loose by about its slope times its width).
_FINE_SLICES = 16


@njit(cache=True, nogil=True)
def _band_reach(s, lo, ground, height):  # type: ignore[no-untyped-def]
    """How far a sector is seen at most past ground at least ``lo`` from ``s`` on (inf when
    that ground is no higher than the target's): the sight line to a plane point at ``S``
    passes ``s`` at ``ground + s height / S``, below ``lo`` once ``S > s height / (lo -
    ground)``, and only passes ``s`` at all when ``S > s``."""
    if not lo - 2e-6 > ground:
        return np.inf
    return max(s, height * s / (lo - 2e-6 - ground))


@njit(cache=True, nogil=True)
def _fine_reach(z, col0, row0, a, b, d, e, s0, step, t0, t1, scale, ground, height):  # type: ignore[no-untyped-def]
    """The least reach the slices of the band ``[s0, s0 + step]`` of a sector give, each
    from its own lowest ground (inf when none hides anything)."""
    reach = np.inf
    width = step / _FINE_SLICES
    for q in range(_FINE_SLICES):
        s = s0 + q * width
        if s <= 0.0:
            continue
        lo = _box_range(z, col0, row0, a, b, d, e, s, s + width, t0, t1, scale)[0]
        if not math.isnan(lo):
            reach = min(reach, _band_reach(s, lo, ground, height))
    return reach


@njit(cache=True, nogil=True)
def _sector_reach(z, col0, row0, ground, height, cone, least, a, b, d, e, step, t0, t1, scale):  # type: ignore[no-untyped-def]
    """For the target at pixel ``(col0, row0)`` and the sector of azimuths ``[t0, t1]``: a
    reach no point of the sector that sees the target exceeds, and one up to which every
    point does.

    The sector is walked in bands ``[s0, s0 + step]``; over a band the surface lies between
    ``lo`` and ``hi`` and its slope is at most ``g``. A plane point at ``s`` of the sector is
    hidden once the terrain at some ``s' < s`` on its ray rises above the line of sight,
    ``z(s') > z_p + s' h / s``: terrain at least ``lo`` over the band hides every
    ``s > s0 h / (lo - z_p)`` (and ``s > s0``), the rule of the exact ray walk with the band's
    lowest ground. Points are certainly seen while ``(z(s') - z_p) / s' <= h / s`` for every
    ``s'`` before them: in a band that ratio is at most ``(hi - z_p) / s0``, and at most the
    steepest slope ``G`` of the bands from the target to it (``z(s') - z_p <= G s'``).
    """
    best = cone
    sure = least
    steepest = 0.0
    i = 0
    while i * step < max(best, sure):
        s0 = i * step
        lo, hi, g = _box_range(z, col0, row0, a, b, d, e, s0, s0 + step, t0, t1, scale)
        if math.isnan(lo):
            # Every point from here on is off the grid, or seen across it.
            best = min(best, s0)
            sure = min(sure, s0)
            break
        if s0 == 0.0:
            # The first band gives nothing from its start, the target itself; its slices
            # give the slope the target stands on.
            best = min(
                best,
                _fine_reach(z, col0, row0, a, b, d, e, s0, step, t0, t1, scale, ground, height),
            )
        elif s0 < best:
            reach = _band_reach(s0, lo, ground, height)
            if _band_reach(s0, hi, ground, height) < best:
                # A band that may end the reach: its slices, each with its own lowest
                # ground, from its own start, are tighter. (A slice starts at s0 or later
                # on ground no higher than hi: no slice can end it before this.)
                reach = min(
                    reach,
                    _fine_reach(z, col0, row0, a, b, d, e, s0, step, t0, t1, scale, ground, height),
                )
            best = min(best, reach)
        if s0 < sure and math.isinf(hi):
            sure = s0
        elif s0 < sure:
            steepest = max(steepest, g)
            ratio = 0.0
            if hi > ground:
                ratio = steepest
                if s0 > 0.0:
                    ratio = min(ratio, (hi - ground) / s0)
            if ratio > 0.0:
                sure = min(sure, height / ratio)
        i += 1
    return best, min(sure, best)


@njit(cache=True, nogil=True)
def _star_kernel(z, col0, row0, ground, height, cone, least, a, b, d, e, step, outer, inner):  # type: ignore[no-untyped-def]
    """Per target ``k`` and sector ``j`` (of ``outer.shape[1]`` around it) the reaches of
    :func:`_sector_reach`, into ``outer[k, j]`` and ``inner[k, j]``."""
    sectors = outer.shape[1]
    scale = math.sqrt(a * a + b * b + d * d + e * e)
    for k in range(col0.shape[0]):
        for j in range(sectors):
            t0 = 2.0 * math.pi * j / sectors
            t1 = 2.0 * math.pi * (j + 1) / sectors
            outer[k, j], inner[k, j] = _sector_reach(
                z, col0[k], row0[k], ground[k], height[k], cone[k], least[k],
                a, b, d, e, step, t0, t1, scale,
            )  # fmt: skip


@njit(cache=True, nogil=True)
def _wedge_kernel(z, col0, row0, ground, height, cone, a, b, d, e, step, t0, t1, outer):  # type: ignore[no-untyped-def]
    """Per wedge ``w`` (of the target at pixel ``(col0[w], row0[w])``, azimuths
    ``[t0[w], t1[w]]``) the outer reach of :func:`_sector_reach` into ``outer[w]``."""
    scale = math.sqrt(a * a + b * b + d * d + e * e)
    for w in range(col0.shape[0]):
        outer[w] = _sector_reach(
            z, col0[w], row0[w], ground[w], height[w], cone[w], 0.0,
            a, b, d, e, step, t0[w], t1[w], scale,
        )[0]  # fmt: skip


def star_reach(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    sectors: int = STAR_SECTORS,
    workers: int | None = 1,
) -> tuple[FloatArray, FloatArray]:
    """Per target and angular sector, where its visibility region certainly ends and where
    it certainly still holds, shapes (targets, sectors) each.

    Sector ``j`` spans the azimuths ``[2 pi j / K, 2 pi (j + 1) / K]`` (counter-clockwise
    from east) around the target's nadir. No point of the sector farther than the outer
    reach sees the target; every point of it no farther than the inner reach does (at every
    heading of a frame camera). Both hold for the DEM's bilinear surface exactly: along a ray
    the seen set is an interval from the nadir, and each band of the sector is walked with the
    lowest (outer) and highest (inner) ground its cells may hold there. Unknown ground hides
    nothing for the outer reach, bar ground wholly off the grid (a line of sight over it is
    not known to be clear), and ends the inner one.
    """
    targets_xy = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    ground = np.ascontiguousarray(ground_m, dtype=np.float64)
    m = len(targets_xy)
    outer = np.zeros((m, sectors), dtype=np.float64)
    inner = np.zeros((m, sectors), dtype=np.float64)
    if m == 0:
        return outer, inner
    height = camera.altitude_m - ground
    cone = np.ascontiguousarray(camera.cone_radius_m(ground))
    # A hair inside what is seen at every heading, so that rounding never claims too much.
    least = np.ascontiguousarray(camera.least_half_width_m(ground) * (1.0 - 1e-9))
    inv = ~terrain.transform
    col0, row0 = terrain.pixel_coords(targets_xy[:, 0], targets_xy[:, 1])
    col0, row0 = np.ascontiguousarray(col0), np.ascontiguousarray(row0)
    step = terrain.cell_m / 2.0
    z = terrain.elevation_m

    def run(lo: int, hi: int) -> None:
        _star_kernel(
            z, col0[lo:hi], row0[lo:hi], ground[lo:hi], height[lo:hi], cone[lo:hi],
            least[lo:hi], inv.a, inv.b, inv.d, inv.e, step, outer[lo:hi], inner[lo:hi],
        )  # fmt: skip

    _in_threads(run, m, workers, 4, 2)
    inner *= 1.0 - 1e-9
    return outer, inner


# A sector walked again for a tighter outer reach is split into this many wedges, each
# walked in bands this many times narrower than the star's.
FINER_SPLIT = 8
FINER_BANDS = 4


def finer_reach(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    sectors: npt.ArrayLike,
    sector: npt.ArrayLike,
    workers: int | None = 1,
) -> FloatArray:
    """A tighter outer reach for sector ``sector[i]`` (of ``sectors`` around target ``i``,
    one row of ``targets_xy`` and ``ground_m`` per sector asked for): the greatest of its
    wedges' reaches (:func:`finer_wedges`)."""
    got: FloatArray = finer_wedges(
        terrain, targets_xy, ground_m, camera, sectors, sector, workers
    ).max(axis=1)
    return got


def finer_wedges(
    terrain: Terrain,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    sectors: npt.ArrayLike,
    sector: npt.ArrayLike,
    workers: int | None = 1,
    split: int = FINER_SPLIT,
    bands: int = FINER_BANDS,
) -> FloatArray:
    """Sector ``sector[i]`` (of ``sectors[i]``, or of ``sectors``, around target ``i``) split
    into ``split`` wedges, shape (sectors asked, split): each wedge walked as
    :func:`star_reach` walks a sector, in bands ``bands`` times narrower, so no point of the
    wedge farther than its reach sees the target."""
    xy = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    j = np.asarray(sector, dtype=np.int64).reshape(-1)
    n = len(j)
    if n == 0:
        return np.zeros((0, split))
    rep = np.repeat(np.arange(n), split)
    ground = np.ascontiguousarray(np.asarray(ground_m, dtype=np.float64)[rep])
    height = np.ascontiguousarray(camera.altitude_m - ground)
    cone = np.ascontiguousarray(camera.cone_radius_m(ground))
    col0, row0 = terrain.pixel_coords(xy[rep, 0], xy[rep, 1])
    col0, row0 = np.ascontiguousarray(col0), np.ascontiguousarray(row0)
    part = np.tile(np.arange(split), n)
    width = 2.0 * math.pi / np.broadcast_to(np.asarray(sectors, dtype=np.float64), (n,))[rep]
    t0 = np.ascontiguousarray(width * (j[rep] + part / split))
    t1 = np.ascontiguousarray(width * (j[rep] + (part + 1) / split))
    inv = ~terrain.transform
    step = terrain.cell_m / 2.0 / bands
    outer = np.zeros(len(rep))

    def run(lo: int, hi: int) -> None:
        _wedge_kernel(
            terrain.elevation_m, col0[lo:hi], row0[lo:hi], ground[lo:hi], height[lo:hi],
            cone[lo:hi], inv.a, inv.b, inv.d, inv.e, step, t0[lo:hi], t1[lo:hi], outer[lo:hi],
        )  # fmt: skip

    _in_threads(run, len(rep), workers, 64, 2)
    got: FloatArray = outer.reshape(n, split)
    return got
