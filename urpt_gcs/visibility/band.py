"""Viewpoints in three dimensions, inside a height band above the terrain.

In the band mode the vehicle may fly anywhere from ``floor_m`` to ``ceiling_m`` above the
surface right below it. Each target is offered candidates at several heights inside the
band: its nadir point and rings around it, each at its own height above the surface under it.
What a candidate sees is decided as on the plane -- the camera's cone (or frame at a heading)
and GSD distance, and an exact line of sight on the DEM's bilinear surface -- but robustly:
a pair counts only when the target stays in the picture from anywhere within the position
tolerance, horizontally and vertically. The cone and the frame are tested at the worst corner
of that cylinder (farthest out, lowest); the line of sight, which a higher eye only lifts,
from the cylinder's bottom at its centre and at points around its rim.

The solver core never sees the terrain: it gets points, cover sets and costs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.errors import PlanError
from urpt_gcs.memory import require_memory
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import Camera, in_frame, line_of_sight

__all__ = [
    "BandViewpoints",
    "band_cover_pairs",
    "band_levels",
    "band_viewpoints",
    "inside_band_around",
    "sees_from",
]

# Heights above the surface a target's candidates are offered at, between the band's limits
# less an inset (a share of the band's width, plus the tolerance): low stops climb less, high
# ones see more.
_LEVELS = 3
_INSET_SHARE = 0.1
# Rings of candidates around each target, as shares of the cone's radius at the ring's
# height, and the azimuths per ring (fewer when the viewpoint budget needs it).
_RING_SHARES = (0.45, 0.85)
_AZIMUTHS = (8, 6, 4)
# Points around the tolerance cylinder's rim whose line of sight is tested.
_RIM_POINTS = 12
# (viewpoint, target) pairs tested per chunk.
_PAIR_CHUNK = 50_000


@dataclass(frozen=True, slots=True)
class BandViewpoints:
    """Candidate viewpoints inside the band and what each sees from anywhere within the
    position tolerance.

    Attributes
    ----------
    xyz
        (n, 3) positions: x, y in the planning CRS, height in the DEM's vertical datum.
    owner
        The target each was made for.
    heading_deg
        Each one's heading (grid north, clockwise) for a frame camera; None for the cone.
    pairs
        (viewpoint, target) index arrays: the viewpoint sees the target.
    """

    xyz: FloatArray
    owner: IntArray
    heading_deg: FloatArray | None
    pairs: tuple[IntArray, IntArray]


def band_levels(floor_m: float, ceiling_m: float, tolerance_m: float) -> FloatArray:
    """The heights above the surface candidates are offered at, inset from the band's limits
    by a share of its width and the position tolerance (the vehicle may be that far off)."""
    inset = _INSET_SHARE * (ceiling_m - floor_m) + tolerance_m
    lo, hi = floor_m + inset, ceiling_m - inset
    if hi < lo:
        least = 2.0 * tolerance_m / (1.0 - 2.0 * _INSET_SHARE)
        raise PlanError(
            f"the band {floor_m:g}:{ceiling_m:g} m is too narrow for --position-tolerance "
            f"{tolerance_m:g} m: widen --agl (at least {least:.1f} m between its limits)"
        )
    out: FloatArray = np.linspace(lo, hi, _LEVELS) if hi > lo else np.array([lo])
    return out


def sees_from(
    terrain: Terrain,
    camera: Camera,
    eye_xyz: FloatArray,
    target_xy: FloatArray,
    ground_m: FloatArray,
    heading_deg: FloatArray | None,
    tolerance_m: float,
    workers: int | None = 1,
) -> BoolArray:
    """Whether each target stays seen from anywhere within ``tolerance_m`` of each eye
    (pairs element by element).

    The cone (or the frame at the heading) must hold the target from the cylinder's worst
    corner: ``tolerance_m`` farther out and ``tolerance_m`` lower; within the GSD distance
    from ``tolerance_m`` higher and farther; and the line of sight must clear the terrain
    from the cylinder's bottom, at its centre and around its rim.
    """
    eye = np.asarray(eye_xyz, dtype=np.float64).reshape(-1, 3)
    tgt = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    ground = np.asarray(ground_m, dtype=np.float64).reshape(-1)
    dx, dy = tgt[:, 0] - eye[:, 0], tgt[:, 1] - eye[:, 1]
    low = eye[:, 2] - tolerance_m - ground
    ok: BoolArray = (low > 0.0) & (np.hypot(dx, dy) + tolerance_m <= low * camera.tan_fov)
    far = camera.max_distance_m
    if math.isfinite(far):
        ok &= np.hypot(np.hypot(dx, dy) + tolerance_m, low + 2.0 * tolerance_m) <= far
    if camera.frame is not None:
        if heading_deg is None:
            raise ValueError("a frame camera needs the heading of every photo")
        ok &= in_frame(camera.frame, dx, dy, low, heading_deg, -tolerance_m)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return ok
    rim = _rim(tolerance_m)
    base = eye[idx].copy()
    base[:, 2] -= tolerance_m
    starts = (base[:, None, :] + rim[None, :, :]).reshape(-1, 3)
    ends = np.repeat(np.column_stack([tgt[idx], ground[idx]]), len(rim), axis=0)
    clear = line_of_sight(terrain, starts, ends, workers).reshape(len(idx), len(rim))
    ok[idx] = clear.all(axis=1)
    return ok


def _rim(tolerance_m: float) -> FloatArray:
    """Offsets of the centre and of points around a circle of ``tolerance_m``."""
    if tolerance_m <= 0.0:
        return np.zeros((1, 3))
    a = np.arange(_RIM_POINTS) * (2.0 * math.pi / _RIM_POINTS)
    ring = np.column_stack([tolerance_m * np.cos(a), tolerance_m * np.sin(a), np.zeros(len(a))])
    out: FloatArray = np.vstack([np.zeros((1, 3)), ring])
    return out


def band_cover_pairs(
    terrain: Terrain,
    camera: Camera,
    eye_xyz: FloatArray,
    heading_deg: FloatArray | None,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    tolerance_m: float,
    workers: int | None = 1,
) -> tuple[IntArray, IntArray]:
    """Every (viewpoint, target) pair where the viewpoint sees the target from anywhere within
    the tolerance (:func:`sees_from`); candidate pairs come from a spatial index."""
    n = len(eye_xyz)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    tree = shapely.STRtree(shapely.points(targets_xy))
    reach = np.maximum(eye_xyz[:, 2] - float(np.min(ground_m)), 0.0) * camera.tan_fov
    vp, tg = tree.query(
        shapely.points(eye_xyz[:, :2]), predicate="dwithin", distance=float(reach.max())
    )
    found_vp: list[IntArray] = []
    found_tg: list[IntArray] = []
    for lo in range(0, len(vp), _PAIR_CHUNK):
        v, t = vp[lo : lo + _PAIR_CHUNK], tg[lo : lo + _PAIR_CHUNK]
        seen = sees_from(
            terrain,
            camera,
            eye_xyz[v],
            targets_xy[t],
            ground_m[t],
            None if heading_deg is None else heading_deg[v],
            tolerance_m,
            workers,
        )
        found_vp.append(v[seen].astype(np.int64))
        found_tg.append(t[seen].astype(np.int64))
    return np.concatenate(found_vp), np.concatenate(found_tg)


def band_viewpoints(
    terrain: Terrain,
    camera: Camera,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    floor_m: float,
    ceiling_m: float,
    tolerance_m: float,
    max_viewpoints: int,
    names: list[str],
    workers: int | None = 1,
) -> BandViewpoints:
    """Candidates at several heights inside the band around every target, with what each
    sees from anywhere within ``tolerance_m``.

    A candidate is kept when, from its own position and from every point of the tolerance
    ring around it, it stays inside the band (``tolerance_m`` above the floor and below the
    ceiling over the surface there) and sees at least the target it was made for.

    Raises
    ------
    PlanError
        A target that no candidate sees (name given, with what to change).
    MemoryBudgetError
        More candidates than ``max_viewpoints`` even at the fewest azimuths.
    """
    targets = np.asarray(targets_xy, dtype=np.float64)
    ground = np.asarray(ground_m, dtype=np.float64)
    m = len(targets)
    levels = band_levels(floor_m, ceiling_m, tolerance_m)
    headings = camera.heading_choices_deg
    per_target = len(levels) * (1 + len(_RING_SHARES) * _AZIMUTHS[-1]) * len(headings)
    require_memory(
        float(m * per_target) ** 2 * 16.0,
        f"the band's flight-time table for {m} targets ({m * per_target} candidates)",
        "plan fewer targets at a time in the band (--agl), or use the constant plane",
    )
    for azimuths in _AZIMUTHS:
        xy, h, own = _candidate_points(targets, levels, azimuths, camera)
        if len(xy) * len(headings) <= max_viewpoints or azimuths == _AZIMUTHS[-1]:
            break
    surface = terrain.sample(xy[:, 0], xy[:, 1])
    # The nadir sits on its target: the surface there is the target's own ground.
    xyz = np.column_stack([xy, surface + h])
    keep = np.isfinite(surface) & inside_band_around(terrain, xyz, floor_m, ceiling_m, tolerance_m)
    xyz, own = xyz[keep], own[keep]
    heading = None
    if camera.frame is not None:
        heading = np.tile(headings, len(xyz))
        xyz, own = np.repeat(xyz, len(headings), axis=0), np.repeat(own, len(headings))
    # Each candidate must see its own target first; then what else it sees.
    sees_own = sees_from(
        terrain, camera, xyz, targets[own], ground[own], heading, tolerance_m, workers
    )
    xyz, own = xyz[sees_own], own[sees_own]
    if heading is not None:
        heading = heading[sees_own]
    unseen = np.setdiff1d(np.arange(m), own)
    if unseen.size:
        raise PlanError(
            f"target '{names[int(unseen[0])]}' is seen from nowhere inside the band "
            f"{floor_m:g}:{ceiling_m:g} m within --position-tolerance {tolerance_m:g} m"
            + (f" (and {unseen.size - 1} more)" if unseen.size > 1 else "")
            + ": raise the band's ceiling, widen --fov or lower --position-tolerance"
        )
    pairs = band_cover_pairs(terrain, camera, xyz, heading, targets, ground, tolerance_m, workers)
    return BandViewpoints(xyz, own.astype(np.int64), heading, pairs)


def _candidate_points(
    targets: FloatArray, levels: FloatArray, azimuths: int, camera: Camera
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Each target's nadir and rings at every level: positions, heights above the surface
    under them, and the target each was made for."""
    a = np.arange(azimuths) * (2.0 * math.pi / azimuths)
    unit = np.column_stack([np.cos(a), np.sin(a)])
    offsets, heights = [], []
    far = camera.max_distance_m
    for h in levels:
        radius = h * camera.tan_fov
        if math.isfinite(far):
            radius = min(radius, math.sqrt(max(far * far - h * h, 0.0)))
        offsets.append(np.zeros((1, 2)))
        heights.append(h)
        for share in _RING_SHARES:
            offsets.append(share * radius * unit)
            heights.extend([h] * azimuths)
    offset = np.vstack(offsets)
    height = np.asarray(heights, dtype=np.float64)
    m, k = len(targets), len(offset)
    xy = (targets[:, None, :] + offset[None, :, :]).reshape(-1, 2)
    own = np.repeat(np.arange(m, dtype=np.int64), k)
    return xy, np.tile(height, m), own


def inside_band_around(
    terrain: Terrain, xyz: FloatArray, floor_m: float, ceiling_m: float, tolerance_m: float
) -> BoolArray:
    """Whether each point, moved anywhere up to ``tolerance_m`` (sampled on its rim), stays
    inside the band over the surface there."""
    ok = np.ones(len(xyz), dtype=bool)
    for dx, dy, _ in _rim(tolerance_m):
        s = terrain.sample(xyz[:, 0] + dx, xyz[:, 1] + dy)
        ok &= np.isfinite(s)
        ok &= xyz[:, 2] - tolerance_m >= s + floor_m
        ok &= xyz[:, 2] + tolerance_m <= s + ceiling_m
    return ok
