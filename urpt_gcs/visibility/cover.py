"""Building the GTSP instance on the terrain: candidate viewpoints and what each really sees.

Candidates are each region's boundary samples, pulled one DEM cell inwards so that they do not
sit on the grazing ray, plus each target's nadir point. A candidate's cover set is decided by
a direct line-of-sight test on the DEM inside the camera cone (``visibility.line_of_sight``),
never by polygon containment. A boundary sample that fails to see its own target is pulled
further in until it does, or dropped. The nadir point always sees its target.
"""

from __future__ import annotations

import numpy as np
import shapely

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.problem.instance import Geometry, Instance, require_instance_memory
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import Camera, Region, line_of_sight

__all__ = ["build_instance", "cover_pairs", "cover_sets"]

# How far boundary samples are pulled towards their target, in DEM cells, on each try.
_INSETS_CELLS = (1.0, 2.0, 4.0)
# Viewpoints whose candidate pairs are gathered and tested at once.
_PAIR_CHUNK_VIEWPOINTS = 20_000


def cover_pairs(
    terrain: Terrain,
    viewpoints_xy: FloatArray,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    workers: int | None = 1,
    heading_deg: FloatArray | None = None,
) -> tuple[IntArray, IntArray]:
    """The (viewpoint, target) index pairs where the viewpoint sees the target.

    A frame camera sees from viewpoint ``v`` at heading ``heading_deg[v]``: the target must
    lie inside the turned frame (and within the GSD distance) before its line of sight counts.

    The pairs within the cone are found through a spatial index and tested by one compiled
    call per chunk of viewpoints, its segments shared among ``workers`` threads (None: every
    core); the answer does not depend on ``workers``. Only a chunk's candidate pairs exist at
    once, and before a chunk's pairs are kept the instance so far is checked against the
    memory budget. No array is dense in viewpoints × targets.

    Raises
    ------
    MemoryBudgetError
        When the pairs seen so far would take the instance over the budget.
    """
    n, m = len(viewpoints_xy), len(targets_xy)
    if n == 0 or m == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    cone = camera.cone_radius_m(ground_m)
    tree = shapely.STRtree(shapely.points(targets_xy))
    found_vp: list[IntArray] = []
    found_tg: list[IntArray] = []
    kept = 0
    for lo in range(0, n, _PAIR_CHUNK_VIEWPOINTS):
        hi = min(lo + _PAIR_CHUNK_VIEWPOINTS, n)
        vp_idx, tg_idx = tree.query(
            shapely.points(viewpoints_xy[lo:hi]), predicate="dwithin", distance=float(cone.max())
        )
        vp_idx = vp_idx + lo
        in_view = camera.in_view(
            viewpoints_xy[vp_idx],
            targets_xy[tg_idx],
            ground_m[tg_idx],
            None if heading_deg is None else heading_deg[vp_idx],
        )
        vp_idx, tg_idx = vp_idx[in_view], tg_idx[in_view]
        eye = np.column_stack([viewpoints_xy[vp_idx], np.full(len(vp_idx), camera.altitude_m)])
        tgt = np.column_stack([targets_xy[tg_idx], ground_m[tg_idx]])
        seen = line_of_sight(terrain, eye, tgt, workers)
        kept += int(seen.sum())
        require_instance_memory(n, kept)
        found_vp.append(vp_idx[seen].astype(np.int64))
        found_tg.append(tg_idx[seen].astype(np.int64))
    return np.concatenate(found_vp), np.concatenate(found_tg)


def cover_sets(
    terrain: Terrain,
    viewpoints_xy: FloatArray,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    workers: int | None = 1,
    heading_deg: FloatArray | None = None,
) -> BoolArray:
    """Which targets each viewpoint sees, as a dense viewpoints × targets array.

    For a few viewpoints (the oracle, the stop margin); the instance uses `cover_pairs`.
    """
    covers = np.zeros((len(viewpoints_xy), len(targets_xy)), dtype=bool)
    vp_idx, tg_idx = cover_pairs(
        terrain, viewpoints_xy, targets_xy, ground_m, camera, workers, heading_deg
    )
    covers[vp_idx, tg_idx] = True
    return covers


def build_instance(
    terrain: Terrain,
    regions: tuple[Region, ...],
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    depot_xy: tuple[float, float] | None,
    terrain_max_m: float,
    workers: int | None = 1,
) -> Instance:
    """Candidate viewpoints with verified cover sets, on the plane (no distance matrix).

    A frame camera offers every candidate at each of its headings, one node per (point,
    heading): along each ray a region's boundary sample is first pulled in to where the frame
    at that heading still holds the target, and the nadir point is offered at every heading
    (copies at distance 0 from each other).
    """
    nadir = np.asarray(targets_xy, dtype=np.float64)
    own = np.concatenate([np.full(len(r.reach_m), r.target, dtype=np.int64) for r in regions])
    az = np.concatenate([r.azimuth_rad for r in regions])
    reach = np.concatenate([r.reach_m for r in regions])
    heading = np.zeros(len(own))
    nadir_own = np.arange(len(nadir), dtype=np.int64)
    nadir_heading = np.zeros(len(nadir))
    if camera.frame is not None:
        # Each sample at each heading, pulled in to the frame's edge along its ray.
        choices = camera.heading_choices_deg
        k = len(choices)
        heading = np.tile(choices, len(own))
        own, az, reach = np.repeat(own, k), np.repeat(az, k), np.repeat(reach, k)
        height = camera.altitude_m - ground_m[own]
        reach = np.minimum(reach, _frame_reach(camera, az, heading, height))
        nadir_heading = np.tile(choices, len(nadir))
        nadir_own = np.repeat(nadir_own, k)
    points, owners, headings = [nadir[nadir_own]], [nadir_own], [nadir_heading]
    pending = np.ones(len(own), dtype=bool)
    for inset_cells in _INSETS_CELLS:
        idx = np.flatnonzero(pending)
        r = reach[idx] - inset_cells * terrain.cell_m
        # A sample pulled onto the nadir point adds nothing: the nadir is already there.
        pending[idx[r <= 1e-6]] = False
        idx, r = idx[r > 1e-6], r[r > 1e-6]
        xy = nadir[own[idx]] + r[:, None] * np.column_stack([np.cos(az[idx]), np.sin(az[idx])])
        eye = np.column_stack([xy, np.full(len(xy), camera.altitude_m)])
        tgt = np.column_stack([nadir[own[idx]], ground_m[own[idx]]])
        ok = line_of_sight(terrain, eye, tgt, workers)
        ok &= camera.in_view(xy, nadir[own[idx]], ground_m[own[idx]], heading[idx])
        points.append(xy[ok])
        owners.append(own[idx[ok]])
        headings.append(heading[idx[ok]])
        pending[idx[ok]] = False
    viewpoints = np.concatenate(points)
    owner = np.concatenate(owners)
    node_heading = np.concatenate(headings) if camera.frame is not None else None
    # Every viewpoint sees at least the target it was made for.
    require_instance_memory(len(viewpoints), len(viewpoints))
    vp_idx, tg_idx = cover_pairs(
        terrain, viewpoints, nadir, ground_m, camera, workers, node_heading
    )

    def oracle(points_xy: FloatArray) -> BoolArray:
        pts = np.asarray(points_xy, dtype=np.float64)
        return cover_sets(terrain, pts, nadir, ground_m, camera, workers)

    return Instance.from_cover_pairs(
        vp_idx,
        tg_idx,
        viewpoints,
        len(nadir),
        depot_xy=depot_xy,
        owner=owner,
        geometry=Geometry(
            targets_xy=nadir,
            ground_m=np.asarray(ground_m, dtype=np.float64),
            altitude_m=camera.altitude_m,
            fov_deg=camera.fov_deg,
            terrain_max_m=terrain_max_m,
        ),
        # A stop placed by a solver has no heading: what it sees is only defined for the cone.
        oracle=oracle if camera.frame is None else None,
        heading_deg=node_heading,
    )


def _frame_reach(
    camera: Camera, azimuth_rad: FloatArray, heading_deg: FloatArray, height_m: FloatArray
) -> FloatArray:
    """How far from a target, along each azimuth (counter-clockwise from east), the frame at
    each heading still holds it, ``height_m`` below the camera."""
    assert camera.frame is not None
    ux, uy = np.cos(azimuth_rad), np.sin(azimuth_rad)
    psi = np.radians(heading_deg)
    along = np.abs(ux * np.sin(psi) + uy * np.cos(psi))
    across = np.abs(ux * np.cos(psi) - uy * np.sin(psi))
    with np.errstate(divide="ignore"):
        out: FloatArray = np.minimum(
            height_m * camera.frame.half_tan_across / across,
            height_m * camera.frame.half_tan_along / along,
        )
    return out
