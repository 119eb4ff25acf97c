"""What the ground station saw of one flight: its photos, its track and which vehicle flew.

:mod:`urpt_gcs.replay.fly` records a :class:`Flight`; :mod:`urpt_gcs.replay.judge` checks it
against the terrain and the targets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from urpt_gcs.vehicle.link import UploadReport

__all__ = ["SIMULATED", "Flight", "PhotoFix", "TrackPoint", "VehicleIdentity"]

# How the simulated copter is named where a vehicle's place is said.
SIMULATED = "the simulated ArduCopter (urpt-gcs)"


@dataclass(frozen=True, slots=True)
class PhotoFix:
    """A photo as CAMERA_FEEDBACK (PX4: CAMERA_IMAGE_CAPTURED) reported it."""

    index: int
    lat_deg: float
    lon_deg: float
    alt_rel_m: float
    time_s: float
    # The vehicle's heading CAMERA_FEEDBACK reported (yaw, degrees); NaN where none came.
    heading_deg: float = math.nan


@dataclass(frozen=True, slots=True)
class TrackPoint:
    """A position as GLOBAL_POSITION_INT reported it (time in simulated seconds).

    ``wall_s`` is the ground station's monotonic clock when it arrived, one clock for every
    vehicle of a fleet.
    """

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_rel_m: float
    wall_s: float = math.nan


@dataclass(frozen=True, slots=True)
class VehicleIdentity:
    """Which vehicle flew: its autopilot and version (AUTOPILOT_VERSION) and where it ran.

    ``version`` is empty when the vehicle did not say.
    """

    autopilot: str
    version: str
    where: str

    def describe(self) -> str:
        """E.g. "ArduPilot 4.7.0-dev (ArduCopter SITL, pid 1234)"."""
        name = f"{self.autopilot} {self.version}".strip()
        if self.where == SIMULATED:
            return f"{SIMULATED}, which reports itself as {name}"
        return f"{name} ({self.where})"


@dataclass(frozen=True, slots=True)
class Flight:
    """What the ground station saw of one flight.

    ``sim_time_s`` is the vehicle's clock from arming to the disarm after landing,
    ``wall_time_s`` the wall clock over the same span. ``upload`` is None for a flight read
    from a log (:mod:`urpt_gcs.replay.flightlog`), whose upload this tool did not see.
    """

    upload: UploadReport | None
    photos: tuple[PhotoFix, ...]
    track: tuple[TrackPoint, ...]
    sim_time_s: float
    wall_time_s: float
    vehicle: VehicleIdentity
