"""The result of the stage chain: :class:`Plan`, everything a plan produced, and with
``--altitude auto`` the sweep of altitudes it was chosen from."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pyproj

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.bound.certificate import Certificate
from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.flight.band import FlightBand
from urpt_gcs.flight.mission import Mission
from urpt_gcs.flight.refinement import Refinement
from urpt_gcs.flight.safety import Leg
from urpt_gcs.flight.sorties import SortieOrder
from urpt_gcs.pipeline.missions import flight_model
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.flight_time import FlightModel, Sortie
from urpt_gcs.problem.instance import Instance
from urpt_gcs.site.dem import DemInfo
from urpt_gcs.site.targets import TargetSet
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import Tour
from urpt_gcs.visibility.regions import Camera, Region


@dataclass(frozen=True, slots=True)
class AltitudePoint:
    """One altitude of the sweep: what its plan flies, or why there is no plan."""

    altitude_m: float
    tour_length_m: float | None
    flight_time_s: float | None
    wall_s: float
    error: str = ""


@dataclass(frozen=True, slots=True)
class AltitudeSweep:
    """Every altitude planned, in ascending order, and the one kept."""

    points: tuple[AltitudePoint, ...]
    best_altitude_m: float
    wall_s: float


@dataclass(frozen=True, slots=True)
class BandFlight:
    """A flight that follows the terrain inside a height band (``--agl``).

    Attributes
    ----------
    band
        The heights above the surface the vehicle stays within.
    stops_xyz
        Every stop in flight order: x, y in the planning CRS, height in the DEM's datum.
    paths_xyz
        Per sortie, every point flown through in order: over home at the take-off height,
        the stops and the waypoints without a photo that follow the terrain, back over home.
    path_stop
        Per sortie, for each point of its path the stop it is (index into ``stops_xyz``),
        -1 for a waypoint that follows the terrain, -2 over home.
    lowest_m, highest_m
        The lowest and highest height above the surface anywhere along the written paths.
    time_bound_s
        A lower bound of the flight time of any flight inside the band that photographs
        every target (take-off and landing included).
    horizontal_bound_m
        A lower bound of the horizontal length of any such flight.
    estimate_s
        The flight time the solver's table gave its tour (its stops before they moved).
    unrefined_s
        The flight time with the solver's stops where it put them; the flight is that or,
        with its stops moved in three dimensions, shorter.
    """

    band: FlightBand
    stops_xyz: FloatArray
    paths_xyz: tuple[FloatArray, ...]
    path_stop: tuple[IntArray, ...]
    lowest_m: float
    highest_m: float
    time_bound_s: float
    horizontal_bound_m: float
    estimate_s: float
    unrefined_s: float

    @property
    def inserted(self) -> int:
        """How many waypoints without a photo follow the terrain."""
        return sum(int((p == -1).sum()) for p in self.path_stop)


@dataclass(frozen=True, slots=True)
class Plan:
    """Everything a plan produced, stage by stage: the site and the DEM window
    (:mod:`~urpt_gcs.pipeline.area`), the visibility regions and viewpoints, the tour, its
    sorties and missions as written and checked (:mod:`~urpt_gcs.pipeline.missions`), and
    the certificate; what :func:`urpt_gcs.pipeline.planner.plan` returns and every output
    file is written from."""

    settings: PlanSettings
    dem: DemInfo
    terrain: Terrain
    targets: TargetSet
    crs: pyproj.CRS
    targets_xy: FloatArray
    ground_m: FloatArray
    home_xy: tuple[float, float]
    home_ground_m: float
    home_source: str
    camera: Camera
    terrain_max_m: float
    regions: tuple[Region, ...]
    instance: Instance
    tour: Tour
    legs: tuple[Leg, ...]
    sorties: tuple[Sortie, ...]
    missions: tuple[Mission, ...]
    geofence_latlon: tuple[tuple[float, float], ...]
    flight_time_s: float
    timings_s: dict[str, float]
    warnings: tuple[str, ...]
    sortie_order: SortieOrder | None = None
    # With --altitude auto: every altitude planned and the one kept.
    altitude_sweep: AltitudeSweep | None = None
    # The solver's tour before and after its stops were moved within their regions.
    refinement: Refinement | None = None
    # The certified lower bound of every flight that photographs every target.
    certificate: Certificate | None = None
    # The solver's claim for its tour (before any stop moved): no tour over the candidate
    # viewpoints is shorter.
    optimal_over_candidates: bool = False
    # With --agl: the flight inside the height band, following the terrain.
    band_flight: BandFlight | None = None

    @property
    def lower_bound_m(self) -> float:
        """A lower bound of every flight from home that photographs every target, from
        anywhere on the plane (not only the candidate viewpoints)."""
        if self.certificate is not None:
            return self.certificate.lower_bound_m
        return min(geometric_lower_bound(self.instance), self.flown_length_m)

    @property
    def flown_length_m(self) -> float:
        """Length of every sortie as flown, each from home and back, added up."""
        return math.fsum(s.length_m for s in self.sorties)

    @property
    def flown_gap(self) -> float:
        """How much longer the flight may be than the shortest that sees every target:
        (flown - LB) / LB, with LB :attr:`lower_bound_m`.

        The bound holds for any closed flight from home that sees every target, and sorties
        from home joined at home are one such flight, no longer than their total: so it
        bounds the total of any set of sorties too.
        """
        bound = self.lower_bound_m
        if bound <= 0.0:
            return 0.0 if self.flown_length_m <= 0.0 else math.inf
        return max(self.flown_length_m - bound, 0.0) / bound

    @property
    def proven_optimal(self) -> bool:
        """Whether the flight is certified within the tolerance of the shortest possible."""
        return self.certificate is not None and self.certificate.proven(self.flown_length_m)

    @property
    def flight_model(self) -> FlightModel:
        """How the flight-time estimate sees the vehicle (see
        :func:`~urpt_gcs.pipeline.missions.flight_model`)."""
        return flight_model(self.settings)

    @property
    def mission(self) -> Mission:
        """The mission of the first (or only) sortie."""
        return self.missions[0]

    @property
    def altitude_rel_m(self) -> float:
        """The flight plane's height above home, as the missions write it."""
        return self.mission.altitude_rel_m


__all__ = ["AltitudePoint", "AltitudeSweep", "BandFlight", "Plan"]
