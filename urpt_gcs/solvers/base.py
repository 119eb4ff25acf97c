"""The solver interface: ``Instance -> Tour``, the settings a solver gets, and finishing a tour."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.problem.instance import Instance

__all__ = [
    "SEED_MAX",
    "SolveSettings",
    "Solver",
    "Tour",
    "finish_placed_tour",
    "finish_tour",
]

SEED_MAX = 2**32 - 1


@dataclass(frozen=True, slots=True)
class SolveSettings:
    """What a solver may spend."""

    time_limit_s: float = 5.0
    seed: int = 0
    # Threads the continuous order search for discs may run side by side.
    threads: int = 1
    # What each stop costs on top of its legs, in the distances' unit (metres on the plane):
    # the heuristic's search on the plane then weighs fewer stops against a longer tour.
    # Lengths and bounds stay lengths. 0: none, or in a plan, the flight model's.
    stop_cost: float = 0.0

    def __post_init__(self) -> None:
        # The messages name the settings; the CLI shows their flags (SettingsError.naming).
        if self.threads < 1:
            raise SettingsError.about("{threads} {value} must be at least 1", value=self.threads)
        if not (math.isfinite(self.time_limit_s) and self.time_limit_s > 0.0):
            raise SettingsError.about(
                "{time_limit_s} {value} must be a positive number of seconds",
                value=self.time_limit_s,
            )
        if not (math.isfinite(self.stop_cost) and self.stop_cost >= 0.0):
            raise SettingsError.about(
                "{stop_cost} {value} must be a number of metres at least 0", value=self.stop_cost
            )
        # numpy's generators take only non-negative seeds; 32 bits is what every one accepts.
        if not 0 <= self.seed <= SEED_MAX:
            raise SettingsError.about(
                "{seed} {value} is out of range; use 0 to {high}", value=self.seed, high=SEED_MAX
            )


@dataclass(frozen=True, slots=True)
class Tour:
    """A closed tour through viewpoints (from the depot and back, if the instance has one).

    ``order`` lists the instance viewpoints in flight order; a stop the solver placed itself
    (not an instance viewpoint) is ``-1`` there. ``points_xy`` are the stops' positions
    (None for an instance without coordinates) and ``sees[k, t]`` says stop ``k`` sees target
    ``t``, checked on the terrain for placed stops. ``lower_bound`` is a proven lower bound on
    any tour that sees every target (for a planning instance: from anywhere on the flight
    plane); ``proven_optimal`` says no tour over the instance's viewpoints is shorter.
    ``headings_deg`` is each stop's heading when the camera is a frame (None for the cone).
    """

    order: tuple[int, ...]
    length: float
    lower_bound: float
    proven_optimal: bool
    solver: str
    solve_s: float
    points_xy: FloatArray | None
    sees: BoolArray
    notes: tuple[str, ...] = field(default=())
    headings_deg: FloatArray | None = None

    @property
    def gap(self) -> float:
        """How much longer the tour may be than the best possible: (L - LB) / LB."""
        if self.proven_optimal:
            return 0.0
        if self.lower_bound <= 0.0:
            return math.inf
        return max(self.length - self.lower_bound, 0.0) / self.lower_bound


class Solver(Protocol):
    """Anything that turns an instance into a tour that sees every target."""

    name: str

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour: ...


def finish_tour(
    instance: Instance,
    order: list[int],
    lower_bound: float,
    solver: str,
    solve_s: float,
    proven: bool = False,
    notes: tuple[str, ...] = (),
) -> Tour:
    """Drop repeated viewpoints, recompute the length and check every target is seen."""
    seen: set[int] = set()
    unique = [v for v in order if not (v in seen or seen.add(v))]  # type: ignore[func-returns-value]
    missing = instance.uncovered(unique)
    if missing:
        raise PlanError(
            f"internal check failed: solver {solver} returned a tour that misses targets "
            f"{missing}; try another --solver and report this"
        )
    length = instance.tour_length(unique)
    if lower_bound > length * (1.0 + 1e-9) + 1e-6:
        raise PlanError(
            f"internal check failed: lower bound {lower_bound:.3f} exceeds the tour "
            f"({length:.3f}) from solver {solver}; report this"
        )
    bound = min(lower_bound, length)
    idx = np.asarray(unique, dtype=np.int64)
    return Tour(
        order=tuple(unique),
        length=length,
        lower_bound=bound,
        proven_optimal=proven or length <= bound * (1.0 + 1e-9),
        solver=solver,
        solve_s=solve_s,
        points_xy=None if instance.points_xy is None else instance.points_xy[idx],
        sees=instance.covers.dense(idx),
        notes=notes,
        headings_deg=None if instance.heading_deg is None else instance.heading_deg[idx],
    )


def finish_placed_tour(
    instance: Instance,
    points_xy: FloatArray,
    lower_bound: float,
    solver: str,
    solve_s: float,
    notes: tuple[str, ...] = (),
) -> Tour:
    """A tour through stops the solver placed itself, each re-checked on the terrain.

    What every stop sees comes from the instance's oracle (line of sight on the DEM inside
    the camera cone), not from the solver; the length is measured on the plane.
    """
    if instance.oracle is None:
        raise PlanError(f"solver {solver} places its own viewpoints and needs the terrain")
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    sees = instance.oracle(pts)
    missing = (
        np.flatnonzero(~sees.any(axis=0)).tolist() if len(pts) else list(range(instance.n_targets))
    )
    if missing:
        raise PlanError(
            f"internal check failed: solver {solver} returned a tour that misses targets "
            f"{missing}; try another --solver and report this"
        )
    legs = np.hypot(*np.diff(pts, axis=0).T).sum() if len(pts) > 1 else 0.0
    if instance.depot_xy is not None:
        depot = np.asarray(instance.depot_xy)
        length = float(legs + np.hypot(*(pts[0] - depot)) + np.hypot(*(pts[-1] - depot)))
    else:
        length = float(legs + np.hypot(*(pts[-1] - pts[0])))
    if lower_bound > length * (1.0 + 1e-9) + 1e-6:
        raise PlanError(
            f"internal check failed: lower bound {lower_bound:.3f} exceeds the tour "
            f"({length:.3f}) from solver {solver}; report this"
        )
    return Tour(
        order=(-1,) * len(pts),
        length=length,
        lower_bound=min(lower_bound, length),
        proven_optimal=False,
        solver=solver,
        solve_s=solve_s,
        points_xy=pts,
        sees=sees,
        notes=notes,
    )
