"""Every setting of a plan and of a fleet, defined once: the table the rest derives from.

An :class:`Option` is one setting as an operator gives it: its key (``min-clearance``: the
flag without its dashes on the command line, the key in a batch jobs file), the library
setting it fills (``min_clearance_m``, the name :class:`urpt_gcs.pipeline.settings.PlanSettings`
and its errors use), its kind, default, unit and help text. From :data:`PLAN_OPTIONS` come the
``urpt-gcs plan`` options (:func:`urpt_gcs.cli.options.plan_options`), the keys a jobs file
takes (:mod:`urpt_gcs.batch.jobs`), the defaults of ``PlanSettings`` and the one mapping from
option values to settings (:func:`urpt_gcs.pipeline.settings.plan_settings`). A new setting
is a line here and a field of ``PlanSettings``.

This module imports no command-line library: the library reads it too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from urpt_gcs.flight.mission import FIRMWARES, MissionSettings
from urpt_gcs.site.camera import CAMERAS
from urpt_gcs.solvers import SOLVER_CHOICES, SolveSettings
from urpt_gcs.visibility.regions import DEFAULT_HEADINGS

__all__ = [
    "DEFAULTS",
    "FLAGS",
    "FLEET_OPTIONS",
    "KINDS",
    "PLAN_OPTIONS",
    "TOML_KEYS",
    "VEHICLE_KEYS",
    "Kind",
    "Option",
    "VehicleKey",
    "option",
]

# number: a float; integer: an int; count: an int from 1; flag: true when given; text: a
# string; choice: one of ``choices``; latlon: "LAT,LON" text; path: a file's path.
Kind = Literal["number", "integer", "count", "flag", "text", "choice", "latlon", "path"]
# What a jobs file is told each kind takes.
KINDS: dict[Kind, str] = {
    "number": "a number",
    "integer": "a whole number",
    "count": "a whole number",
    "flag": "true or false",
    "text": "a string",
    "choice": "a string",
    "latlon": "a string",
    "path": "a string",
}


@dataclass(frozen=True, slots=True)
class Option:
    """One setting as the command line and a jobs file take it.

    Attributes
    ----------
    key
        The flag without ``--`` and the jobs file's key: ``min-clearance``.
    setting
        What it fills: a field of ``PlanSettings`` (``min_clearance_m``), of its ``solve`` or
        ``mission`` (``solve.time_limit_s``), or ``""`` for one read beside the settings
        (``no-map``, a camera's description).
    kind
        The value it takes (see :data:`Kind`).
    default
        Its value when not given. With ``unset`` the command line passes None instead, so
        that what was given can be told from the default.
    help
        One sentence for ``--help``; ``{default}`` is replaced by the default.
    unit
        The unit of a number (``m``, ``s``, ``deg``), ``""`` for none.
    choices
        A choice's values.
    also
        Other settings the same value fills (``--speed`` sets cruise and hover speed).
    invert
        A flag that sets its setting to False (``no-refine``).
    unset
        See ``default``.
    show_default
        ``--help`` shows ``[default: ...]``.
    in_jobs
        A jobs file may set it (else the command line only).
    auto
        The command line also takes the word ``auto`` (``--altitude``: plan a range).
    """

    key: str
    setting: str
    kind: Kind
    default: Any
    help: str
    unit: str = ""
    choices: tuple[str, ...] = ()
    also: tuple[str, ...] = ()
    invert: bool = False
    unset: bool = False
    show_default: bool = True
    in_jobs: bool = True
    auto: bool = False

    @property
    def flag(self) -> str:
        """The command-line flag: ``--min-clearance``."""
        return f"--{self.key}"

    @property
    def name(self) -> str:
        """The library's name, as errors give it: ``min_clearance_m``."""
        return self.setting.rpartition(".")[2] or self.key


_SOLVE = SolveSettings()
_MISSION = MissionSettings()

PLAN_OPTIONS: tuple[Option, ...] = (
    Option(
        "band",
        "band",
        "count",
        None,
        "Band of the DEM holding the elevations; needed when it has several.",
    ),
    Option(
        "workers",
        "workers",
        "count",
        None,
        "Threads for the line-of-sight tests [default: every core].",
    ),
    Option(
        "fov",
        "fov_deg",
        "number",
        30.0,
        "Camera half-angle from nadir, degrees: a cone camera [default: {default:g}].",
        unit="deg",
        unset=True,
        show_default=False,
    ),
    Option(
        "camera",
        "",
        "text",
        None,
        "A frame camera by name: " + ", ".join(sorted(CAMERAS)) + ".",
    ),
    Option("sensor", "", "text", None, "Frame camera's sensor, WIDTHxHEIGHT mm.", unit="mm"),
    Option("focal", "", "number", None, "Frame camera's focal length, mm.", unit="mm"),
    Option("image", "", "text", None, "Frame camera's image, WIDTHxHEIGHT px.", unit="px"),
    Option(
        "headings",
        "headings",
        "integer",
        DEFAULT_HEADINGS,
        "Headings over 0-180 deg each viewpoint is offered at (frame camera).",
    ),
    Option(
        "gsd",
        "gsd_cm",
        "number",
        None,
        "Ground resolution every photo must reach at its targets, cm/px (frame camera).",
        unit="cm/px",
    ),
    Option("samples", "samples", "integer", 36, "Azimuths sampled per visibility region."),
    Option(
        "altitude",
        "altitude_m",
        "number",
        None,
        "Flight-plane altitude in the DEM's vertical datum, metres; or auto: plan a range "
        "of altitudes in parallel and keep the shortest flight.",
        unit="m",
        auto=True,
    ),
    Option(
        "agl",
        "agl_band_m",
        "text",
        None,
        "Follow the terrain: fly anywhere from FLOOR to CEILING metres above the surface "
        "below the vehicle, e.g. 30:120 (instead of one flight plane); each photo from its "
        "own height.",
        unit="m",
    ),
    Option(
        "clearance",
        "clearance_m",
        "number",
        30.0,
        "Without --altitude: metres above the highest terrain in the area.",
        unit="m",
    ),
    Option(
        "min-clearance",
        "min_clearance_m",
        "number",
        10.0,
        "Refuse a plan whose legs pass closer than this to the terrain, metres.",
        unit="m",
    ),
    Option(
        "position-tolerance",
        "position_tolerance_m",
        "number",
        1.5,
        "How far from a waypoint the vehicle may take its photo, metres: every stop keeps "
        "its targets in the picture from anywhere that close on the flight plane, and in sight "
        "from the waypoint and 9 points that far from it (0: from the waypoint only).",
        unit="m",
    ),
    Option(
        "max-agl",
        "max_agl_m",
        "number",
        120.0,
        "Height above ground (under every stop, and above home) to warn about, metres.",
        unit="m",
    ),
    Option("strict", "strict", "flag", False, "Refuse, rather than warn, over --max-agl."),
    Option(
        "endurance",
        "endurance_min",
        "number",
        20.0,
        "Battery endurance, minutes; a longer tour is split into sorties.",
        unit="min",
    ),
    Option("no-map", "", "flag", False, "Do not draw map.png and map.html."),
    Option(
        "home",
        "home",
        "latlon",
        None,
        "Take-off point LAT,LON (overrides a Home placemark).",
        unit="deg",
    ),
    Option(
        "hold",
        "mission.hold_s",
        "number",
        _MISSION.hold_s,
        "Hold at each viewpoint, s.",
        unit="s",
    ),
    Option(
        "speed",
        "mission.cruise_speed_m_s",
        "number",
        _MISSION.cruise_speed_m_s,
        "Cruise speed, m/s.",
        unit="m/s",
        also=("mission.hover_speed_m_s",),
    ),
    Option(
        "firmware",
        "mission.firmware",
        "choice",
        _MISSION.firmware,
        f"Autopilot: {' or '.join(FIRMWARES)}.",
        choices=FIRMWARES,
    ),
    Option(
        "solver",
        "solver",
        "choice",
        "auto",
        f"One of {', '.join(SOLVER_CHOICES)}.",
        choices=SOLVER_CHOICES,
    ),
    Option(
        "time-limit",
        "solve.time_limit_s",
        "number",
        _SOLVE.time_limit_s,
        "Seconds the solve stage may take (compiling the solver on first use aside).",
        unit="s",
    ),
    Option("seed", "solve.seed", "integer", _SOLVE.seed, "Seed for randomised solvers."),
    Option(
        "bound-time",
        "bound_time_s",
        "number",
        None,
        "Seconds for the certified lower bound of the shortest possible flight "
        "[default: half --time-limit, at most 5].",
        unit="s",
    ),
    Option(
        "no-refine",
        "refine",
        "flag",
        False,
        "Fly the solver's viewpoints as they are, without moving the stops within what they see.",
        invert=True,
    ),
)

# How vehicles share the sky: ``urpt-gcs plan`` only (a jobs file plans one vehicle).
FLEET_OPTIONS: tuple[Option, ...] = (
    Option(
        "vehicles",
        "vehicles",
        "integer",
        1,
        "Vehicles flying at once; the targets are shared out for the earliest last landing.",
        in_jobs=False,
    ),
    Option(
        "fleet",
        "fleet_file",
        "path",
        None,
        "TOML file, one [[vehicle]] table per vehicle (home_lat, home_lon, speed_m_s, "
        "endurance_min, altitude_m; missing keys take the plan's values).",
        in_jobs=False,
    ),
    Option(
        "separation",
        "separation",
        "choice",
        "altitude",
        "Fleet: altitude (a layer per vehicle) or time (one layer, tracks checked).",
        choices=("altitude", "time"),
        in_jobs=False,
    ),
    Option(
        "layer-spacing",
        "layer_spacing_m",
        "number",
        10.0,
        "Fleet, --separation altitude: metres between the vehicles' layers.",
        unit="m",
        in_jobs=False,
    ),
    Option(
        "min-separation",
        "min_separation_m",
        "number",
        10.0,
        "Fleet, --separation time: least horizontal distance between vehicles, metres.",
        unit="m",
        in_jobs=False,
    ),
)


def option(key: str) -> Option:
    """The option of this key (``min-clearance``), plan or fleet.

    Raises
    ------
    KeyError
        No option has this key.
    """
    for found in (*PLAN_OPTIONS, *FLEET_OPTIONS):
        if found.key == key:
            return found
    raise KeyError(key)


# The default of each setting an option fills (``fov_deg`` -> 30.0, ``solve.seed`` -> 0):
# PlanSettings and FleetSettings take theirs from here.
DEFAULTS: dict[str, Any] = {
    o.setting: (not o.default) if o.invert else o.default
    for o in (*PLAN_OPTIONS, *FLEET_OPTIONS)
    if o.setting
}

# What the command line calls each setting (``fov_deg`` -> ``--fov``), for its errors; and
# the arguments of library functions the command line takes beside the table
# (``best_altitude``'s steps).
FLAGS: dict[str, str] = {
    **{
        name: o.flag
        for o in (*PLAN_OPTIONS, *FLEET_OPTIONS)
        for name in (o.name, *(a.rpartition(".")[2] for a in o.also))
    },
    "altitude_steps": "--altitude-steps",
}
# What a jobs file calls each setting (``fov_deg`` -> ``fov``), for its errors.
TOML_KEYS: dict[str, str] = {
    name: o.key
    for o in PLAN_OPTIONS
    if o.in_jobs
    for name in (o.name, *(a.rpartition(".")[2] for a in o.also))
}


@dataclass(frozen=True, slots=True)
class VehicleKey:
    """One key of a fleet file's ``[[vehicle]]`` table: a number in ``unit``, within
    ``low`` to ``high`` when they are given."""

    key: str
    unit: str
    low: float | None = None
    high: float | None = None


# The keys of a fleet file's [[vehicle]] table (VehicleSpec's fields, the home in two).
VEHICLE_KEYS: tuple[VehicleKey, ...] = (
    VehicleKey("home_lat", "degrees"),
    VehicleKey("home_lon", "degrees"),
    VehicleKey("speed_m_s", "m/s", 0.1, 50.0),
    VehicleKey("endurance_min", "minutes", 1e-6, 1e6),
    VehicleKey("altitude_m", "metres"),
)
