"""GTSP instance: candidate viewpoints, what each really sees, and the distances between them.

Candidates are each region's boundary samples, pulled one DEM cell inwards so that they do not
sit on the grazing ray, plus each target's nadir point. A candidate's cover set is decided by
a direct line-of-sight test on the DEM inside the camera cone (``visibility.line_of_sight``),
never by polygon containment. A boundary sample that fails to see its own target is pulled
further in until it does, or dropped. The nadir point always sees its target.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import shapely

from urpt_gcs.inputs import require_memory
from urpt_gcs.terrain import FloatArray, Terrain
from urpt_gcs.visibility import BoolArray, Camera, Region, line_of_sight

IntArray = npt.NDArray[np.int64]

# How far boundary samples are pulled towards their target, in DEM cells, on each try.
_INSETS_CELLS = (1.0, 2.0, 4.0)
# Elements per block of rows of a distance matrix under construction.
_BLOCK_ELEMENTS = 1 << 20


@dataclass(frozen=True, slots=True)
class Geometry:
    """Where the targets are and how they are seen: what geometric bounds need."""

    targets_xy: FloatArray
    ground_m: FloatArray
    altitude_m: float
    fov_deg: float
    terrain_max_m: float

    @property
    def cone_radius_m(self) -> FloatArray:
        tan = math.tan(math.radians(self.fov_deg))
        cone: FloatArray = np.maximum(self.altitude_m - self.ground_m, 0.0) * tan
        return cone


Oracle = Callable[[FloatArray], BoolArray]


@dataclass(frozen=True, slots=True)
class Instance:
    """A generalized TSP with cover sets: visit viewpoints so that every target is seen.

    ``covers[v, t]`` says viewpoint ``v`` sees target ``t`` (a GTSPLIB cluster is a target
    whose viewpoints are its nodes). ``distance[u, v]`` is the cost of flying from ``u`` to
    ``v`` (asymmetric allowed). With a depot, every tour starts and ends there:
    ``depot_distance[0, v]`` is depot -> ``v`` and ``depot_distance[1, v]`` is ``v`` -> depot;
    without one, a tour is a closed cycle through its viewpoints.

    Planning instances also carry the viewpoints' positions, the target geometry (for
    geometric bounds) and an ``oracle`` that says what any point of the flight plane sees, so
    a solver that places viewpoints of its own can have each one checked on the terrain.
    """

    covers: BoolArray
    distance: FloatArray
    depot_distance: FloatArray | None = None
    points_xy: FloatArray | None = None
    depot_xy: tuple[float, float] | None = None
    owner: IntArray | None = None
    geometry: Geometry | None = None
    oracle: Oracle | None = field(default=None, repr=False, compare=False)
    name: str = ""

    def __post_init__(self) -> None:
        n, _m = self.covers.shape
        if self.distance.shape != (n, n):
            raise ValueError("Instance.distance must be n x n for n viewpoints")
        if self.depot_distance is not None and self.depot_distance.shape != (2, n):
            raise ValueError("Instance.depot_distance must be 2 x n")
        if self.points_xy is not None and self.points_xy.shape != (n, 2):
            raise ValueError("Instance.points_xy must be n x 2")
        if self.owner is not None and self.owner.shape != (n,):
            raise ValueError("Instance.owner must have one entry per viewpoint")
        missing = np.flatnonzero(~self.covers.any(axis=0))
        if missing.size:
            raise ValueError(f"targets {missing.tolist()} are seen by no viewpoint")
        # Solvers share these arrays; none may change them.
        for array in (self.covers, self.distance, self.depot_distance, self.points_xy, self.owner):
            if array is not None:
                array.setflags(write=False)

    @property
    def n_viewpoints(self) -> int:
        return int(self.covers.shape[0])

    @property
    def n_targets(self) -> int:
        return int(self.covers.shape[1])

    @property
    def has_depot(self) -> bool:
        return self.depot_distance is not None

    def tour_length(self, order: npt.ArrayLike) -> float:
        """Length of the closed tour through viewpoints ``order`` (and the depot, if any)."""
        idx = np.asarray(order, dtype=np.int64)
        if idx.size == 0:
            return 0.0
        inner = float(self.distance[idx[:-1], idx[1:]].sum())
        if self.depot_distance is not None:
            return inner + float(self.depot_distance[0, idx[0]] + self.depot_distance[1, idx[-1]])
        return inner + float(self.distance[idx[-1], idx[0]])

    def uncovered(self, order: npt.ArrayLike) -> list[int]:
        """Targets that no viewpoint in ``order`` sees."""
        idx = np.asarray(order, dtype=np.int64)
        seen = self.covers[idx].any(axis=0) if idx.size else np.zeros(self.n_targets, bool)
        return [int(t) for t in np.flatnonzero(~seen)]


def euclidean_matrix(points_xy: FloatArray) -> FloatArray:
    """Pairwise Euclidean distances, an (n, n) float64 matrix.

    Built a block of rows at a time, so that beside the result only a few blocks of
    ``_BLOCK_ELEMENTS`` are ever allocated (no (n, n, 2) temporary).
    """
    pts = np.asarray(points_xy, dtype=np.float64)
    n = len(pts)
    dist: FloatArray = np.empty((n, n), dtype=np.float64)
    rows = max(_BLOCK_ELEMENTS // max(n, 1), 1)
    for lo in range(0, n, rows):
        dx = pts[lo : lo + rows, None, 0] - pts[None, :, 0]
        dy = pts[lo : lo + rows, None, 1] - pts[None, :, 1]
        np.sqrt(dx * dx + dy * dy, out=dist[lo : lo + rows])
    return dist


def instance_bytes(n_viewpoints: int, n_targets: int) -> float:
    """Memory of a planning instance's dense arrays: the distance matrix
    (``n_viewpoints**2 * 8`` bytes, and the blocks it is built from) and the cover sets."""
    n = float(n_viewpoints)
    return n * n * 8.0 + n * n_targets + 2.0 * 8.0 * _BLOCK_ELEMENTS


def require_instance_memory(n_viewpoints: int, n_targets: int) -> None:
    """Refuse a planning instance whose dense arrays would not fit the memory budget.

    Raises
    ------
    MemoryBudgetError
        Naming the estimate and what to change (both sizes scale with ``--samples`` and the
        number of targets).
    """
    require_memory(
        instance_bytes(n_viewpoints, n_targets),
        f"the distance matrix of {n_viewpoints} viewpoints ({n_targets} targets)",
        "use fewer --samples, or fewer targets per plan",
    )


def cover_sets(
    terrain: Terrain,
    viewpoints_xy: FloatArray,
    targets_xy: FloatArray,
    ground_m: FloatArray,
    camera: Camera,
    workers: int | None = 1,
) -> BoolArray:
    """Which targets each viewpoint sees: inside the camera cone and in line of sight.

    Every (viewpoint, target) pair within the cone is found at once through a spatial index
    and tested by one compiled call, its segments shared among ``workers`` threads (None:
    every core); the answer does not depend on ``workers``.
    """
    n, m = len(viewpoints_xy), len(targets_xy)
    covers = np.zeros((n, m), dtype=bool)
    if n == 0 or m == 0:
        return covers
    cone = camera.cone_radius_m(ground_m)
    tree = shapely.STRtree(shapely.points(targets_xy))
    vp_idx, tg_idx = tree.query(
        shapely.points(viewpoints_xy), predicate="dwithin", distance=float(cone.max())
    )
    horizontal = np.hypot(
        viewpoints_xy[vp_idx, 0] - targets_xy[tg_idx, 0],
        viewpoints_xy[vp_idx, 1] - targets_xy[tg_idx, 1],
    )
    in_cone = horizontal <= cone[tg_idx]
    vp_idx, tg_idx = vp_idx[in_cone], tg_idx[in_cone]
    eye = np.column_stack([viewpoints_xy[vp_idx], np.full(len(vp_idx), camera.altitude_m)])
    tgt = np.column_stack([targets_xy[tg_idx], ground_m[tg_idx]])
    seen = line_of_sight(terrain, eye, tgt, workers)
    covers[vp_idx[seen], tg_idx[seen]] = True
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
    """Candidate viewpoints with verified cover sets, and the distance matrix."""
    nadir = np.asarray(targets_xy, dtype=np.float64)
    own = np.concatenate([np.full(len(r.reach_m), r.target, dtype=np.int64) for r in regions])
    az = np.concatenate([r.azimuth_rad for r in regions])
    reach = np.concatenate([r.reach_m for r in regions])
    points, owners = [nadir], [np.arange(len(nadir), dtype=np.int64)]
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
        points.append(xy[ok])
        owners.append(own[idx[ok]])
        pending[idx[ok]] = False
    viewpoints = np.concatenate(points)
    owner = np.concatenate(owners)
    require_instance_memory(len(viewpoints), len(nadir))
    covers = cover_sets(terrain, viewpoints, nadir, ground_m, camera, workers)
    depot_distance = None
    if depot_xy is not None:
        depot = np.asarray(depot_xy, dtype=np.float64)
        to_depot = np.hypot(viewpoints[:, 0] - depot[0], viewpoints[:, 1] - depot[1])
        depot_distance = np.vstack([to_depot, to_depot])
        depot_xy = (float(depot[0]), float(depot[1]))

    def oracle(points_xy: FloatArray) -> BoolArray:
        return cover_sets(terrain, np.asarray(points_xy, dtype=np.float64), nadir, ground_m, camera)

    return Instance(
        covers=covers,
        distance=euclidean_matrix(viewpoints),
        depot_distance=depot_distance,
        points_xy=viewpoints,
        depot_xy=depot_xy,
        owner=owner,
        geometry=Geometry(
            targets_xy=nadir,
            ground_m=np.asarray(ground_m, dtype=np.float64),
            altitude_m=camera.altitude_m,
            fov_deg=camera.fov_deg,
            terrain_max_m=terrain_max_m,
        ),
        oracle=oracle,
    )
