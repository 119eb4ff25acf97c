"""Settings of a plan and of a fleet: every choice a plan depends on, with its default."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from urpt_gcs.errors import SettingsError
from urpt_gcs.flight.mission import MissionSettings
from urpt_gcs.site.camera import Frame
from urpt_gcs.solvers import SOLVER_CHOICES, SolveSettings
from urpt_gcs.visibility.regions import DEFAULT_HEADINGS, Camera

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True, slots=True)
class PlanSettings:
    """Every choice a plan depends on. Defaults are what ``urpt-gcs plan`` uses."""

    fov_deg: float = 30.0
    samples: int = 36
    altitude_m: float | None = None
    clearance_m: float = 30.0
    min_clearance_m: float = 10.0
    home: tuple[float, float] | None = None
    solver: str = "auto"
    solve: SolveSettings = field(default_factory=SolveSettings)
    mission: MissionSettings = field(default_factory=MissionSettings)
    climb_m_s: float = 2.5
    descent_m_s: float = 1.5
    accel_m_s2: float = 2.5
    max_agl_m: float = 120.0
    strict: bool = False
    endurance_min: float | None = 20.0
    geofence_margin_m: float = 30.0
    position_tolerance_m: float = 1.5
    band: int | None = None
    workers: int | None = None
    frame: Frame | None = None
    gsd_cm: float | None = None
    headings: int = DEFAULT_HEADINGS
    # Seconds for the certified lower bound (None: min(5 s, half the time limit)).
    bound_time_s: float | None = None
    refine: bool = True
    # Whether to certify the flight (a plan tried only for its length may skip it).
    certify: bool = True

    def __post_init__(self) -> None:
        # The camera's own checks (GSD without pixels, headings out of range) run here, so a
        # bad flag is refused before any file is read.
        self.camera_at(0.0)
        if self.frame is not None and self.solver == "approx":
            raise SettingsError(
                "--solver approx places its own stops, which have no heading for a frame "
                "camera: use --solver auto, exact, heuristic or ortools, or the cone (--fov)"
            )
        if self.workers is not None and self.workers < 1:
            raise SettingsError(
                f"--workers {self.workers} is below 1: give a number of threads, or omit it "
                "to use every core"
            )
        if not (
            math.isfinite(self.position_tolerance_m) and 0.0 <= self.position_tolerance_m <= 20.0
        ):
            raise SettingsError(
                f"--position-tolerance {self.position_tolerance_m} m is out of range; use 0 to 20 m"
            )
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError(
                f"--fov {self.fov_deg} is outside (0, 90): give the camera half-angle in degrees"
            )
        if self.samples < 3:
            raise SettingsError(f"--samples {self.samples} is below 3: use at least 3 azimuths")
        if self.samples > 3600:
            raise SettingsError(f"--samples {self.samples} is above 3600: use fewer azimuths")
        if self.altitude_m is not None and not math.isfinite(self.altitude_m):
            raise SettingsError(f"--altitude {self.altitude_m} is not a number of metres")
        if not (math.isfinite(self.clearance_m) and self.clearance_m > 0.0):
            raise SettingsError(
                f"--clearance {self.clearance_m} must be a positive number of metres"
            )
        if not (math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0.0):
            raise SettingsError(
                f"--min-clearance {self.min_clearance_m} must be zero or more metres"
            )
        if not (math.isfinite(self.max_agl_m) and self.max_agl_m > 0.0):
            raise SettingsError(f"--max-agl {self.max_agl_m} must be a positive number of metres")
        if self.endurance_min is not None and not (
            math.isfinite(self.endurance_min) and self.endurance_min > 0.0
        ):
            raise SettingsError(
                f"--endurance {self.endurance_min} must be a positive number of minutes"
            )
        if self.solver not in SOLVER_CHOICES:
            raise SettingsError(
                f"--solver {self.solver!r} is not known: use one of {', '.join(SOLVER_CHOICES)}"
            )
        if self.home is not None:
            lat, lon = self.home
            if not (
                math.isfinite(lat)
                and -90 <= lat <= 90
                and math.isfinite(lon)
                and -180 <= lon <= 180
            ):
                hint = ""
                if -90 <= lon <= 90 and -180 <= lat <= 180:
                    hint = f": did you swap lat and lon? Give --home LAT,LON: --home {lon},{lat}"
                raise SettingsError(f"--home {lat},{lon} is not a valid LAT,LON in degrees{hint}")
        if self.bound_time_s is not None and not (
            math.isfinite(self.bound_time_s) and 0.0 < self.bound_time_s <= 3600.0
        ):
            raise SettingsError(
                f"--bound-time {self.bound_time_s} is out of range: give a number of seconds "
                "above 0, up to 3600"
            )
        if self.band is not None and self.band < 1:
            raise SettingsError(f"--band {self.band} is below 1: bands are numbered from 1")

    def camera_at(self, altitude_m: float) -> Camera:
        """The camera these settings describe, on a plane at ``altitude_m``."""
        if self.frame is None:
            return Camera(altitude_m, self.fov_deg, gsd_cm=self.gsd_cm)
        return Camera.framed(altitude_m, self.frame, self.gsd_cm, self.headings)


SeparationMode = Literal["altitude", "time"]
SEPARATION_MODES = ("altitude", "time")
_FLEET_KEYS = {
    "home_lat": "degrees",
    "home_lon": "degrees",
    "speed_m_s": "m/s",
    "endurance_min": "minutes",
    "altitude_m": "metres",
}


@dataclass(frozen=True, slots=True)
class VehicleSpec:
    """What differs for one vehicle; None: the plan's own value."""

    home: tuple[float, float] | None = None
    speed_m_s: float | None = None
    endurance_min: float | None = None
    altitude_m: float | None = None


@dataclass(frozen=True, slots=True)
class FleetSettings:
    """The fleet and how its vehicles are kept apart."""

    vehicles: tuple[VehicleSpec, ...]
    separation: SeparationMode = "altitude"
    layer_spacing_m: float = 10.0
    min_separation_m: float = 10.0
    source: str = "--vehicles"

    def __post_init__(self) -> None:
        if not self.vehicles:
            raise SettingsError(f"{self.source} has no vehicle: give at least one")
        if len(self.vehicles) > 16:
            raise SettingsError(
                f"{self.source}: {len(self.vehicles)} vehicles, over the 16 a fleet may have: "
                "plan fewer at a time"
            )
        if self.separation not in SEPARATION_MODES:
            raise SettingsError(
                f"--separation {self.separation!r} is not known: use altitude or time"
            )
        if not (math.isfinite(self.layer_spacing_m) and self.layer_spacing_m > 0.0):
            raise SettingsError(
                f"--layer-spacing {self.layer_spacing_m} must be a positive number of metres"
            )
        if not (math.isfinite(self.min_separation_m) and self.min_separation_m > 0.0):
            raise SettingsError(
                f"--min-separation {self.min_separation_m} must be a positive number of metres"
            )

    @property
    def min_m(self) -> float:
        """The separation required: vertical spacing, or horizontal distance in time mode."""
        return self.layer_spacing_m if self.separation == "altitude" else self.min_separation_m


def read_fleet(path: Path) -> tuple[VehicleSpec, ...]:
    """The vehicles of a fleet file: one ``[[vehicle]]`` table each, with any of
    ``home_lat``/``home_lon`` (together), ``speed_m_s``, ``endurance_min``, ``altitude_m``.

    Raises
    ------
    SettingsError
        One line naming the file, the vehicle, the key and the fix.
    """
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise SettingsError(f"--fleet '{path}' does not exist: check the path") from None
    except IsADirectoryError:
        raise SettingsError(f"--fleet '{path}' is a folder: give a .toml file") from None
    except UnicodeDecodeError:
        raise SettingsError(f"--fleet '{path}' is not UTF-8 text: save it as UTF-8") from None
    except OSError as exc:
        raise SettingsError(f"--fleet '{path}' cannot be read: {exc.strerror or exc}") from None
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"--fleet {path}: not valid TOML ({exc}): fix the syntax") from None
    extra = sorted(set(document) - {"vehicle"})
    if extra:
        raise SettingsError(
            f"--fleet {path}: unknown table or key '{extra[0]}': the file holds only "
            "[[vehicle]] tables"
        )
    tables = document.get("vehicle")
    if not isinstance(tables, list) or not tables:
        raise SettingsError(
            f"--fleet {path}: no [[vehicle]] table: add one per vehicle (an empty one takes "
            "the plan's defaults)"
        )
    return tuple(_vehicle(path, number, raw) for number, raw in enumerate(tables, start=1))


def _vehicle(path: Path, number: int, raw: object) -> VehicleSpec:
    where = f"--fleet {path}: [[vehicle]] {number}"
    if not isinstance(raw, dict):
        raise SettingsError(f"{where} is not a table: write it as [[vehicle]] with keys")
    values: dict[str, float] = {}
    for key, value in raw.items():
        if key not in _FLEET_KEYS:
            known = ", ".join(_FLEET_KEYS)
            raise SettingsError(f"{where}: unknown key '{key}': use {known}")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SettingsError(
                f"{where}: {key} = {value!r} is not a number: give it in {_FLEET_KEYS[key]}"
            )
        if not math.isfinite(value):
            raise SettingsError(f"{where}: {key} = {value} is not a finite number")
        values[key] = float(value)
    if ("home_lat" in values) != ("home_lon" in values):
        missing = "home_lon" if "home_lat" in values else "home_lat"
        raise SettingsError(f"{where}: home_lat and home_lon go together: add {missing}")
    home = None
    if "home_lat" in values:
        lat, lon = values["home_lat"], values["home_lon"]
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise SettingsError(
                f"{where}: home_lat = {lat:g}, home_lon = {lon:g} is not a position in degrees: "
                "latitude -90..90, longitude -180..180"
            )
        home = (lat, lon)
    for key, low, high in (("speed_m_s", 0.1, 50.0), ("endurance_min", 1e-6, 1e6)):
        if key in values and not low <= values[key] <= high:
            raise SettingsError(
                f"{where}: {key} = {values[key]:g} is out of range: use {low:g} to {high:g} "
                f"{_FLEET_KEYS[key]}"
            )
    return VehicleSpec(
        home=home,
        speed_m_s=values.get("speed_m_s"),
        endurance_min=values.get("endurance_min"),
        altitude_m=values.get("altitude_m"),
    )
