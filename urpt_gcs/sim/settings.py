"""Settings of the simulated vehicle, checked on construction."""

from __future__ import annotations

import math
from dataclasses import dataclass

from urpt_gcs.errors import SettingsError
from urpt_gcs.flight.mission import GeoPoint
from urpt_gcs.site.position import parse_latlon

__all__ = [
    "DEFAULT_CAPACITY",
    "DEFAULT_HOME",
    "VehicleSettings",
    "parse_home",
]

# ArduPilot's capacity on common boards: (storage bytes - 4) / 15 items (see FACTS).
DEFAULT_CAPACITY = 700
DEFAULT_HOME = GeoPoint(47.397742, 8.545594, 488.0)


@dataclass(frozen=True, slots=True)
class VehicleSettings:
    """How the simulated vehicle behaves, and the faults it injects.

    Attributes
    ----------
    home
        Launch point; its altitude is AMSL.
    speedup
        Simulated seconds per wall-clock second.
    loss
        Fraction of packets dropped, independently in each direction.
    latency_ms
        Delay added to every packet, in each direction.
    drop_after
        Go silent (both directions) once this many mission items have been received, for
        ``drop_s`` seconds of wall time; once only.
    drop_s
        Length of the scripted silence.
    px4
        Identify as PX4 (no home item at seq 0, items stored verbatim).
    capacity
        Most mission items held, home included; a longer upload is refused with
        MAV_MISSION_NO_SPACE.
    boot_s
        For this long after start (wall time) refuse uploads with MAV_MISSION_NO_SPACE and
        arming, as ArduPilot does for about ten seconds after boot.
    seed
        Seed of the packet-loss random generator.
    corrupt_seq
        Read this seq back altered (about 1 m north): a fault for testing read-back checks.
    system_id
        MAVLink system id.
    arm_refusals
        Refuse this many arming commands after start-up ("PreArm: ..."), as a vehicle slow to
        pass its checks does: a fault for testing a fleet's staggered take-offs.
    """

    home: GeoPoint = DEFAULT_HOME
    speedup: float = 1.0
    loss: float = 0.0
    latency_ms: float = 0.0
    drop_after: int | None = None
    drop_s: float = 4.0
    px4: bool = False
    capacity: int = DEFAULT_CAPACITY
    boot_s: float = 0.0
    seed: int = 0
    corrupt_seq: int | None = None
    system_id: int = 1
    arm_refusals: int = 0

    def __post_init__(self) -> None:
        # The messages name the settings; ``urpt-gcs sitl`` shows its flags
        # (urpt_gcs.cli._root.SITL_FLAGS, SettingsError.naming).
        if not (math.isfinite(self.speedup) and 0.1 <= self.speedup <= 1000.0):
            raise SettingsError.about(
                "{speedup} {value} is out of range; use 0.1 to 1000", value=self.speedup
            )
        if not (math.isfinite(self.loss) and 0.0 <= self.loss < 1.0):
            raise SettingsError.about(
                "{loss} {value} is out of range; use 0 to below 1", value=self.loss
            )
        if not (math.isfinite(self.latency_ms) and 0.0 <= self.latency_ms <= 10_000.0):
            raise SettingsError.about(
                "{latency_ms} {value} ms is out of range; use 0 to 10000", value=self.latency_ms
            )
        if self.drop_after is not None and self.drop_after < 1:
            raise SettingsError.about(
                "{drop_after} {value} must be at least 1 item", value=self.drop_after
            )
        if not (math.isfinite(self.drop_s) and 0.0 < self.drop_s <= 600.0):
            raise SettingsError(f"drop length {self.drop_s} s is out of range; use up to 600 s")
        if not 2 <= self.capacity <= 65_535:
            raise SettingsError.about(
                "{capacity} {value} is out of range; use 2 to 65535", value=self.capacity
            )
        if not (math.isfinite(self.boot_s) and 0.0 <= self.boot_s <= 600.0):
            raise SettingsError.about(
                "{boot_s} {value} s is out of range; use 0 to 600 s", value=self.boot_s
            )
        if not 0 <= self.seed <= 2**32 - 1:
            raise SettingsError.about(
                "{seed} {value} is out of range; use 0 to {high}", value=self.seed, high=2**32 - 1
            )
        if not 0 <= self.arm_refusals <= 10_000:
            raise SettingsError(f"{self.arm_refusals} arm refusals is out of range; use 0 to 10000")
        if not 1 <= self.system_id <= 250:
            raise SettingsError(f"system id {self.system_id} is out of range; use 1 to 250")


def parse_home(text: str) -> GeoPoint:
    """``LAT,LON,ALT`` (degrees, degrees, metres AMSL) as a :class:`GeoPoint`."""
    lat, lon, alt = parse_latlon(text, "home", with_alt=True)
    return GeoPoint(lat, lon, alt)
