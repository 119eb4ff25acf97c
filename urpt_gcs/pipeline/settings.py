"""Settings of a plan and of a fleet: every choice a plan depends on, with its default.

The defaults, flags, units and help texts are defined once, in :mod:`urpt_gcs.pipeline.options`;
:func:`plan_settings` turns option values (as the command line and a jobs file give them) into
:class:`PlanSettings`. An error names the setting (``fov_deg``): the command line shows its flag,
a jobs file its key (:meth:`urpt_gcs.errors.SettingsError.naming`).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from urpt_gcs.errors import SettingsError
from urpt_gcs.flight.band import FlightBand, parse_band
from urpt_gcs.flight.mission import MissionSettings
from urpt_gcs.pipeline.options import DEFAULTS, PLAN_OPTIONS, VEHICLE_KEYS
from urpt_gcs.site.camera import Frame, frame_from_flags
from urpt_gcs.site.inputs import read_settings_text
from urpt_gcs.site.position import parse_latlon
from urpt_gcs.solvers import SOLVER_CHOICES, SolveSettings
from urpt_gcs.visibility.regions import Camera

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "FLEET_MAX_VEHICLES",
    "SEPARATION_MODES",
    "FleetSettings",
    "PlanSettings",
    "SeparationMode",
    "VehicleSpec",
    "plan_settings",
    "read_fleet",
    "settings_from_record",
    "settings_record",
]

# The most vehicles one fleet plan shares the targets among: the split's search and the
# separation's pairwise checks grow with the square of the count.
FLEET_MAX_VEHICLES = 16


@dataclass(frozen=True, slots=True)
class PlanSettings:
    """Every choice a plan depends on. Defaults are what ``urpt-gcs plan`` uses."""

    fov_deg: float = DEFAULTS["fov_deg"]
    samples: int = DEFAULTS["samples"]
    altitude_m: float | None = DEFAULTS["altitude_m"]
    # Fly inside this band of heights above the surface (floor, ceiling), metres, following
    # the terrain; None: one flight plane.
    agl_band_m: tuple[float, float] | None = DEFAULTS["agl_band_m"]
    clearance_m: float = DEFAULTS["clearance_m"]
    min_clearance_m: float = DEFAULTS["min_clearance_m"]
    home: tuple[float, float] | None = DEFAULTS["home"]
    solver: str = DEFAULTS["solver"]
    solve: SolveSettings = field(default_factory=SolveSettings)
    mission: MissionSettings = field(default_factory=MissionSettings)
    climb_m_s: float = 2.5
    descent_m_s: float = 1.5
    accel_m_s2: float = 2.5
    max_agl_m: float = DEFAULTS["max_agl_m"]
    strict: bool = DEFAULTS["strict"]
    endurance_min: float | None = DEFAULTS["endurance_min"]
    geofence_margin_m: float = 30.0
    position_tolerance_m: float = DEFAULTS["position_tolerance_m"]
    band: int | None = DEFAULTS["band"]
    workers: int | None = DEFAULTS["workers"]
    frame: Frame | None = None
    gsd_cm: float | None = DEFAULTS["gsd_cm"]
    headings: int = DEFAULTS["headings"]
    # Seconds for the certified lower bound (None: min(5 s, half the time limit)).
    bound_time_s: float | None = DEFAULTS["bound_time_s"]
    refine: bool = DEFAULTS["refine"]
    # Whether to certify the flight (a plan tried only for its length may skip it).
    certify: bool = True

    def __post_init__(self) -> None:
        # The camera's own checks (GSD without pixels, headings out of range) run here, so a
        # bad flag is refused before any file is read.
        self.camera_at(0.0)
        if self.frame is not None and self.solver == "approx":
            raise SettingsError.about(
                "{solver} approx places its own stops, which have no heading for a frame "
                "camera: use {solver} auto, exact, heuristic or ortools, or the cone ({fov_deg})"
            )
        if self.workers is not None and self.workers < 1:
            raise SettingsError.about(
                "{workers} {value} is below 1: give a number of threads, or omit it "
                "to use every core",
                value=self.workers,
            )
        if not (
            math.isfinite(self.position_tolerance_m) and 0.0 <= self.position_tolerance_m <= 20.0
        ):
            raise SettingsError.about(
                "{position_tolerance_m} {value} m is out of range; use 0 to 20 m",
                value=self.position_tolerance_m,
            )
        if not (math.isfinite(self.fov_deg) and 0.0 < self.fov_deg < 90.0):
            raise SettingsError.about(
                "{fov_deg} {value} is outside (0, 90): give the camera half-angle in degrees",
                value=self.fov_deg,
            )
        if self.samples < 3:
            raise SettingsError.about(
                "{samples} {value} is below 3: use at least 3 azimuths", value=self.samples
            )
        if self.samples > 3600:
            raise SettingsError.about(
                "{samples} {value} is above 3600: use fewer azimuths", value=self.samples
            )
        if self.altitude_m is not None and not math.isfinite(self.altitude_m):
            raise SettingsError.about(
                "{altitude_m} {value} is not a number of metres", value=self.altitude_m
            )
        if not (math.isfinite(self.clearance_m) and self.clearance_m > 0.0):
            raise SettingsError.about(
                "{clearance_m} {value} must be a positive number of metres",
                value=self.clearance_m,
            )
        if not (math.isfinite(self.min_clearance_m) and self.min_clearance_m >= 0.0):
            raise SettingsError.about(
                "{min_clearance_m} {value} must be zero or more metres",
                value=self.min_clearance_m,
            )
        if not (math.isfinite(self.max_agl_m) and self.max_agl_m > 0.0):
            raise SettingsError.about(
                "{max_agl_m} {value} must be a positive number of metres", value=self.max_agl_m
            )
        if self.endurance_min is not None and not (
            math.isfinite(self.endurance_min) and self.endurance_min > 0.0
        ):
            raise SettingsError.about(
                "{endurance_min} {value} must be a positive number of minutes",
                value=self.endurance_min,
            )
        if self.solver not in SOLVER_CHOICES:
            raise SettingsError.about(
                "{solver} {value!r} is not known: use one of {known}",
                value=self.solver,
                known=", ".join(SOLVER_CHOICES),
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
                    hint = ": did you swap lat and lon? Give {home} LAT,LON: {home} {lon},{lat}"
                raise SettingsError.about(
                    "{home} {lat},{lon} is not a valid LAT,LON in degrees" + hint, lat=lat, lon=lon
                )
        if self.bound_time_s is not None and not (
            math.isfinite(self.bound_time_s) and 0.0 < self.bound_time_s <= 3600.0
        ):
            raise SettingsError.about(
                "{bound_time_s} {value} is out of range: give a number of seconds above 0, up "
                "to 3600",
                value=self.bound_time_s,
            )
        if self.agl_band_m is not None:
            FlightBand(*self.agl_band_m)
            if self.altitude_m is not None:
                raise SettingsError.about(
                    "{agl_band_m} follows the terrain and {altitude_m} flies one plane: give one"
                )
            if self.solver == "approx":
                raise SettingsError.about(
                    "{solver} approx places its own stops on a plane: inside the band "
                    "({agl_band_m}) use {solver} auto, exact, heuristic or ortools"
                )
        if self.band is not None and self.band < 1:
            raise SettingsError.about(
                "{band} {value} is below 1: bands are numbered from 1", value=self.band
            )

    def camera_at(self, altitude_m: float) -> Camera:
        """The camera these settings describe, on a plane at ``altitude_m``."""
        if self.frame is None:
            return Camera(altitude_m, self.fov_deg, gsd_cm=self.gsd_cm)
        return Camera.framed(altitude_m, self.frame, self.gsd_cm, self.headings)


SeparationMode = Literal["altitude", "time"]
SEPARATION_MODES: tuple[SeparationMode, ...] = ("altitude", "time")


@dataclass(frozen=True, slots=True)
class VehicleSpec:
    """What differs for one vehicle; None: the plan's own value."""

    home: tuple[float, float] | None = None
    speed_m_s: float | None = None
    endurance_min: float | None = None
    altitude_m: float | None = None


@dataclass(frozen=True, slots=True)
class FleetSettings:
    """The fleet and how its vehicles are kept apart.

    ``source`` says where the vehicles came from, for messages (the command line gives its
    flag and value: ``--fleet fleet.toml``).
    """

    vehicles: tuple[VehicleSpec, ...]
    separation: SeparationMode = DEFAULTS["separation"]
    layer_spacing_m: float = DEFAULTS["layer_spacing_m"]
    min_separation_m: float = DEFAULTS["min_separation_m"]
    source: str = "the fleet"

    def __post_init__(self) -> None:
        if not self.vehicles:
            raise SettingsError(f"{self.source} has no vehicle: give at least one")
        if len(self.vehicles) > FLEET_MAX_VEHICLES:
            raise SettingsError(too_many_vehicles(self.source, len(self.vehicles)))
        if self.separation not in SEPARATION_MODES:
            raise SettingsError.about(
                "{separation} {value!r} is not known: use altitude or time", value=self.separation
            )
        if not (math.isfinite(self.layer_spacing_m) and self.layer_spacing_m > 0.0):
            raise SettingsError.about(
                "{layer_spacing_m} {value} must be a positive number of metres",
                value=self.layer_spacing_m,
            )
        if not (math.isfinite(self.min_separation_m) and self.min_separation_m > 0.0):
            raise SettingsError.about(
                "{min_separation_m} {value} must be a positive number of metres",
                value=self.min_separation_m,
            )

    @property
    def min_m(self) -> float:
        """The separation required: vertical spacing, or horizontal distance in time mode."""
        return self.layer_spacing_m if self.separation == "altitude" else self.min_separation_m


# Settings of how the work runs rather than of the plan: a later plan runs on its own
# computer, with its own threads.
_NOT_RECORDED = ("workers",)


def settings_record(settings: PlanSettings) -> dict[str, Any]:
    """``settings`` as JSON-ready values, field by field (``summary.json``'s ``settings``),
    but for how the work ran (the threads)."""
    record = dataclasses.asdict(settings)
    for name in _NOT_RECORDED:
        del record[name]
    return record


def settings_from_record(record: Mapping[str, Any], source: str) -> PlanSettings:
    """The settings :func:`settings_record` wrote, read back.

    Raises
    ------
    SettingsError
        One line naming ``source`` when the record is not one this version wrote.
    """
    fix = "plan it again with this version of urpt-gcs"
    if not isinstance(record, Mapping):
        raise SettingsError(f"{source} records no settings: {fix}")
    known = {f.name for f in dataclasses.fields(PlanSettings)}
    unknown = sorted(set(record) - known)
    if unknown:
        raise SettingsError(
            f"{source} records settings this version does not know ({unknown[0]}): {fix}"
        )
    values = dict(record)
    try:
        values["solve"] = SolveSettings(**record.get("solve", {}))
        values["mission"] = MissionSettings(**record.get("mission", {}))
        if record.get("frame") is not None:
            values["frame"] = Frame(**record["frame"])
        for name in ("agl_band_m", "home"):
            if record.get(name) is not None:
                values[name] = tuple(record[name])
        return PlanSettings(**values)
    except (TypeError, ValueError) as exc:
        raise SettingsError(
            f"{source} records settings that cannot be used ({exc}): {fix}"
        ) from None


def plan_settings(values: Mapping[str, Any]) -> PlanSettings:
    """The settings of these option values, as ``urpt-gcs plan`` and a jobs file give them.

    Parameters
    ----------
    values
        Option key (``min-clearance``, see :data:`urpt_gcs.pipeline.options.PLAN_OPTIONS`)
        -> value; an option missing or None takes its default. ``camera``, ``sensor``,
        ``focal`` and ``image`` describe a frame camera; ``no-map`` is not a setting of the
        plan and is left to the caller.

    Returns
    -------
    PlanSettings
        Checked.

    Raises
    ------
    SettingsError
        A value out of range, or a cone and a frame camera both given.
    """
    given = {o.key: values[o.key] for o in PLAN_OPTIONS if values.get(o.key) is not None}
    for o in PLAN_OPTIONS:
        if o.kind == "number" and o.key in given:
            given[o.key] = float(given[o.key])
    frame = frame_from_flags(*(given.get(key) for key in ("camera", "sensor", "focal", "image")))
    if frame is not None and "fov" in given:
        raise SettingsError.about(
            "{fov_deg} is the cone camera's half-angle and {camera}/{sensor} a frame camera: "
            "give one"
        )
    if "home" in given:
        given["home"] = parse_latlon(given["home"], "home")
    if "agl" in given:
        given["agl"] = parse_band(given["agl"])
    top: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {"solve": {}, "mission": {}}
    for o in PLAN_OPTIONS:
        if not o.setting or o.key not in given:
            continue
        value = (not given[o.key]) if o.invert else given[o.key]
        for path in (o.setting, *o.also):
            group, _, name = path.rpartition(".")
            (nested[group] if group else top)[name] = value
    return PlanSettings(
        **top,
        frame=frame,
        solve=SolveSettings(**nested["solve"]),
        mission=MissionSettings(**nested["mission"]),
    )


def too_many_vehicles(source: str, count: int) -> str:
    """The message refusing a fleet of ``count`` vehicles, over :data:`FLEET_MAX_VEHICLES`."""
    return (
        f"{source}: {count} vehicles, over the {FLEET_MAX_VEHICLES} a fleet may have: "
        "plan fewer at a time"
    )


def read_fleet(path: Path | str) -> tuple[VehicleSpec, ...]:
    """The vehicles of a fleet file: one ``[[vehicle]]`` table each, with any of
    ``home_lat``/``home_lon`` (together), ``speed_m_s``, ``endurance_min``, ``altitude_m``.

    Raises
    ------
    SettingsError
        One line naming the file (as the setting ``fleet_file``), the vehicle, the key and
        the fix.
    """
    path = Path(path)
    text = read_settings_text(path, "fleet file", "--fleet", SettingsError)
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError.about(
            "{fleet_file} {path}: not valid TOML ({why}): fix the syntax", path=path, why=exc
        ) from None
    extra = sorted(set(document) - {"vehicle"})
    if extra:
        raise SettingsError.about(
            "{fleet_file} {path}: unknown table or key '{key}': the file holds only "
            "[[vehicle]] tables",
            path=path,
            key=extra[0],
        )
    tables = document.get("vehicle")
    if not isinstance(tables, list) or not tables:
        raise SettingsError.about(
            "{fleet_file} {path}: no [[vehicle]] table: add one per vehicle (an empty one "
            "takes the plan's defaults)",
            path=path,
        )
    return tuple(_vehicle(path, number, raw) for number, raw in enumerate(tables, start=1))


_UNITS = {k.key: k.unit for k in VEHICLE_KEYS}


def _vehicle(path: Path, number: int, raw: object) -> VehicleSpec:
    where = "{fleet_file} {path}: [[vehicle]] {number}"
    at = {"path": path, "number": number}
    if not isinstance(raw, dict):
        raise SettingsError.about(
            where + " is not a table: write it as [[vehicle]] with keys", **at
        )
    values: dict[str, float] = {}
    for key, value in raw.items():
        if key not in _UNITS:
            raise SettingsError.about(
                where + ": unknown key '{key}': use {known}", key=key, known=", ".join(_UNITS), **at
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SettingsError.about(
                where + ": {key} = {value!r} is not a number: give it in {unit}",
                key=key,
                value=value,
                unit=_UNITS[key],
                **at,
            )
        if not math.isfinite(value):
            raise SettingsError.about(
                where + ": {key} = {value} is not a finite number", key=key, value=value, **at
            )
        values[key] = float(value)
    if ("home_lat" in values) != ("home_lon" in values):
        missing = "home_lon" if "home_lat" in values else "home_lat"
        raise SettingsError.about(
            where + ": home_lat and home_lon go together: add {missing}", missing=missing, **at
        )
    home = None
    if "home_lat" in values:
        lat, lon = values["home_lat"], values["home_lon"]
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise SettingsError.about(
                where + ": home_lat = {lat:g}, home_lon = {lon:g} is not a position in degrees: "
                "latitude -90..90, longitude -180..180",
                lat=lat,
                lon=lon,
                **at,
            )
        home = (lat, lon)
    for spec in VEHICLE_KEYS:
        if spec.low is None or spec.high is None or spec.key not in values:
            continue
        if not spec.low <= values[spec.key] <= spec.high:
            raise SettingsError.about(
                where + ": {key} = {value:g} is out of range: use {low:g} to {high:g} {unit}",
                key=spec.key,
                value=values[spec.key],
                low=spec.low,
                high=spec.high,
                unit=spec.unit,
                **at,
            )
    return VehicleSpec(
        home=home,
        speed_m_s=values.get("speed_m_s"),
        endurance_min=values.get("endurance_min"),
        altitude_m=values.get("altitude_m"),
    )
