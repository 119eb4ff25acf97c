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
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray
from urpt_gcs.memory import require_memory
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import Camera, Region, line_of_sight

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
class Covers:
    """Cover sets in compressed sparse rows: viewpoint ``v`` sees the targets
    ``target[ptr[v]:ptr[v + 1]]`` (ascending). Memory is linear in (viewpoint, target) pairs."""

    ptr: IntArray
    target: IntArray
    n_targets: int

    def __post_init__(self) -> None:
        if self.ptr.ndim != 1 or self.ptr.size < 1 or self.ptr[0] != 0:
            raise ValueError("Covers.ptr must be a 1-d offset array starting at 0")
        if int(self.ptr[-1]) != self.target.size or np.any(np.diff(self.ptr) < 0):
            raise ValueError("Covers.ptr must be non-decreasing and end at len(target)")
        if self.target.size and (self.target.min() < 0 or self.target.max() >= self.n_targets):
            raise ValueError(f"Covers.target must lie in 0..{self.n_targets - 1}")
        self.ptr.setflags(write=False)
        self.target.setflags(write=False)

    @classmethod
    def from_pairs(
        cls,
        viewpoint_idx: npt.ArrayLike,
        target_idx: npt.ArrayLike,
        n_viewpoints: int,
        n_targets: int,
    ) -> Covers:
        """Cover sets from (viewpoint, target) pairs, in any order, duplicates allowed."""
        vp = np.asarray(viewpoint_idx, dtype=np.int64).ravel()
        tg = np.asarray(target_idx, dtype=np.int64).ravel()
        if vp.shape != tg.shape:
            raise ValueError("Covers.from_pairs needs as many viewpoint as target indices")
        if vp.size and (vp.min() < 0 or vp.max() >= n_viewpoints):
            raise ValueError(f"Covers.from_pairs: viewpoints must lie in 0..{n_viewpoints - 1}")
        key = np.unique(vp * max(n_targets, 1) + tg)
        vp, tg = key // max(n_targets, 1), key % max(n_targets, 1)
        ptr = np.zeros(n_viewpoints + 1, dtype=np.int64)
        np.cumsum(np.bincount(vp, minlength=n_viewpoints), out=ptr[1:])
        return cls(ptr, tg.astype(np.int64), int(n_targets))

    @classmethod
    def from_dense(cls, covers: BoolArray) -> Covers:
        """Cover sets from an ``(n_viewpoints, n_targets)`` boolean matrix."""
        matrix = np.asarray(covers, dtype=bool)
        if matrix.ndim != 2:
            raise ValueError("a dense cover matrix must be n_viewpoints x n_targets")
        vp, tg = np.nonzero(matrix)
        return cls.from_pairs(vp, tg, matrix.shape[0], matrix.shape[1])

    @classmethod
    def identity(cls, n: int) -> Covers:
        """Viewpoint ``k`` sees target ``k`` only: a plain TSP."""
        return cls(np.arange(n + 1, dtype=np.int64), np.arange(n, dtype=np.int64), n)

    @property
    def n_viewpoints(self) -> int:
        return int(self.ptr.size - 1)

    @property
    def n_pairs(self) -> int:
        return int(self.target.size)

    @property
    def nbytes(self) -> int:
        return int(self.ptr.nbytes + self.target.nbytes)

    def pairs(self) -> tuple[IntArray, IntArray]:
        """Every (viewpoint, target) pair, viewpoint-major as ``np.nonzero`` of the dense form."""
        vp = np.repeat(np.arange(self.n_viewpoints, dtype=np.int64), np.diff(self.ptr))
        return vp, self.target.copy()

    def per_viewpoint(self) -> IntArray:
        """How many targets each viewpoint sees."""
        counts: IntArray = np.diff(self.ptr)
        return counts

    def per_target(self) -> IntArray:
        """How many viewpoints see each target."""
        counts: IntArray = np.bincount(self.target, minlength=self.n_targets)
        return counts

    def viewpoints_of(self, target: int) -> IntArray:
        """The viewpoints that see ``target``, ascending."""
        vp, tg = self.pairs()
        out: IntArray = vp[tg == target]
        return out

    def dense(self, rows: npt.ArrayLike | None = None) -> BoolArray:
        """The boolean matrix of ``rows`` (all viewpoints when None) by targets; only for
        small instances or a tour's few rows."""
        idx = (
            np.arange(self.n_viewpoints, dtype=np.int64)
            if rows is None
            else np.asarray(rows, dtype=np.int64).ravel()
        )
        out = np.zeros((idx.size, self.n_targets), dtype=bool)
        counts = self.ptr[idx + 1] - self.ptr[idx]
        row = np.repeat(np.arange(idx.size), counts)
        starts = np.repeat(self.ptr[idx] - np.cumsum(counts) + counts, counts)
        out[row, self.target[starts + np.arange(row.size)]] = True
        return out

    def seen(self, order: npt.ArrayLike) -> BoolArray:
        """Which targets the viewpoints ``order`` see between them."""
        idx = np.asarray(order, dtype=np.int64).ravel()
        out = np.zeros(self.n_targets, dtype=bool)
        if idx.size:
            counts = self.ptr[idx + 1] - self.ptr[idx]
            starts = np.repeat(self.ptr[idx] - np.cumsum(counts) + counts, counts)
            out[self.target[starts + np.arange(starts.size)]] = True
        return out


@dataclass(frozen=True, slots=True)
class Instance:
    """A generalized TSP with cover sets: visit viewpoints so that every target is seen.

    ``covers`` says which targets each viewpoint sees (a GTSPLIB cluster is a target whose
    viewpoints are its nodes), as sparse rows. Distances come in one of two forms:

    - explicit: ``distance[u, v]`` is the cost of flying from ``u`` to ``v`` (asymmetric
      allowed), an ``n x n`` matrix for small instances such as GTSPLIB's;
    - on the plane: ``distance`` is None and the cost is the Euclidean distance between
      ``points_xy``, computed where it is needed, so that memory grows linearly with the
      viewpoints.

    With a depot, every tour starts and ends there: ``depot_distance[0, v]`` is depot -> ``v``
    and ``depot_distance[1, v]`` is ``v`` -> depot (on the plane, both are the distances to
    ``depot_xy``); without one, a tour is a closed cycle through its viewpoints.

    Planning instances also carry the target geometry (for geometric bounds) and an
    ``oracle`` that says what any point of the flight plane sees, so a solver that places
    viewpoints of its own can have each one checked on the terrain.
    """

    covers: Covers
    distance: FloatArray | None = None
    depot_distance: FloatArray | None = None
    points_xy: FloatArray | None = None
    depot_xy: tuple[float, float] | None = None
    owner: IntArray | None = None
    geometry: Geometry | None = None
    oracle: Oracle | None = field(default=None, repr=False, compare=False)
    name: str = ""
    heading_deg: FloatArray | None = None

    def __post_init__(self) -> None:
        n = self.covers.n_viewpoints
        if self.distance is None and self.points_xy is None:
            raise ValueError("Instance needs a distance matrix or the viewpoints' points_xy")
        if self.distance is not None and self.distance.shape != (n, n):
            raise ValueError("Instance.distance must be n x n for n viewpoints")
        if self.depot_distance is not None and self.depot_distance.shape != (2, n):
            raise ValueError("Instance.depot_distance must be 2 x n")
        if self.distance is None and self.depot_distance is not None and self.depot_xy is None:
            raise ValueError("Instance on the plane with a depot needs depot_xy")
        if self.points_xy is not None and self.points_xy.shape != (n, 2):
            raise ValueError("Instance.points_xy must be n x 2")
        if self.owner is not None and self.owner.shape != (n,):
            raise ValueError("Instance.owner must have one entry per viewpoint")
        if self.heading_deg is not None and self.heading_deg.shape != (n,):
            raise ValueError("Instance.heading_deg must have one entry per viewpoint")
        missing = np.flatnonzero(self.covers.per_target() == 0)
        if missing.size:
            raise ValueError(f"targets {missing.tolist()} are seen by no viewpoint")
        # Solvers share these arrays; none may change them.
        arrays = (self.distance, self.depot_distance, self.points_xy, self.owner, self.heading_deg)
        for array in arrays:
            if array is not None:
                array.setflags(write=False)

    @classmethod
    def from_cover_pairs(
        cls,
        viewpoint_idx: npt.ArrayLike,
        target_idx: npt.ArrayLike,
        points_xy: FloatArray,
        n_targets: int,
        depot_xy: tuple[float, float] | None = None,
        **fields: Any,
    ) -> Instance:
        """An instance on the plane from (viewpoint, target) pairs: viewpoint
        ``viewpoint_idx[k]`` sees target ``target_idx[k]``.

        Parameters
        ----------
        viewpoint_idx, target_idx
            The pairs, in any order.
        points_xy
            ``(n, 2)`` viewpoint positions, metres; distances are Euclidean between them.
        n_targets
            How many targets there are (each must be seen by some viewpoint).
        depot_xy
            The depot, if tours start and end there.
        **fields
            Other :class:`Instance` fields (``owner``, ``geometry``, ``oracle``, ``name``,
            ``heading_deg``).
        """
        pts = np.asarray(points_xy, dtype=np.float64)
        covers = Covers.from_pairs(viewpoint_idx, target_idx, len(pts), n_targets)
        depot_distance = None
        if depot_xy is not None:
            to_depot = np.hypot(pts[:, 0] - depot_xy[0], pts[:, 1] - depot_xy[1])
            depot_distance = np.vstack([to_depot, to_depot])
            depot_xy = (float(depot_xy[0]), float(depot_xy[1]))
        return cls(
            covers=covers,
            depot_distance=depot_distance,
            points_xy=pts,
            depot_xy=depot_xy,
            **fields,
        )

    @property
    def n_viewpoints(self) -> int:
        return self.covers.n_viewpoints

    @property
    def n_targets(self) -> int:
        return self.covers.n_targets

    @property
    def has_depot(self) -> bool:
        return self.depot_distance is not None

    @property
    def explicit(self) -> bool:
        """Whether distances come from a matrix (else from ``points_xy``)."""
        return self.distance is not None

    def legs(self, u: npt.ArrayLike, v: npt.ArrayLike) -> FloatArray:
        """The costs of ``u[k] -> v[k]``, element by element."""
        a = np.asarray(u, dtype=np.int64)
        b = np.asarray(v, dtype=np.int64)
        if self.distance is not None:
            out: FloatArray = self.distance[a, b]
            return out
        assert self.points_xy is not None
        p, q = self.points_xy[a], self.points_xy[b]
        legs: FloatArray = np.hypot(p[..., 0] - q[..., 0], p[..., 1] - q[..., 1])
        return legs

    def matrix(self) -> FloatArray:
        """The full ``n x n`` distance matrix: the stored one, or built from the points.
        For small instances only; callers check the memory budget first."""
        if self.distance is not None:
            return self.distance
        assert self.points_xy is not None
        return euclidean_matrix(self.points_xy)

    def nbytes(self) -> int:
        """Memory held by the instance's arrays."""
        arrays = (self.distance, self.depot_distance, self.points_xy, self.owner)
        return self.covers.nbytes + sum(a.nbytes for a in arrays if a is not None)

    def tour_length(self, order: npt.ArrayLike) -> float:
        """Length of the closed tour through viewpoints ``order`` (and the depot, if any)."""
        idx = np.asarray(order, dtype=np.int64)
        if idx.size == 0:
            return 0.0
        inner = float(self.legs(idx[:-1], idx[1:]).sum())
        if self.depot_distance is not None:
            return inner + float(self.depot_distance[0, idx[0]] + self.depot_distance[1, idx[-1]])
        return inner + float(self.legs(idx[-1:], idx[:1]).sum())

    def uncovered(self, order: npt.ArrayLike) -> list[int]:
        """Targets that no viewpoint in ``order`` sees."""
        return [int(t) for t in np.flatnonzero(~self.covers.seen(order))]


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


# Bytes per viewpoint of a planning instance on the plane: its position, the two depot legs,
# its owner and its cover-row offset.
_BYTES_PER_VIEWPOINT = 16.0 + 16.0 + 8.0 + 8.0
# Bytes per (viewpoint, target) pair that sees: its two indices.
_BYTES_PER_PAIR = 16.0
# Viewpoints whose candidate pairs are gathered and tested at once.
_PAIR_CHUNK_VIEWPOINTS = 20_000


def instance_bytes(n_viewpoints: int, n_pairs: int) -> float:
    """Memory of a planning instance: linear in the viewpoints (positions, depot legs, owners,
    cover-row offsets) and in the (viewpoint, target) pairs where one sees the other (two
    indices each, while they are gathered). No distance matrix is kept."""
    return float(n_viewpoints) * _BYTES_PER_VIEWPOINT + float(n_pairs) * _BYTES_PER_PAIR


def require_instance_memory(n_viewpoints: int, n_pairs: int) -> None:
    """Refuse a planning instance whose arrays would not fit the memory budget.

    Raises
    ------
    MemoryBudgetError
        Naming the estimate and what to change (both sizes scale with ``--samples`` and the
        number of targets).
    """
    require_memory(
        instance_bytes(n_viewpoints, n_pairs),
        f"the cover sets of {n_viewpoints} viewpoints ({n_pairs} viewpoint-target pairs)",
        "use fewer --samples, or fewer targets per plan",
    )


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
