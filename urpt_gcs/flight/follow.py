"""Legs bent into a flight band: waypoints over the leg's own horizontal line.

A straight leg between two points inside a :class:`~urpt_gcs.flight.band.FlightBand` may leave
it over a ridge or a valley. :func:`follow_terrain` puts a few waypoints on the leg's horizontal
line so that every straight piece stays inside, each piece checked exactly
(:func:`~urpt_gcs.flight.band.inside_band`), and :func:`path_in_band` does so for every leg of
a path.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.errors import PlanError
from urpt_gcs.flight.band import FlightBand, band_profile, inside_band, negated_terrain
from urpt_gcs.site.terrain import Terrain

__all__ = ["follow_terrain", "path_in_band"]

# follow_terrain samples the surface this many times per DEM cell along a leg, and more finely
# only where a piece between two samples cannot be kept inside.
_SAMPLES_PER_CELL = (4, 16, 64)
# Waypoints keep this share of the band's width from either limit where they can, ...
_INSET = 0.1
# ... growing from nothing at a leg's given ends at this many metres per metre.
_INSET_RAMP = 0.1
# How many samples the first look ahead from a point covers; it doubles while all are reached.
_LOOKAHEAD = 256
# Heights within this of a limit count as on it (rounding).
_TOLERANCE_M = 1e-6


def _leg_error(name: str, a: FloatArray, b: FloatArray, band: FlightBand, why: str) -> PlanError:
    return PlanError(
        f"{name} from ({a[0]:.1f}, {a[1]:.1f}) to ({b[0]:.1f}, {b[1]:.1f}) {why}: the flight "
        f"band {band.floor_m:g}:{band.ceiling_m:g} m cannot be kept along it"
    )


def follow_terrain(
    terrain: Terrain,
    a_xyz: npt.ArrayLike,
    b_xyz: npt.ArrayLike,
    band: FlightBand,
    aim_m: float | None = None,
    *,
    negated: Terrain | None = None,
    name: str = "the leg",
) -> FloatArray:
    """Waypoints that keep a leg inside the band, over its own horizontal line.

    The surface is sampled along the line every quarter cell; from each point the next one is
    put as far on as a straight piece can reach while every sample between stays within the
    band (each sample bounds the piece's slope from above and below, so the slopes left are an
    interval), preferring the farthest point from which ``b`` is reached in turn, at the height
    nearest ``aim_m`` above the surface (or the straight line on to ``b``) that leaves some
    room; the piece is then checked exactly (:func:`~urpt_gcs.flight.band.inside_band`) and
    drawn back until it passes. Samples are held a tenth of the band's width inside either
    limit where the given ends allow. Where no piece between two samples passes, the leg is
    sampled again 4 and then 16 times finer.

    Parameters
    ----------
    terrain
        The DEM window.
    a_xyz, b_xyz
        The leg's ends (x, y, height), both inside the band.
    band
        The heights above the surface allowed.
    aim_m
        The height above the surface to put waypoints at, where they can be (None: on the
        straight line from the last one on to ``b``, so that the vehicle climbs and descends
        only where the band makes it).
    negated
        :func:`~urpt_gcs.flight.band.negated_terrain` of ``terrain`` covering the leg (made
        here when None).
    name
        What the leg is called in an error.

    Returns
    -------
    FloatArray
        (k, 3) the waypoints strictly between ``a`` and ``b``, in order; (0, 3) when the
        straight leg stays inside the band.

    Raises
    ------
    ValueError
        When an end is not inside the band.
    PlanError
        When the leg crosses unknown ground, or the band is too narrow for the surface.
    """
    a = np.asarray(a_xyz, dtype=np.float64).reshape(3)
    b = np.asarray(b_xyz, dtype=np.float64).reshape(3)
    if negated is None:
        negated = negated_terrain(terrain, a, b)
    tol = _TOLERANCE_M
    ends = terrain.sample(np.array([a[0], b[0]]), np.array([a[1], b[1]]))
    height = np.array([a[2], b[2]]) - ends
    if not np.all((height >= band.floor_m - tol) & (height <= band.ceiling_m + tol)):
        raise ValueError(f"{name}: both ends must be inside the flight band")
    whole = band_profile(terrain, a, b, negated=negated)
    if whole.unknown_fraction[0] > 0.0:
        raise _leg_error(name, a, b, band, "crosses unknown ground")
    if whole.lowest_m[0] >= band.floor_m - tol and whole.highest_m[0] <= band.ceiling_m + tol:
        return np.empty((0, 3))
    length = float(np.hypot(b[0] - a[0], b[1] - a[1]))
    if length > 0.0:  # (both ends inside, one above the other: only rounding can fail it)
        for per_cell in _SAMPLES_PER_CELL:
            n = max(math.ceil(length * per_cell / terrain.cell_m), 1)
            waypoints = _follow(terrain, negated, a, b, band, aim_m, n)
            if waypoints is not None:
                return waypoints
    raise _leg_error(name, a, b, band, "climbs too steeply for the band")


def _follow(
    terrain: Terrain,
    negated: Terrain,
    a: FloatArray,
    b: FloatArray,
    band: FlightBand,
    aim_m: float | None,
    n: int,
) -> FloatArray | None:
    """:func:`follow_terrain`'s waypoints with ``n`` steps between samples; None when some
    piece cannot be kept inside at that spacing."""
    tol = _TOLERANCE_M
    length = float(np.hypot(b[0] - a[0], b[1] - a[1]))
    u = np.arange(n + 1) / n
    surface = terrain.sample(a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]))
    if not np.all(np.isfinite(surface)):  # (known ground by the exact check: only rounding)
        return None
    dist = u * length
    inset = np.minimum(_INSET * band.width_m, _INSET_RAMP * np.minimum(dist, length - dist))
    low = surface + band.floor_m + inset
    high = surface + band.ceiling_m - inset
    aim = None if aim_m is None else surface + aim_m

    # The heights at each sample from which a straight piece reaches b with every sample
    # between in the band: slopes back from b, narrowed sample by sample towards a.
    rest = length - dist
    with np.errstate(divide="ignore", invalid="ignore"):
        back_lo = np.maximum.accumulate(((low - b[2]) / rest)[:-1][::-1])[::-1]
        back_hi = np.minimum.accumulate(((high - b[2]) / rest)[:-1][::-1])[::-1]
    sees_lo, sees_hi = b[2] + back_lo * rest[:-1], b[2] + back_hi * rest[:-1]

    def point(i: int, z: float) -> FloatArray:
        return np.array([a[0] + u[i] * (b[0] - a[0]), a[1] + u[i] * (b[1] - a[1]), z])

    def tries(i0: int, z0: float) -> Iterator[tuple[int, float]]:
        """Where the next piece from sample ``i0`` at height ``z0`` may end, best first."""

        def pick(j: int, lo: float, hi: float) -> float:
            # Without a height to aim at, the straight line on to b: the vehicle climbs and
            # descends only where the band makes it.
            room = 0.1 * (hi - lo)
            share = (dist[j] - dist[i0]) / max(length - dist[i0], 1e-9)
            want = z0 + (b[2] - z0) * share if aim is None else aim[j]
            return float(np.clip(want, lo + room, hi - room))

        # Slopes (metres per metre) from (i0, z0) that keep samples i0+1 .. e in the band.
        reach = _LOOKAHEAD
        while True:
            e = min(n, i0 + reach)
            d = dist[i0 + 1 : e + 1] - dist[i0]
            z_lo = z0 + np.maximum.accumulate((low[i0 + 1 : e + 1] - z0) / d) * d
            z_hi = z0 + np.minimum.accumulate((high[i0 + 1 : e + 1] - z0) / d) * d
            # The slopes left only narrow, so the samples reached are a prefix (never empty).
            far = max(int(np.count_nonzero(z_lo <= z_hi)), 1)
            if far < e - i0 or e == n:
                break
            reach *= 2
        if i0 + far == n:
            if z_lo[-1] - tol <= b[2] <= z_hi[-1] + tol:
                yield n, float(b[2])
            far -= 1
        # The farthest sample reached from which b is reached too, ...
        k = np.arange(far)
        lo = np.maximum(z_lo[k], sees_lo[i0 + 1 + k])
        hi = np.minimum(z_hi[k], sees_hi[i0 + 1 + k])
        both = np.flatnonzero(lo <= hi)
        if both.size:
            j = int(both[-1])
            yield i0 + 1 + j, pick(i0 + 1 + j, float(lo[j]), float(hi[j]))
        # ... else the farthest reached, drawn back while the exact check fails ...
        j = i0 + far
        while j > i0:
            yield j, pick(j, float(z_lo[j - i0 - 1]), float(z_hi[j - i0 - 1]))
            j = i0 + (j - i0) * 3 // 4 if j > i0 + 1 else i0
        # ... and at last the band's middle at the next sample.
        if i0 < n - 1:
            yield i0 + 1, float(surface[i0 + 1] + band.mid_m)

    out: list[FloatArray] = []
    i0, z0 = 0, float(a[2])
    while i0 < n:
        p = point(i0, z0)
        for j, z in tries(i0, z0):
            q = b if j == n else point(j, z)
            if inside_band(terrain, p, q, band, negated=negated)[0]:
                break
        else:
            return None
        if j < n:
            out.append(q)
        i0, z0 = j, z
    return np.array(out) if out else np.empty((0, 3))


def path_in_band(
    terrain: Terrain,
    path_xyz: npt.ArrayLike,
    band: FlightBand,
    aim_m: float | None = None,
    workers: int | None = 1,
) -> tuple[FloatArray, IntArray]:
    """A path with waypoints inserted so that every leg stays inside the band.

    Parameters
    ----------
    terrain
        The DEM window.
    path_xyz
        (n, 3) the stops, each inside the band.
    band
        The heights above the surface allowed.
    aim_m
        The height above the surface to put inserted waypoints at, where they can be.
    workers
        Threads for the first check of every leg at once.

    Returns
    -------
    tuple of FloatArray and IntArray
        The (m, 3) path, and per row the index of the stop it is in ``path_xyz`` (-1 for an
        inserted waypoint).

    Raises
    ------
    ValueError
        When a stop is not inside the band.
    PlanError
        When a leg crosses unknown ground or the band is too narrow for the surface.
    """
    path = np.asarray(path_xyz, dtype=np.float64).reshape(-1, 3)
    index = np.arange(len(path), dtype=np.int64)
    if len(path) < 2:
        return path.copy(), index
    negated = negated_terrain(terrain, path[:-1], path[1:])
    fine = inside_band(terrain, path[:-1], path[1:], band, workers, negated=negated)
    pieces: list[FloatArray] = [path[:1]]
    marks: list[IntArray] = [index[:1]]
    for leg in range(len(path) - 1):
        if not fine[leg]:
            extra = follow_terrain(
                terrain,
                path[leg],
                path[leg + 1],
                band,
                aim_m,
                negated=negated,
                name=f"leg {leg + 1}",
            )
            pieces.append(extra)
            marks.append(np.full(len(extra), -1, dtype=np.int64))
        pieces.append(path[leg + 1 : leg + 2])
        marks.append(index[leg + 1 : leg + 2])
    return np.concatenate(pieces), np.concatenate(marks)
