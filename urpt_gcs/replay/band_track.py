"""The band check of a replayed flight: did the track stay inside the height band?

A plan made with ``--agl FLOOR:CEILING`` flies between ``FLOOR`` and ``CEILING`` metres above
the DSM's surface below the vehicle. Its ``summary.json`` says so under ``"band"``
(``{"floor_m": 30, "ceiling_m": 120}``); :func:`band_of_summary` reads that key, and
:func:`band_track` measures every recorded fix (GLOBAL_POSITION_INT, at its full rate) against
the DEM's bilinear surface: the lowest and the highest height above it, and how far the worst
fix fell below the floor or rose above the ceiling. Fixes over home are left out: the take-off
climbs there from the ground and the landing descends to it, outside any band.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from urpt_gcs.arrays import FloatArray
from urpt_gcs.site.terrain import Terrain

__all__ = [
    "BAND_TRACKING_TOLERANCE_M",
    "HOME_RADIUS_M",
    "BandTrack",
    "band_of_summary",
    "band_track",
    "band_track_text",
]

# How far outside the band a fix may be and the flight still pass. The plan keeps every leg
# inside the band to the centimetre, but a vehicle follows it only as well as its controller:
# PX4 SITL holds its altitude within about +-0.9 m, and a metre of horizontal error across a
# steep slope changes the height above the surface below by about as much again.
BAND_TRACKING_TOLERANCE_M = 2.0
# Fixes within this horizontal distance of home are the take-off climb and the landing
# descent (from and to the ground, outside any band): they are not judged against it.
HOME_RADIUS_M = 5.0


@dataclass(frozen=True, slots=True)
class BandTrack:
    """The track against the band.

    Attributes
    ----------
    floor_m, ceiling_m
        The band the plan was made for, in metres above the surface.
    lowest_m, highest_m
        The least and the greatest height above the surface of any fix judged (NaN: none).
    judged
        How many fixes were judged (away from home, over known ground).
    unknown
        How many fixes away from home were over no data.
    """

    floor_m: float
    ceiling_m: float
    lowest_m: float
    highest_m: float
    judged: int
    unknown: int

    @property
    def below_m(self) -> float:
        """How far the lowest fix was below the floor (0 when none was)."""
        return max(self.floor_m - self.lowest_m, 0.0) if self.judged else 0.0

    @property
    def above_m(self) -> float:
        """How far the highest fix was above the ceiling (0 when none was)."""
        return max(self.highest_m - self.ceiling_m, 0.0) if self.judged else 0.0

    def problems(self) -> list[str]:
        """Why the track fails the band, one clause each (empty when it passes)."""
        out = []
        if self.judged == 0:
            out.append("no position away from home was received: the band is unchecked")
        if self.below_m > BAND_TRACKING_TOLERANCE_M:
            out.append(
                f"the track fell to {self.lowest_m:.1f} m above the surface, {self.below_m:.1f} m "
                f"under the band's floor {self.floor_m:g} m (more than the "
                f"{BAND_TRACKING_TOLERANCE_M:g} m a vehicle may be off)"
            )
        if self.above_m > BAND_TRACKING_TOLERANCE_M:
            out.append(
                f"the track rose to {self.highest_m:.1f} m above the surface, "
                f"{self.above_m:.1f} m over the band's ceiling {self.ceiling_m:g} m (more than the "
                f"{BAND_TRACKING_TOLERANCE_M:g} m a vehicle may be off)"
            )
        return out


def band_of_summary(data: Any) -> tuple[float, float] | None:
    """The band a ``summary.json``'s data names under ``"band"``, or None for a plane's plan.

    Raises
    ------
    ValueError
        When ``"band"`` is there but is not ``{"floor_m": F, "ceiling_m": C}`` with
        ``0 < F < C``, both finite.
    """
    if not isinstance(data, dict) or data.get("band") is None:
        return None
    band = data["band"]
    if not isinstance(band, dict):
        raise ValueError(f"its band is {band!r}, not floor_m and ceiling_m")
    try:
        floor, ceiling = float(band["floor_m"]), float(band["ceiling_m"])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"its band {band!r} has no numbers floor_m and ceiling_m") from None
    if not (math.isfinite(floor) and math.isfinite(ceiling) and 0.0 < floor < ceiling):
        raise ValueError(f"its band {floor:g}:{ceiling:g} m is not 0 < floor < ceiling")
    return floor, ceiling


def band_track(
    terrain: Terrain,
    track_xy: FloatArray,
    track_z: FloatArray,
    home_xy: FloatArray,
    band: tuple[float, float],
) -> BandTrack:
    """Every fix's height above the surface below it, against the band.

    Parameters
    ----------
    terrain
        The DEM window around the track.
    track_xy, track_z
        (n, 2) the fixes in the terrain's CRS and (n,) their heights in the DEM's datum.
    home_xy
        Home in the terrain's CRS: fixes within ``HOME_RADIUS_M`` of it are left out.
    band
        The floor and the ceiling, metres above the surface.
    """
    xy = np.asarray(track_xy, dtype=np.float64).reshape(-1, 2)
    z = np.asarray(track_z, dtype=np.float64).reshape(-1)
    away = np.hypot(xy[:, 0] - home_xy[0], xy[:, 1] - home_xy[1]) > HOME_RADIUS_M
    ground = terrain.sample(xy[away, 0], xy[away, 1]) if away.any() else np.zeros(0)
    height = z[away] - ground
    known = np.isfinite(height)
    lowest = float(height[known].min()) if known.any() else math.nan
    highest = float(height[known].max()) if known.any() else math.nan
    return BandTrack(band[0], band[1], lowest, highest, int(known.sum()), int((~known).sum()))


def band_track_text(band: BandTrack) -> str:
    """The report's line: the band, the heights flown, the worst excursions."""
    if not band.judged:
        return f"band      {band.floor_m:g}:{band.ceiling_m:g} m: no fix away from home"
    unknown = f", {band.unknown} over no data" if band.unknown else ""
    return (
        f"band      {band.floor_m:g}:{band.ceiling_m:g} m: track {band.lowest_m:.1f} to "
        f"{band.highest_m:.1f} m above the surface over {band.judged} fixes{unknown}; worst "
        f"{band.below_m:.2f} m under the floor, {band.above_m:.2f} m over the ceiling "
        f"(tolerance {BAND_TRACKING_TOLERANCE_M:g} m)"
    )
