"""A flight band: the heights above the terrain a terrain-following vehicle may fly at.

In terrain-following flight the vehicle may be anywhere from ``floor_m`` to ``ceiling_m``
metres above the DSM's bilinear surface directly below it. :func:`band_profile` gives, per
straight segment, the lowest and the highest height above that surface, exactly, from the
exact segment routine :func:`~urpt_gcs.visibility.segments.segment_profile`: the lowest is
minus the terrain's largest excess over the segment, and the highest is that same excess on
the negated terrain under the negated segment (max(segment - surface)). Bending legs into the
band is :mod:`urpt_gcs.flight.follow`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from affine import Affine

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.segments import segment_profile

__all__ = [
    "MAX_CEILING_M",
    "BandProfile",
    "FlightBand",
    "band_profile",
    "inside_band",
    "negated_terrain",
    "parse_band",
]

# The highest ceiling a band may have, in metres above the surface.
MAX_CEILING_M = 10_000.0


@dataclass(frozen=True, slots=True)
class FlightBand:
    """Heights above the surface a terrain-following vehicle may fly at, in metres.

    Raises
    ------
    SettingsError
        Unless ``0 < floor_m < ceiling_m <= 10000`` (the setting is ``agl_band_m``).
    """

    floor_m: float
    ceiling_m: float

    def __post_init__(self) -> None:
        shown = f"{self.floor_m:g}:{self.ceiling_m:g}"
        if not (math.isfinite(self.floor_m) and math.isfinite(self.ceiling_m)):
            raise SettingsError.about(
                "{agl_band_m} {value}: give finite heights, e.g. 30:120", value=shown
            )
        if self.floor_m <= 0.0:
            raise SettingsError.about(
                "{agl_band_m} {value}: the floor must be above the surface; give e.g. 30:120",
                value=shown,
            )
        if self.floor_m >= self.ceiling_m:
            raise SettingsError.about(
                "{agl_band_m} {value}: the floor must be below the ceiling; give e.g. "
                "{floor:g}:{ceiling:g}",
                value=shown,
                floor=min(self.floor_m, self.ceiling_m),
                ceiling=max(self.floor_m, self.ceiling_m),
            )
        if self.ceiling_m > MAX_CEILING_M:
            raise SettingsError.about(
                "{agl_band_m} {value}: the ceiling is over {limit:g} m above the surface; "
                "give e.g. 30:120",
                value=shown,
                limit=MAX_CEILING_M,
            )

    def describe(self) -> str:
        """``30:120 m``, as messages give it."""
        return f"{self.floor_m:g}:{self.ceiling_m:g} m"

    @property
    def mid_m(self) -> float:
        """The height halfway between the floor and the ceiling."""
        return 0.5 * (self.floor_m + self.ceiling_m)

    @property
    def width_m(self) -> float:
        """The ceiling less the floor."""
        return self.ceiling_m - self.floor_m


def parse_band(text: str) -> tuple[float, float]:
    """``FLOOR:CEILING`` metres (``30:120``) as two numbers; checked by :class:`FlightBand`.

    Raises
    ------
    SettingsError
        Text that is not two numbers joined by a colon.
    """
    floor, sep, ceiling = str(text).partition(":")
    try:
        if not sep:
            raise ValueError(text)
        band = (float(floor), float(ceiling))
    except ValueError:
        raise SettingsError.about(
            "{agl_band_m} {value!r} is not FLOOR:CEILING in metres: give e.g. 30:120",
            value=str(text),
        ) from None
    FlightBand(*band)
    return band


@dataclass(frozen=True, slots=True)
class BandProfile:
    """The heights of segments above the terrain, one entry per segment.

    ``lowest_m`` and ``highest_m`` are the least and the greatest height of the segment above
    the known surface below it, ``lowest_at`` and ``highest_at`` the fractions of the way from
    start to end where they are, and ``unknown_fraction`` the fraction of the segment's
    horizontal length over unknown ground. A segment over no known ground at all has
    ``lowest_m = +inf`` and ``highest_m = -inf``.
    """

    lowest_m: FloatArray
    lowest_at: FloatArray
    highest_m: FloatArray
    highest_at: FloatArray
    unknown_fraction: FloatArray


def _ends(start_xyz: npt.ArrayLike, end_xyz: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    a = np.asarray(start_xyz, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(end_xyz, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError("a band check needs as many starts as ends")
    return a, b


def negated_terrain(
    terrain: Terrain, start_xyz: npt.ArrayLike | None = None, end_xyz: npt.ArrayLike | None = None
) -> Terrain:
    """The terrain with its elevations negated, for :func:`band_profile`'s highest heights.

    Parameters
    ----------
    terrain
        The DEM window.
    start_xyz, end_xyz
        (n, 3) segment ends, or None. When given, only the cells the segments' surface depends
        on are kept (the window of their bounding box, two cells wider, within the raster), so
        the result is as good as the whole for those segments and no others.

    Returns
    -------
    Terrain
        Its surface is minus ``terrain``'s, NaN where that is NaN.
    """
    z = terrain.elevation_m
    rows, cols = z.shape
    c0 = r0 = 0
    c1, r1 = cols, rows
    if start_xyz is not None and end_xyz is not None:
        a, b = _ends(start_xyz, end_xyz)
        col, row = terrain.pixel_coords(
            np.concatenate([a[:, 0], b[:, 0]]), np.concatenate([a[:, 1], b[:, 1]])
        )
        ok = np.isfinite(col) & np.isfinite(row)
        if ok.any():
            # Pixel centres at whole numbers: a point's surface depends on the centres
            # floor(col) and floor(col) + 1 (and one before, on a line of centres).
            lo_c, hi_c = float(col[ok].min()), float(col[ok].max())
            lo_r, hi_r = float(row[ok].min()), float(row[ok].max())
            c0 = int(np.clip(math.floor(lo_c) - 2, 0, cols - 1))
            r0 = int(np.clip(math.floor(lo_r) - 2, 0, rows - 1))
            c1 = int(np.clip(math.floor(hi_c) + 3, c0 + 1, cols))
            r1 = int(np.clip(math.floor(hi_r) + 3, r0 + 1, rows))
    window = terrain.read_window_px
    return Terrain(
        elevation_m=-z[r0:r1, c0:c1],
        transform=terrain.transform @ Affine.translation(c0, r0),
        crs=terrain.crs,
        source=terrain.source,
        read_window_px=(window[0] + c0, window[1] + r0, c1 - c0, r1 - r0),
        source_shape_px=terrain.source_shape_px,
    )


def band_profile(
    terrain: Terrain,
    start_xyz: npt.ArrayLike,
    end_xyz: npt.ArrayLike,
    workers: int | None = 1,
    *,
    negated: Terrain | None = None,
) -> BandProfile:
    """The lowest and highest height of each straight segment above the surface, exactly.

    Parameters
    ----------
    terrain
        The DEM window; its bilinear surface is the ground.
    start_xyz, end_xyz
        (n, 3) ends of the segments: x, y in the terrain's CRS and height in metres.
    workers
        Threads for :func:`~urpt_gcs.visibility.segments.segment_profile` (None: every core).
    negated
        :func:`negated_terrain` of ``terrain`` covering these segments, when the caller keeps
        one for many calls; made here (for these segments only) when None.

    Returns
    -------
    BandProfile
        Per segment, the lowest and the highest height above the known surface, where, and the
        fraction over unknown ground.
    """
    a, b = _ends(start_xyz, end_xyz)
    below = segment_profile(terrain, a, b, workers)
    if negated is None:
        negated = negated_terrain(terrain, a, b)
    flip = np.array([1.0, 1.0, -1.0])
    above = segment_profile(negated, a * flip, b * flip, workers)
    return BandProfile(
        lowest_m=-below.excess_m,
        lowest_at=below.at,
        highest_m=above.excess_m,
        highest_at=above.at,
        unknown_fraction=below.unknown_fraction,
    )


def inside_band(
    terrain: Terrain,
    start_xyz: npt.ArrayLike,
    end_xyz: npt.ArrayLike,
    band: FlightBand,
    workers: int | None = 1,
    tolerance_m: float = 1e-6,
    *,
    negated: Terrain | None = None,
) -> BoolArray:
    """Whether each segment runs over known ground, everywhere within ``band``.

    Parameters
    ----------
    terrain, start_xyz, end_xyz, workers, negated
        As for :func:`band_profile`.
    band
        The heights above the surface allowed.
    tolerance_m
        How far past either limit a segment may reach and still count as inside (rounding).

    Returns
    -------
    BoolArray
        (n,) True where every point of the segment is from ``floor_m`` to ``ceiling_m`` above
        the surface and none is over unknown ground.
    """
    p = band_profile(terrain, start_xyz, end_xyz, workers, negated=negated)
    inside: BoolArray = (
        (p.unknown_fraction == 0.0)
        & (p.lowest_m >= band.floor_m - tolerance_m)
        & (p.highest_m <= band.ceiling_m + tolerance_m)
    )
    return inside
