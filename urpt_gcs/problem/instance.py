"""The GTSP instance with cover sets, free of terrain: viewpoints, what each sees, distances.

:class:`Instance` is what every solver takes: which targets each viewpoint sees
(:class:`Covers`, sparse rows), distances between viewpoints (a matrix or points on the
plane), an optional depot and, for planning instances, the target :class:`Geometry`.
Building one from a DEM is the job of the visibility package (``build_instance``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import BoolArray, FloatArray, IntArray, unique_ints
from urpt_gcs.memory import require_memory

__all__ = [
    "Covers",
    "Geometry",
    "Instance",
    "Oracle",
    "euclidean_matrix",
    "instance_bytes",
    "require_instance_memory",
]

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
        key = unique_ints(vp * max(n_targets, 1) + tg)
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
