"""Straight segments against the DEM's bilinear surface, exactly.

Every terrain test of a segment — a viewpoint's line of sight, a leg's clearance, a replayed
track — asks one question: how far does the terrain rise above the segment, at most, and how
much of the segment runs over unknown ground? Sampling cannot answer it: a one-pixel wall or
spike between two samples is missed. Here the answer is exact.

Pixel values sit at pixel centres; between four centres the surface is bilinear. A straight
segment crosses the lines through pixel centres at known parameters; between two crossings it
stays in one cell, where both the surface height and the segment's height are polynomials in
the segment parameter ``t`` (quadratic and linear), so their difference is a quadratic whose
maximum on the piece is at one of its ends or at its stationary point. Between the outermost
centres and the raster's edge the surface takes the edge values (as
:meth:`urpt_gcs.site.terrain.Terrain.sample` does); beyond the edge, and in any cell touching a
nodata value, the ground is unknown.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.site.terrain import Terrain

__all__ = [
    "SIGHT_TOLERANCE_M",
    "SegmentProfile",
    "clear_of_terrain",
    "in_threads",
    "resolve_workers",
    "segment_profile",
]

# Terrain less than this above a line of sight does not block it: the target itself lies on
# the surface, so at its end the difference is zero up to rounding.
SIGHT_TOLERANCE_M = 1e-6
# Below this many segments a thread pool costs more than it saves.
_MIN_PARALLEL_SEGMENTS = 4096


def resolve_workers(workers: int | None) -> int:
    """The number of threads segment tests use: ``workers``, or every core when None."""
    return max(1, os.cpu_count() or 1) if workers is None else max(1, int(workers))


def in_threads(
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


@dataclass(frozen=True, slots=True)
class SegmentProfile:
    """How segments meet the terrain, one entry per segment.

    ``excess_m`` is the largest height of the known terrain above the segment (negative when
    the segment clears it everywhere; ``-inf`` when no part of it is over known ground),
    ``at`` the fraction of the way from start to end where that maximum is, and
    ``unknown_fraction`` the fraction of the segment's horizontal length over unknown ground.
    """

    excess_m: FloatArray
    at: FloatArray
    unknown_fraction: FloatArray


@njit(cache=True)
def _corner(z, row, col):  # type: ignore[no-untyped-def]
    # Cells of the padded grid: index 0 and the last index repeat the edge values.
    rows, cols = z.shape
    r = min(max(row - 1, 0), rows - 1)
    c = min(max(col - 1, 0), cols - 1)
    return z[r, c]


@njit(cache=True)
def _point_value(z, c, r):  # type: ignore[no-untyped-def]
    """The surface at one point of the padded grid; NaN when a corner that carries weight
    there is nodata."""
    rows, cols = z.shape
    i = min(max(math.floor(c), 0), cols)
    j = min(max(math.floor(r), 0), rows)
    u = c - i
    v = r - j
    total = 0.0
    for dj in range(2):
        for di in range(2):
            w = (u if di else 1.0 - u) * (v if dj else 1.0 - v)
            if w > 0.0:
                value = _corner(z, j + dj, i + di)
                if math.isnan(value):
                    return np.nan
                total += w * value
    return total


@njit(cache=True)
def _clip(p0, d, lo, hi, t0, t1):  # type: ignore[no-untyped-def]
    """Liang–Barsky clip of ``p0 + t d`` to ``[lo, hi]``, narrowing ``[t0, t1]``."""
    if d == 0.0:
        if p0 < lo or p0 > hi:
            return 1.0, 0.0
        return t0, t1
    a = (lo - p0) / d
    b = (hi - p0) / d
    if a > b:
        a, b = b, a
    return max(t0, a), min(t1, b)


@njit(cache=True, nogil=True)
def _profile_kernel(z, c0, r0, h0, c1, r1, h1, excess, at, unknown):  # type: ignore[no-untyped-def]
    """Fill ``excess``, ``at`` and ``unknown`` for segments in padded pixel coordinates.

    The padded grid has a ring of edge values around ``z``: its centre ``(i, j)`` is the source
    centre ``(i - 1, j - 1)``, and the surface is known on ``[0.5, cols + 0.5] x [0.5, rows +
    0.5]``.
    """
    rows, cols = z.shape
    n = c0.shape[0]
    for k in range(n):
        dc = c1[k] - c0[k]
        dr = r1[k] - r0[k]
        dh = h1[k] - h0[k]
        ta, tb = _clip(c0[k], dc, 0.5, cols + 0.5, 0.0, 1.0)
        ta, tb = _clip(r0[k], dr, 0.5, rows + 0.5, ta, tb)
        best = -np.inf
        best_t = 0.0
        if tb < ta:
            excess[k] = best
            at[k] = 0.0
            unknown[k] = 1.0
            continue
        lost = ta + (1.0 - tb)
        # Crossings of the integer column and row lines strictly inside (ta, tb), in order.
        ca = c0[k] + dc * ta
        cb = c0[k] + dc * tb
        ra = r0[k] + dr * ta
        rb = r0[k] + dr * tb
        nc = 0
        if dc > 0.0:
            cfirst = math.floor(ca) + 1.0
            nc = max(int(math.ceil(cb) - cfirst), 0)
            cstep = 1.0
        elif dc < 0.0:
            cfirst = math.ceil(ca) - 1.0
            nc = max(int(cfirst - math.floor(cb)), 0)
            cstep = -1.0
        else:
            cfirst = 0.0
            cstep = 0.0
        nr = 0
        if dr > 0.0:
            rfirst = math.floor(ra) + 1.0
            nr = max(int(math.ceil(rb) - rfirst), 0)
            rstep = 1.0
        elif dr < 0.0:
            rfirst = math.ceil(ra) - 1.0
            nr = max(int(rfirst - math.floor(rb)), 0)
            rstep = -1.0
        else:
            rfirst = 0.0
            rstep = 0.0
        ic = 0
        ir = 0
        t_prev = ta
        while True:
            tc = (cfirst + cstep * ic - c0[k]) / dc if ic < nc else np.inf
            tr = (rfirst + rstep * ir - r0[k]) / dr if ir < nr else np.inf
            t_next = min(tc, tr, tb)
            if tc <= t_next:
                ic += 1
            if tr <= t_next:
                ir += 1
            if t_next > t_prev or (t_next == tb and t_prev == ta):
                tm = 0.5 * (t_prev + t_next)
                cm = c0[k] + dc * tm
                rm = r0[k] + dr * tm
                i0 = min(max(math.floor(cm), 0), cols)
                j0 = min(max(math.floor(rm), 0), rows)
                # A piece running along a centre line borders two cells; the surface on the
                # line comes from the line's own centres, so either known cell gives it.
                on_col = dc == 0.0 and cm == math.floor(cm) and i0 > 0
                on_row = dr == 0.0 and rm == math.floor(rm) and j0 > 0
                known = False
                i = i0
                j = j0
                z00 = z10 = z01 = z11 = np.nan
                for shift in range(4):
                    if (shift & 1 and not on_col) or (shift & 2 and not on_row):
                        continue
                    i = i0 - (shift & 1)
                    j = j0 - (shift >> 1)
                    z00 = _corner(z, j, i)
                    z10 = _corner(z, j, i + 1)
                    z01 = _corner(z, j + 1, i)
                    z11 = _corner(z, j + 1, i + 1)
                    if not (
                        math.isnan(z00) or math.isnan(z10) or math.isnan(z01) or math.isnan(z11)
                    ):
                        known = True
                        break
                if not known:
                    # A segment with no horizontal extent is wholly over this cell.
                    lost += t_next - t_prev if (dc != 0.0 or dr != 0.0) else 1.0
                    # The piece's ends may still be known ground: on a line of centres the
                    # corners across it carry no weight.
                    for t in (t_prev, t_next):
                        surface = _point_value(z, c0[k] + dc * t, r0[k] + dr * t)
                        if not math.isnan(surface):
                            f = surface - (h0[k] + dh * t)
                            if f > best:
                                best = f
                                best_t = t
                else:
                    a1 = z10 - z00
                    a2 = z01 - z00
                    e = z00 - z10 - z01 + z11
                    u0 = c0[k] - i
                    v0 = r0[k] - j
                    # f(t) = A t^2 + B t + C: surface minus segment height in this cell.
                    qa = e * dc * dr
                    qb = a1 * dc + a2 * dr + e * (u0 * dr + v0 * dc) - dh
                    for side in range(3):
                        if side == 0:
                            t = t_prev
                        elif side == 1:
                            t = t_next
                        else:
                            if qa >= 0.0:
                                continue
                            t = -qb / (2.0 * qa)
                            if not (t_prev < t < t_next):
                                continue
                        u = u0 + dc * t
                        v = v0 + dr * t
                        surface = z00 + a1 * u + a2 * v + e * u * v
                        f = surface - (h0[k] + dh * t)
                        if f > best:
                            best = f
                            best_t = t
                t_prev = t_next
            if t_next >= tb:
                break
        excess[k] = best
        at[k] = best_t
        unknown[k] = min(max(lost, 0.0), 1.0)


def segment_profile(
    terrain: Terrain,
    start_xyz: npt.ArrayLike,
    end_xyz: npt.ArrayLike,
    workers: int | None = 1,
) -> SegmentProfile:
    """How far the terrain rises above each straight segment, exactly.

    Parameters
    ----------
    terrain
        The DEM window; its bilinear surface is the ground.
    start_xyz, end_xyz
        (n, 3) ends of the segments: x, y in the terrain's CRS and height in metres.
    workers
        Threads to share the segments among (None: every core); the compiled kernel runs
        without the GIL, and each segment's answer does not depend on how they are shared.

    Returns
    -------
    SegmentProfile
        Per segment, the largest height of the terrain above it, where, and the fraction over
        unknown ground.
    """
    a = np.asarray(start_xyz, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(end_xyz, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError("segment_profile needs as many starts as ends")
    ca, ra = terrain.pixel_coords(a[:, 0], a[:, 1])
    cb, rb = terrain.pixel_coords(b[:, 0], b[:, 1])
    n = len(a)
    # A segment with a non-finite end is over no ground anyone knows.
    excess = np.full(n, -np.inf)
    at = np.zeros(n)
    unknown = np.ones(n)
    ok = np.flatnonzero(
        np.isfinite(ca)
        & np.isfinite(ra)
        & np.isfinite(cb)
        & np.isfinite(rb)
        & np.isfinite(a[:, 2])
        & np.isfinite(b[:, 2])
    )
    if ok.size:
        e, t, u = (np.empty(ok.size) for _ in range(3))
        args = (
            ca[ok] + 1.0,
            ra[ok] + 1.0,
            np.ascontiguousarray(a[ok, 2]),
            cb[ok] + 1.0,
            rb[ok] + 1.0,
            np.ascontiguousarray(b[ok, 2]),
        )
        z = terrain.elevation_m

        def run(lo: int, hi: int) -> None:
            c0, r0, h0, c1, r1, h1 = (v[lo:hi] for v in args)
            _profile_kernel(z, c0, r0, h0, c1, r1, h1, e[lo:hi], t[lo:hi], u[lo:hi])

        threads = min(resolve_workers(workers), max(ok.size // (_MIN_PARALLEL_SEGMENTS // 4), 1))
        if threads <= 1 or ok.size < _MIN_PARALLEL_SEGMENTS:
            run(0, ok.size)
        else:
            # Several chunks per thread even out segments of very different lengths.
            bounds = np.linspace(0, ok.size, 4 * threads + 1).astype(np.intp).tolist()
            with ThreadPoolExecutor(max_workers=threads) as pool:
                for future in [pool.submit(run, lo, hi) for lo, hi in itertools.pairwise(bounds)]:
                    future.result()
        excess[ok], at[ok], unknown[ok] = e, t, u
    return SegmentProfile(excess_m=excess, at=at, unknown_fraction=unknown)


def clear_of_terrain(
    terrain: Terrain,
    start_xyz: npt.ArrayLike,
    end_xyz: npt.ArrayLike,
    workers: int | None = 1,
) -> BoolArray:
    """Whether each segment runs over known ground and nowhere below the terrain."""
    profile = segment_profile(terrain, start_xyz, end_xyz, workers)
    clear: BoolArray = (profile.unknown_fraction == 0.0) & (profile.excess_m <= SIGHT_TOLERANCE_M)
    return clear
