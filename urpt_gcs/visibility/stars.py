"""Outer and inner stars: per target and angular sector, where its visibility region
certainly ends and where it certainly still holds.

The certified lower bound (:mod:`urpt_gcs.bound.certificate`) needs, for every target, a
region that holds every point of the plane that sees it: the outer star. Each sector's reach
is walked in bands, with the lowest (outer) and highest (inner) ground the band's cells may
hold, so both stars hold for the DEM's bilinear surface exactly (see :func:`star_reach`);
:func:`finer_wedges` walks a sector again in narrower wedges for a tighter outer reach.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from urpt_gcs.arrays import FloatArray
from urpt_gcs.site.terrain import Terrain, bilinear_at
from urpt_gcs.visibility.regions import Camera
from urpt_gcs.visibility.segments import in_threads

__all__ = [
    "FINER_BANDS",
    "FINER_SPLIT",
    "STAR_SECTORS",
    "finer_reach",
    "finer_wedges",
    "star_reach",
]

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

    in_threads(run, m, workers, 4, 2)
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

    in_threads(run, len(rep), workers, 64, 2)
    got: FloatArray = outer.reshape(n, split)
    return got
