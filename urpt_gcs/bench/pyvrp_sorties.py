"""PyVRP beside our sortie planning: sorties from one home, each within the endurance, for the
least total flight time.

Our planning solves one GTSP tour over the candidate viewpoints
(:func:`urpt_gcs.solvers.registry.solve`) and then searches its sorties
(:func:`urpt_gcs.flight.sorties.order_sorties`: the order for its cut, then the sorties as
routes, each stop flyable from the nearest other viewpoints that see what it sees). PyVRP
(an optional dependency, the ``bench`` extra) solves the same question as a vehicle-routing
problem:

- home is the one depot and every sortie is a vehicle of one type, as many available as there
  are targets (each target alone fits a sortie, or the plan is refused);
- a viewpoint is a client; the viewpoints of a target form a required client group (exactly
  one visited). A client belongs to one group, so only viewpoints that see exactly one target
  can be expressed: :func:`one_target_instance` keeps those, and drops the targets that have
  none. Splitting a viewpoint into one copy per target it sees is not equivalent: a stop that
  serves two targets would be counted, and timed, as two stops;
- the duration matrix is the :class:`~urpt_gcs.problem.flight_time.FlightModel`'s leg times
  (into home: the leg home at the return speed, so it is asymmetric), the clients' service
  duration is the stop's time, the depot's service duration and each vehicle's fixed cost the
  take-off and the landing, and the shift duration the endurance. The distance matrix is the
  duration matrix, so that PyVRP's objective is the total flight time less the stops' time,
  which is the same for every solution (one stop per target);
- PyVRP takes integers: seconds are scaled to centiseconds (:data:`TICKS_PER_S`), every time
  rounded up and the endurance down, so that a route PyVRP finds within the endurance is
  within it in the model too.

Both sides are checked by :func:`check_sorties`, which times every sortie again with
:meth:`FlightModel.sortie_s <urpt_gcs.problem.flight_time.FlightModel.sortie_s>` from the
positions alone and checks that every target is seen and every sortie fits the endurance.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.flight.sorties import SEARCH_SHARE, order_sorties
from urpt_gcs.pipeline.missions import ALTERNATIVES
from urpt_gcs.problem.flight_time import FlightModel, split_sorties
from urpt_gcs.problem.instance import Covers, Geometry, Instance, euclidean_matrix
from urpt_gcs.solvers import SolveSettings, choose, prepare, solve
from urpt_gcs.solvers.sortie_routes import viewpoints_seeing

if TYPE_CHECKING:
    import pyvrp

__all__ = [
    "ENDURANCE_SLACK_S",
    "TICKS_PER_S",
    "SortieCheck",
    "SortieRun",
    "best_viewpoint_instance",
    "check_sorties",
    "one_target_instance",
    "our_sorties",
    "pyvrp_data",
    "pyvrp_sorties",
]

# PyVRP's times are integers: ticks per second of the model (centiseconds).
TICKS_PER_S = 100
# How far over the endurance a sortie may be timed by the check before it counts as over:
# float rounding between two sums of the same legs in another order.
ENDURANCE_SLACK_S = 1e-6


@dataclass(frozen=True, slots=True)
class SortieRun:
    """Sorties one side found, as it reports them.

    Attributes
    ----------
    solver
        Who found them (``ours (heuristic)``, ``pyvrp``).
    routes
        Each sortie's viewpoints in flight order, as indices of the instance solved.
    reported_s
        The total flight time the side reports: ours the sum of its sorties' times, PyVRP
        its objective (centiseconds, as seconds) plus the stops' time.
    feasible
        Whether the side says its solution is feasible (PyVRP's ``is_feasible``; ours
        always, or it raises).
    wall_s
        Wall time of the search, model building aside.
    """

    solver: str
    routes: tuple[tuple[int, ...], ...]
    reported_s: float
    feasible: bool
    wall_s: float


@dataclass(frozen=True, slots=True)
class SortieCheck:
    """Sorties timed again from their positions alone, and checked.

    Attributes
    ----------
    flight_time_s
        Total flight time, each sortie by :meth:`FlightModel.sortie_s`.
    length_m
        Total horizontal length flown, home to home for every sortie.
    longest_s
        The longest sortie.
    uncovered
        Targets no sortie sees.
    repeated
        Targets seen by more than one stop.
    over_endurance
        Sorties (by index) longer than the endurance.
    """

    flight_time_s: float
    length_m: float
    longest_s: float
    uncovered: tuple[int, ...]
    repeated: tuple[int, ...]
    over_endurance: tuple[int, ...]

    @property
    def ok(self) -> bool:
        """Every target seen and every sortie within the endurance."""
        return not self.uncovered and not self.over_endurance


def one_target_instance(instance: Instance) -> tuple[Instance, IntArray, IntArray]:
    """The instance's viewpoints that see exactly one target, and the targets they see.

    Parameters
    ----------
    instance
        A planning instance on the plane with a depot (home).

    Returns
    -------
    tuple of Instance, ndarray, ndarray
        The restricted instance (no oracle: it cannot place viewpoints of its own), and the
        original indices of its viewpoints and of its targets.
    """
    if instance.points_xy is None or instance.depot_xy is None:
        raise ValueError("one_target_instance needs viewpoints on the plane and a home")
    single = np.flatnonzero(instance.covers.per_viewpoint() == 1)
    seen_by = instance.covers.target[instance.covers.ptr[single]]
    targets = np.unique(seen_by)
    new_target = np.full(instance.n_targets, -1, dtype=np.int64)
    new_target[targets] = np.arange(targets.size)
    geometry = None
    g = instance.geometry
    if g is not None:
        geometry = Geometry(
            targets_xy=g.targets_xy[targets],
            ground_m=g.ground_m[targets],
            altitude_m=g.altitude_m,
            fov_deg=g.fov_deg,
            terrain_max_m=g.terrain_max_m,
        )
    restricted = Instance.from_cover_pairs(
        np.arange(single.size),
        new_target[seen_by],
        instance.points_xy[single],
        int(targets.size),
        depot_xy=instance.depot_xy,
        geometry=geometry,
        name=f"{instance.name} one-target viewpoints",
        heading_deg=None if instance.heading_deg is None else instance.heading_deg[single],
    )
    return restricted, single, targets


def best_viewpoint_instance(instance: Instance) -> tuple[Instance, IntArray]:
    """One viewpoint per target of a one-target instance: the nearest to the target on the
    plane (plain vehicle routing, no choice of viewpoint left).

    Parameters
    ----------
    instance
        An instance whose viewpoints each see one target (:func:`one_target_instance`),
        with the target geometry.

    Returns
    -------
    tuple of Instance and ndarray
        The instance with viewpoint ``t`` seeing target ``t``, and the indices of its
        viewpoints in ``instance``.
    """
    g, pts = instance.geometry, instance.points_xy
    if g is None or pts is None or instance.depot_xy is None:
        raise ValueError("best_viewpoint_instance needs the target geometry, points and home")
    if np.any(instance.covers.per_viewpoint() != 1):
        raise ValueError("best_viewpoint_instance needs viewpoints that see one target each")
    vp, tg = instance.covers.pairs()
    off = np.hypot(*(pts[vp] - g.targets_xy[tg]).T)
    order = np.lexsort((off, tg))
    first = np.flatnonzero(np.r_[True, np.diff(tg[order]) != 0])
    chosen = vp[order[first]]
    best = Instance(
        covers=Covers.identity(instance.n_targets),
        depot_distance=instance.depot_distance[:, chosen]
        if instance.depot_distance is not None
        else None,
        points_xy=pts[chosen],
        depot_xy=instance.depot_xy,
        geometry=g,
        name=f"{instance.name}, best viewpoint",
        heading_deg=None if instance.heading_deg is None else instance.heading_deg[chosen],
    )
    return best, chosen


def check_sorties(
    instance: Instance,
    routes: tuple[tuple[int, ...], ...],
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float,
) -> SortieCheck:
    """Time each sortie from home through its viewpoints and back, and check the whole.

    Parameters
    ----------
    instance
        The instance the routes visit (its viewpoints on the plane, home its depot).
    routes
        Each sortie's viewpoints in flight order.
    altitude_rel_m
        The flight plane above home (take-off and landing).
    model
        Times the legs, stops, take-off and landing.
    endurance_s
        The longest a sortie may fly.

    Returns
    -------
    SortieCheck
        The totals and whatever is wrong.
    """
    assert instance.points_xy is not None and instance.depot_xy is not None
    home = np.asarray(instance.depot_xy, dtype=np.float64)
    times: list[float] = []
    lengths: list[float] = []
    for route in routes:
        path = np.vstack([home, instance.points_xy[list(route)], home])
        legs = np.hypot(*np.diff(path, axis=0).T)
        times.append(model.sortie_s(legs, altitude_rel_m))
        lengths.append(float(legs.sum()))
    visited = [v for route in routes for v in route]
    vp, tg = instance.covers.pairs()
    hits = np.zeros(instance.n_targets, dtype=np.int64)
    for v in visited:
        hits[tg[vp == v]] += 1
    return SortieCheck(
        flight_time_s=math.fsum(times),
        length_m=math.fsum(lengths),
        longest_s=max(times, default=0.0),
        uncovered=tuple(int(t) for t in np.flatnonzero(hits == 0)),
        repeated=tuple(int(t) for t in np.flatnonzero(hits > 1)),
        over_endurance=tuple(k for k, t in enumerate(times) if t > endurance_s + ENDURANCE_SLACK_S),
    )


def our_sorties(
    instance: Instance,
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float,
    wall_s: float,
    seed: int = 0,
    solver: str = "auto",
) -> SortieRun:
    """Our planning within ``wall_s``: the solver's tour, then its stops ordered for the cut
    into sorties, the two sharing the time as the planner shares ``--time-limit``.

    Parameters
    ----------
    instance
        Viewpoints on the plane with home as the depot.
    altitude_rel_m, model, endurance_s
        The flight plane above home, the flight-time model and the endurance.
    wall_s
        The time both stages may spend together: the solver gets ``wall_s / (1 +
        SEARCH_SHARE)``, the sortie order the rest (its kernels compiled first).
    seed
        The solver's and the order search's seed.
    solver
        The solver's name, as for :func:`urpt_gcs.solvers.registry.solve`.

    Returns
    -------
    SortieRun
        The sorties, their total flight time by the cut, and the wall time of both stages.
    """
    assert instance.depot_xy is not None
    name = choose(instance, solver)
    prepare(name)
    solve_s = wall_s / (1.0 + SEARCH_SHARE)
    started = time.perf_counter()
    tour = solve(instance, name, SolveSettings(time_limit_s=solve_s, seed=seed))
    if -1 in tour.order:
        raise ValueError(f"{tour.solver}: a stop that is not an instance viewpoint")
    names = [f"stop {k}" for k in range(1, len(tour.order) + 1)]
    home = (float(instance.depot_xy[0]), float(instance.depot_xy[1]))
    assert tour.points_xy is not None and instance.points_xy is not None
    # Each stop may be flown from the other viewpoints of what it sees, as PyVRP chooses
    # among a group's clients (no terrain here: every viewpoint sees what it is given).
    others, owner = viewpoints_seeing(instance, tour.points_xy, tour.sees, ALTERNATIVES)
    ptr = np.searchsorted(owner, np.arange(len(tour.sees) + 1))
    tour, _ = order_sorties(
        tour,
        home,
        altitude_rel_m,
        model,
        endurance_s,
        names,
        wall_s - solve_s,
        seed,
        lambda: (others, ptr),
    )
    assert tour.points_xy is not None
    cut = split_sorties(tour.points_xy, home, altitude_rel_m, model, endurance_s, names)
    wall = time.perf_counter() - started
    # A stop flown from an alternative is that viewpoint: found by its position.
    dist, nearest = cKDTree(instance.points_xy).query(tour.points_xy)
    if float(np.max(dist)) > 0.0:
        raise ValueError("ours: a stop that is not at an instance viewpoint")
    visited = np.asarray(nearest, dtype=np.int64)
    routes = tuple(tuple(int(v) for v in visited[s.first : s.stop]) for s in cut)
    return SortieRun(
        solver=f"ours ({name})",
        routes=routes,
        reported_s=math.fsum(s.flight_time_s for s in cut),
        feasible=True,
        wall_s=wall,
    )


def _ticks(seconds: FloatArray | float) -> IntArray:
    """Seconds as whole ticks, rounded up."""
    out: IntArray = np.ceil(np.asarray(seconds, dtype=np.float64) * TICKS_PER_S - 1e-9).astype(
        np.int64
    )
    return out


def pyvrp_data(
    instance: Instance, altitude_rel_m: float, model: FlightModel, endurance_s: float
) -> pyvrp.ProblemData:
    """The instance as PyVRP's ``ProblemData`` (see the module's description).

    Parameters
    ----------
    instance
        Viewpoints on the plane, each seeing one target, with home as the depot.
    altitude_rel_m, model, endurance_s
        The flight plane above home, the flight-time model and the endurance.

    Returns
    -------
    pyvrp.ProblemData
        Home the depot (location 0) and viewpoint ``v`` client ``v`` (location ``v + 1``);
        when some target has more than one viewpoint, every target a required client group
        of its viewpoints, else every client required.
    """
    import pyvrp

    assert instance.points_xy is not None and instance.depot_xy is not None
    xy = np.vstack([np.asarray(instance.depot_xy, dtype=np.float64), instance.points_xy])
    dist = euclidean_matrix(xy)
    secs = model.leg_s(dist)
    secs[:, 0] = model.return_s(dist[:, 0])
    np.fill_diagonal(secs, 0.0)
    matrix = _ticks(secs)
    ends = int(_ticks(model.takeoff_s(altitude_rel_m) + model.landing_s(altitude_rel_m)))
    stop = int(_ticks(model.stop_s))
    vp, tg = instance.covers.pairs()
    if vp.size != instance.n_viewpoints:
        raise ValueError("PyVRP's client groups take viewpoints that see one target each")
    grouped = instance.n_viewpoints > instance.n_targets
    target_of = np.empty(instance.n_viewpoints, dtype=np.int64)
    target_of[vp] = tg
    locations = [pyvrp.Location(float(x), float(y)) for x, y in xy]
    clients = [
        pyvrp.Client(
            location=v + 1,
            service_duration=stop,
            required=not grouped,
            group=int(target_of[v]) if grouped else None,
        )
        for v in range(instance.n_viewpoints)
    ]
    groups = (
        [
            pyvrp.ClientGroup([int(v) for v in np.flatnonzero(target_of == t)], required=True)
            for t in range(instance.n_targets)
        ]
        if grouped
        else []
    )
    vehicles = pyvrp.VehicleType(
        num_available=instance.n_targets,
        fixed_cost=ends,
        shift_duration=math.floor(endurance_s * TICKS_PER_S),
        unit_distance_cost=1,
        unit_duration_cost=0,
    )
    # PyVRP's stubs type a matrix as ndarray[int]: one distance and one duration matrix.
    matrices: list[Any] = [matrix]
    return pyvrp.ProblemData(
        locations,
        clients,
        [pyvrp.Depot(location=0, service_duration=ends)],
        [vehicles],
        matrices,
        matrices,
        groups,
    )


def pyvrp_sorties(
    instance: Instance,
    altitude_rel_m: float,
    model: FlightModel,
    endurance_s: float,
    wall_s: float,
    seed: int = 0,
) -> SortieRun:
    """PyVRP's sorties within ``wall_s`` (``MaxRuntime``), its seed fixed.

    Parameters
    ----------
    instance
        Viewpoints on the plane, each seeing one target, with home as the depot.
    altitude_rel_m, model, endurance_s
        The flight plane above home, the flight-time model and the endurance.
    wall_s
        PyVRP's runtime.
    seed
        PyVRP's seed.

    Returns
    -------
    SortieRun
        Its best solution's routes, and its objective as a flight time.
    """
    import pyvrp
    from pyvrp.stop import MaxRuntime

    data = pyvrp_data(instance, altitude_rel_m, model, endurance_s)
    started = time.perf_counter()
    result = pyvrp.solve(data, MaxRuntime(wall_s), seed=seed, collect_stats=False, display=False)
    wall = time.perf_counter() - started
    best = result.best
    routes = tuple(tuple(int(a.idx) for a in route if a.is_client()) for route in best.routes())
    stops = sum(len(r) for r in routes)
    # The objective is the legs' time and the take-offs and landings; the stops' time is the
    # same for every complete solution. An infeasible best solution has no objective.
    reported = result.cost() / TICKS_PER_S + stops * model.stop_s
    return SortieRun(
        solver="pyvrp",
        routes=routes,
        reported_s=reported if best.is_feasible() else math.inf,
        feasible=bool(best.is_feasible()),
        wall_s=wall,
    )
