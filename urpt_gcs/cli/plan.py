"""``urpt-gcs plan`` and ``urpt-gcs demo-site``."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import click

from urpt_gcs.cli._root import fail, main, parse_home, upload_and_report
from urpt_gcs.errors import SettingsError, UrptError
from urpt_gcs.flight.mission import FIRMWARES, MissionSettings
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.progress import StageProgress
from urpt_gcs.site.camera import CAMERAS, frame_from_flags
from urpt_gcs.solvers import SOLVER_CHOICES, SolveSettings
from urpt_gcs.vehicle.protocol import DEFAULT_URL
from urpt_gcs.visibility.regions import DEFAULT_HEADINGS

if TYPE_CHECKING:
    from urpt_gcs.pipeline.settings import FleetSettings


@main.command("plan")
@click.option("--dem", "dem", required=True, help="DSM/DEM GeoTIFF of the site (e.g. from Pix4D).")
@click.option(
    "--targets", "targets", required=True, help="Targets: KML/KMZ, GeoJSON or CSV (name,lat,lon)."
)
@click.option(
    "--band",
    type=click.IntRange(min=1),
    default=None,
    help="Band of the DEM holding the elevations; needed when it has several.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    help="Threads for the line-of-sight tests [default: every core].",
)
@click.option("--out", "out", default="out", show_default=True, help="Folder for the outputs.")
@click.option(
    "--fov",
    "fov",
    type=float,
    default=None,
    help="Camera half-angle from nadir, degrees: a cone camera [default: 30].",
)
@click.option(
    "--camera",
    "camera",
    default=None,
    help="A frame camera by name: " + ", ".join(sorted(CAMERAS)) + ".",
)
@click.option("--sensor", default=None, help="Frame camera's sensor, WIDTHxHEIGHT mm.")
@click.option("--focal", type=float, default=None, help="Frame camera's focal length, mm.")
@click.option("--image", default=None, help="Frame camera's image, WIDTHxHEIGHT px.")
@click.option(
    "--headings",
    type=int,
    default=DEFAULT_HEADINGS,
    show_default=True,
    help="Headings over 0-180 deg each viewpoint is offered at (frame camera).",
)
@click.option(
    "--gsd",
    type=float,
    default=None,
    help="Ground resolution every photo must reach at its targets, cm/px (frame camera).",
)
@click.option(
    "--samples",
    type=int,
    default=36,
    show_default=True,
    help="Azimuths sampled per visibility region.",
)
@click.option(
    "--altitude",
    default=None,
    help="Flight-plane altitude in the DEM's vertical datum, metres; or auto: plan a range "
    "of altitudes in parallel and keep the shortest flight.",
)
@click.option(
    "--altitude-steps",
    type=int,
    default=6,
    show_default=True,
    help="With --altitude auto: how many altitudes to plan.",
)
@click.option(
    "--clearance",
    type=float,
    default=30.0,
    show_default=True,
    help="Without --altitude: metres above the highest terrain in the area.",
)
@click.option(
    "--min-clearance",
    type=float,
    default=10.0,
    show_default=True,
    help="Refuse a plan whose legs pass closer than this to the terrain, metres.",
)
@click.option(
    "--position-tolerance",
    type=float,
    default=1.5,
    show_default=True,
    help="How far from a waypoint the vehicle may take its photo, metres: every stop must see "
    "its targets from anywhere that close (0: from the waypoint only).",
)
@click.option(
    "--max-agl",
    type=float,
    default=120.0,
    show_default=True,
    help="Height above ground (under every stop, and above home) to warn about, metres.",
)
@click.option("--strict", is_flag=True, help="Refuse, rather than warn, over --max-agl.")
@click.option(
    "--endurance",
    type=float,
    default=20.0,
    show_default=True,
    help="Battery endurance, minutes; a longer tour is split into sorties.",
)
@click.option("--no-map", is_flag=True, help="Do not draw map.png.")
@click.option(
    "--home", "home", default=None, help="Take-off point LAT,LON (overrides a Home placemark)."
)
@click.option(
    "--hold", type=float, default=2.0, show_default=True, help="Hold at each viewpoint, s."
)
@click.option("--speed", type=float, default=5.0, show_default=True, help="Cruise speed, m/s.")
@click.option(
    "--firmware",
    type=str,
    default="ardupilot",
    show_default=True,
    help=f"Autopilot: {' or '.join(FIRMWARES)}.",
)
@click.option(
    "--solver",
    type=str,
    default="auto",
    show_default=True,
    help=f"One of {', '.join(SOLVER_CHOICES)}.",
)
@click.option(
    "--time-limit",
    type=float,
    default=5.0,
    show_default=True,
    help="Seconds the solve stage may take (compiling the solver on first use aside).",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for randomised solvers.")
@click.option(
    "--bound-time",
    type=float,
    default=None,
    help="Seconds for the certified lower bound of the shortest possible flight "
    "[default: half --time-limit, at most 5].",
)
@click.option(
    "--no-refine",
    is_flag=True,
    help="Fly the solver's viewpoints as they are, without moving the stops within what they see.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", is_flag=True, help="Print nothing but errors.")
@click.option(
    "--export-gtsp",
    "export_gtsp",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the planning instance as a GTSPLIB file (EUC_2D, centimetres).",
)
@click.option(
    "--vehicles",
    type=int,
    default=1,
    show_default=True,
    help="Vehicles flying at once; the targets are shared out for the earliest last landing.",
)
@click.option(
    "--fleet",
    "fleet_file",
    type=click.Path(dir_okay=True, path_type=Path),
    default=None,
    help="TOML file, one [[vehicle]] table per vehicle (home_lat, home_lon, speed_m_s, "
    "endurance_min, altitude_m; missing keys take the plan's values).",
)
@click.option(
    "--separation",
    type=str,
    default="altitude",
    show_default=True,
    help="Fleet: altitude (a layer per vehicle) or time (one layer, tracks checked).",
)
@click.option(
    "--layer-spacing",
    type=float,
    default=10.0,
    show_default=True,
    help="Fleet, --separation altitude: metres between the vehicles' layers.",
)
@click.option(
    "--min-separation",
    type=float,
    default=10.0,
    show_default=True,
    help="Fleet, --separation time: least horizontal distance between vehicles, metres.",
)
@click.option(
    "--upload", "do_upload", is_flag=True, help="Upload the mission and verify its read-back."
)
@click.option(
    "--connect",
    default=DEFAULT_URL,
    show_default=True,
    help="With --upload: MAVSDK connection string of the vehicle.",
)
@click.option(
    "--retries",
    type=int,
    default=3,
    show_default=True,
    help="With --upload: whole uploads tried again after a failure.",
)
def plan_command(
    dem: str,
    targets: str,
    band: int | None,
    workers: int | None,
    out: str,
    fov: float | None,
    camera: str | None,
    sensor: str | None,
    focal: float | None,
    image: str | None,
    headings: int,
    gsd: float | None,
    samples: int,
    altitude: str | None,
    altitude_steps: int,
    clearance: float,
    min_clearance: float,
    position_tolerance: float,
    max_agl: float,
    strict: bool,
    endurance: float,
    no_map: bool,
    home: str | None,
    hold: float,
    speed: float,
    firmware: str,
    solver: str,
    time_limit: float,
    seed: int,
    bound_time: float | None,
    no_refine: bool,
    as_json: bool,
    quiet: bool,
    export_gtsp: Path | None,
    vehicles: int,
    fleet_file: Path | None,
    separation: str,
    layer_spacing: float,
    min_separation: float,
    do_upload: bool,
    connect: str,
    retries: int,
) -> None:
    """Plan the shortest flight that photographs every target; write .plan, .waypoints, summary."""
    from urpt_gcs.files.products import check_extra, check_out, write_products
    from urpt_gcs.files.report import summary_text
    from urpt_gcs.pipeline.planner import plan

    try:
        fleet = _fleet(vehicles, fleet_file, separation, layer_spacing, min_separation)
        if fleet is not None:
            for flag, given in (
                ("--upload", do_upload),
                ("--export-gtsp", export_gtsp is not None),
                ("--altitude auto", altitude is not None and altitude.strip().lower() == "auto"),
            ):
                if given:
                    fix = (
                        "upload each vehicle with urpt-gcs upload --fleet"
                        if flag == "--upload"
                        else f"plan one vehicle for {flag}, or drop it"
                    )
                    raise SettingsError(f"{flag} is not available for a fleet plan: {fix}")
        # Everything about the outputs that can be known now is checked before the planning.
        destination = check_out(Path(out))
        export = None
        if export_gtsp is not None:
            export = check_extra(export_gtsp, "--export-gtsp", destination)
        auto = altitude is not None and altitude.strip().lower() == "auto"
        altitude_m = None
        if altitude is not None and not auto:
            try:
                altitude_m = float(altitude)
            except ValueError:
                raise SettingsError(
                    f"--altitude {altitude!r} is not a number of metres: give one, or auto"
                ) from None
        frame = frame_from_flags(camera, sensor, focal, image)
        if frame is not None and fov is not None:
            raise SettingsError(
                "--fov is the cone camera's half-angle and --camera/--sensor a frame camera: "
                "give one"
            )
        settings = PlanSettings(
            fov_deg=30.0 if fov is None else fov,
            frame=frame,
            gsd_cm=gsd,
            headings=headings,
            samples=samples,
            altitude_m=None if auto else altitude_m,
            clearance_m=clearance,
            min_clearance_m=min_clearance,
            position_tolerance_m=position_tolerance,
            max_agl_m=max_agl,
            strict=strict,
            endurance_min=endurance,
            home=parse_home(home),
            band=band,
            workers=workers,
            solver=solver,
            solve=SolveSettings(time_limit_s=time_limit, seed=seed),
            bound_time_s=bound_time,
            refine=not no_refine,
            mission=MissionSettings(
                firmware=firmware,  # type: ignore[arg-type]  # validated in __post_init__
                hold_s=hold,
                cruise_speed_m_s=speed,
                hover_speed_m_s=speed,
            ),
        )
        # A ticking line when stderr is a terminal; else a line per stage on stdout, before
        # the summary, so stderr holds nothing but the error. Nothing with --quiet or --json.
        live = sys.stderr.isatty()
        stream = sys.stderr if live else sys.stdout
        if fleet is not None:
            _plan_fleet(
                Path(dem), Path(targets), settings, fleet, Path(out), no_map, as_json, quiet, stream
            )
            return
        with StageProgress(stream, time_limit, live=live) as progress:
            say = None if quiet or as_json else progress
            if auto:
                from urpt_gcs.pipeline.altitude import best_altitude

                result = best_altitude(
                    Path(dem), Path(targets), settings, altitude_steps, progress=say
                )
            else:
                result = plan(Path(dem), Path(targets), settings, progress=say)
            if say is not None:
                say("writing outputs")
            also = []
            if export_gtsp is not None and export is not None:
                from urpt_gcs.files.formats.gtsplib import write_gtsplib

                comment = f"urpt-gcs plan of {Path(targets).name}"
                text = write_gtsplib(result.instance, export_gtsp.stem, comment)
                also.append((export, {export_gtsp.name: text}))
            data = write_products(result, destination, with_map=not no_map, also=also)
    except UrptError as exc:
        fail(exc)
        return
    if as_json:
        click.echo(json.dumps(data, indent=2))
    elif not quiet:
        click.echo(summary_text(data))
    if do_upload:
        if len(result.missions) > 1:
            click.echo(
                f"uploading sortie 1 of {len(result.missions)}; upload the others with "
                "urpt-gcs upload after each landing",
                err=True,
            )
        from urpt_gcs.flight.geofence import Geofence

        fence = Geofence.inclusion(result.geofence_latlon)
        upload_and_report(result.missions[0], connect, retries, 10.0, quiet or as_json, fence)


def _fleet(
    vehicles: int,
    fleet_file: Path | None,
    separation: str,
    layer_spacing: float,
    min_separation: float,
) -> FleetSettings | None:
    """The fleet the flags ask for; None for one vehicle without --fleet (the plain plan)."""
    from urpt_gcs.pipeline.settings import FleetSettings, VehicleSpec, read_fleet

    if vehicles < 1:
        raise SettingsError(f"--vehicles {vehicles} is below 1: give how many vehicles fly")
    if fleet_file is None:
        if vehicles == 1:
            return None
        specs = tuple(VehicleSpec() for _ in range(vehicles))
        source = f"--vehicles {vehicles}"
    else:
        specs = read_fleet(fleet_file)
        source = f"--fleet {fleet_file}"
        if vehicles not in (1, len(specs)):
            raise SettingsError(
                f"--vehicles {vehicles} disagrees with the {len(specs)} vehicles of --fleet "
                f"{fleet_file}: drop --vehicles or make them agree"
            )
    return FleetSettings(
        specs,
        separation=separation,  # type: ignore[arg-type]  # validated in __post_init__
        layer_spacing_m=layer_spacing,
        min_separation_m=min_separation,
        source=source,
    )


def _plan_fleet(
    dem: Path,
    targets: Path,
    settings: PlanSettings,
    fleet: FleetSettings,
    out: Path,
    no_map: bool,
    as_json: bool,
    quiet: bool,
    stream: TextIO,
) -> None:
    from urpt_gcs.files.fleet_output import (
        check_fleet_out,
        fleet_summary_text,
        write_fleet_products,
    )
    from urpt_gcs.pipeline.fleet import plan_fleet

    destinations = check_fleet_out(out, len(fleet.vehicles))
    live = sys.stderr.isatty()
    with StageProgress(stream, settings.solve.time_limit_s, live=live) as progress:
        say = None if quiet or as_json else progress
        result = plan_fleet(dem, targets, settings, fleet, progress=say)
        if say is not None:
            say("writing outputs")
        data = write_fleet_products(result, destinations, with_map=not no_map)
    if as_json:
        click.echo(json.dumps(data, indent=2))
    elif not quiet:
        click.echo(fleet_summary_text(data))


@main.command("demo-site")
@click.option(
    "--out",
    "out",
    default="missions/demo",
    show_default=True,
    help="Folder for site.tif and targets.kml.",
)
@click.option("--seed", type=int, default=7, show_default=True)
def demo_site_command(out: str, seed: int) -> None:
    """Generate the demo site: a Pix4D-like DSM and a KML of targets."""
    from urpt_gcs.site.demo import make_demo_site

    try:
        site = make_demo_site(Path(out), seed=seed)
    except UrptError as exc:
        fail(exc)
        return
    click.echo(f"wrote {site.dsm_path} and {site.targets_path}")
