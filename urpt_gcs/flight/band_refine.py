"""Moving the band's stops in three dimensions, the order fixed.

The solver picks each stop among a few candidates per target (two rings and a nadir at three
heights). Here each stop in turn is moved -- across and up or down -- to where its two legs
take less time, by a pattern search with shrinking steps. A move is kept only where the stop
still sees every target it must from anywhere within the position tolerance
(:func:`~urpt_gcs.visibility.band.sees_from`) and stays inside the band from anywhere on its
tolerance rim; its legs are costed as the solver's table costs them: the flight model's time
for the horizontal length and the least climbing the terrain under the leg forces inside the
band. The paths are made to follow the terrain afterwards, and the caller keeps the moved
stops only if that flight is faster.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.flight.band import FlightBand, band_profile
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.band import inside_band_around, sees_from
from urpt_gcs.visibility.regions import Camera

__all__ = ["BandStops", "refine_band_stops"]

# Horizontal steps of the pattern search, in DEM cells, largest first; each with a vertical
# step of this share of the band's width.
_STEPS_CELLS = (8.0, 4.0, 2.0, 1.0)
_VERTICAL_SHARE = 0.1
# Passes over the stops at most.
_PASSES = 3
# Directions tried at each step: eight across, and up and down in place.
_ACROSS = np.array(
    [(math.cos(a), math.sin(a)) for a in np.arange(8) * (math.pi / 4.0)], dtype=np.float64
)


@dataclass(frozen=True, slots=True)
class BandStops:
    """What a stop must keep while it moves: the targets it sees, the camera and the band.

    Attributes
    ----------
    terrain, camera, band
        The DEM window, the camera, the band.
    targets_xy, ground_m
        The targets and the ground under them.
    sees
        (stops, targets): which targets each stop must keep seeing.
    heading_deg
        Each stop's heading (frame camera), or None.
    tolerance_m
        The position tolerance every stop sees its targets from.
    """

    terrain: Terrain
    camera: Camera
    band: FlightBand
    targets_xy: FloatArray
    ground_m: FloatArray
    sees: BoolArray
    heading_deg: FloatArray | None
    tolerance_m: float


def refine_band_stops(
    stops: BandStops, stops_xyz: FloatArray, home_xyz: FloatArray, model: FlightModel
) -> FloatArray:
    """The stops moved, one at a time, to where their legs take less time.

    Parameters
    ----------
    stops
        What each stop must keep.
    stops_xyz
        (k, 3) the stops in flight order; the tour runs from ``home_xyz`` and back.
    home_xyz
        Over home at the take-off height.
    model
        The flight model the legs are timed with.

    Returns
    -------
    FloatArray
        (k, 3) the stops, each where it was or where it sees the same targets faster.
    """
    out = np.array(stops_xyz, dtype=np.float64, copy=True)
    k = len(out)
    if k == 0:
        return out
    cell = stops.terrain.cell_m
    for _ in range(_PASSES):
        moved = False
        for i in range(k):
            before = out[i - 1] if i > 0 else home_xyz
            after = out[i + 1] if i + 1 < k else home_xyz
            best = float(_legs_s(stops, model, before, out[i], after)[0])
            for step in _STEPS_CELLS:
                dz = _VERTICAL_SHARE * stops.band.width_m * step / _STEPS_CELLS[0]
                tries = np.vstack(
                    [
                        out[i] + np.column_stack([step * cell * _ACROSS, np.zeros(8)]),
                        out[i] + np.array([[0.0, 0.0, dz], [0.0, 0.0, -dz]]),
                    ]
                )
                costs = _legs_s(stops, model, before, tries, after)
                for j in np.argsort(costs):
                    if costs[j] >= best - 1e-9:
                        break
                    if _holds(stops, i, tries[j]):
                        out[i], best, moved = tries[j], float(costs[j]), True
                        break
        if not moved:
            break
    return out


def _legs_s(
    stops: BandStops, model: FlightModel, before: FloatArray, at: FloatArray, after: FloatArray
) -> FloatArray:
    """The time of the legs ``before -> at -> after`` for every row of ``at``, as the solver's
    table costs a leg."""
    points = np.atleast_2d(at)
    n = len(points)
    starts = np.vstack([np.repeat(before[None, :], n, axis=0), points])
    ends = np.vstack([points, np.repeat(after[None, :], n, axis=0)])
    flat_a = np.column_stack([starts[:, :2], np.zeros(2 * n)])
    flat_b = np.column_stack([ends[:, :2], np.zeros(2 * n)])
    # Lines at height 0: their lowest height above the surface is minus the highest ground.
    profile = band_profile(stops.terrain, flat_a, flat_b)
    peak = np.where(np.isfinite(profile.lowest_m), -profile.lowest_m, -np.inf)
    trough = np.where(np.isfinite(profile.highest_m), -profile.highest_m, np.inf)
    length = np.hypot(*(ends[:, :2] - starts[:, :2]).T)
    extra = model.least_vertical_s(
        length,
        starts[:, 2],
        ends[:, 2],
        peak + stops.band.floor_m,
        trough + stops.band.ceiling_m,
    )
    legs: FloatArray = model.leg3_s(length, 0.0, extra)
    total: FloatArray = legs[:n] + legs[n:]
    return total


def _holds(stops: BandStops, i: int, xyz: FloatArray) -> bool:
    """Whether stop ``i`` at ``xyz`` stays in the band around it and sees its targets from
    anywhere within the tolerance."""
    point = xyz[None, :]
    band = stops.band
    if not inside_band_around(
        stops.terrain, point, band.floor_m, band.ceiling_m, stops.tolerance_m
    )[0]:
        return False
    targets = np.flatnonzero(stops.sees[i])
    eyes = np.repeat(point, len(targets), axis=0)
    heading = None
    if stops.heading_deg is not None:
        heading = np.full(len(targets), stops.heading_deg[i])
    seen = sees_from(
        stops.terrain,
        stops.camera,
        eyes,
        stops.targets_xy[targets],
        stops.ground_m[targets],
        heading,
        stops.tolerance_m,
    )
    return bool(seen.all())
