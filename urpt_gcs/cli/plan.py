"""``urpt-gcs plan`` and ``urpt-gcs demo-site``."""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import click

from urpt_gcs.cli._root import main, upload_and_report
from urpt_gcs.cli.flown import log_option
from urpt_gcs.cli.options import out_option, setting_options
from urpt_gcs.errors import SettingsError
from urpt_gcs.pipeline.options import FLEET_OPTIONS, PLAN_OPTIONS, Option
from urpt_gcs.pipeline.settings import (
    FLEET_MAX_VEHICLES,
    FleetSettings,
    PlanSettings,
    VehicleSpec,
    plan_settings,
    read_fleet,
    too_many_vehicles,
)
from urpt_gcs.progress import StageProgress
from urpt_gcs.vehicle.protocol import DEFAULT_URL, check_url

if TYPE_CHECKING:
    from urpt_gcs.files.output import Destination

__all__ = ["demo_site_command", "plan_command"]


def _refuse_plan(o: Option, value: str) -> object:
    """The library's error for a choice of the plan it does not know."""
    return plan_settings({o.key: value})


def _refuse_fleet(o: Option, value: str) -> object:
    """The library's error for a choice of the fleet it does not know."""
    given: dict[str, Any] = {o.setting: value}
    return FleetSettings((VehicleSpec(),), **given)


@main.command("plan")
@click.option("--dem", "dem", help="DSM/DEM GeoTIFF of the site (e.g. from Pix4D).")
@click.option("--targets", "targets", help="Targets: KML/KMZ, GeoJSON or CSV (name,lat,lon).")
@setting_options(
    PLAN_OPTIONS,
    _refuse_plan,
    after={
        "workers": out_option("Folder for the outputs.", default="out", path=False),
        "altitude": click.option(
            "--altitude-steps",
            type=int,
            default=6,
            show_default=True,
            help="With --altitude auto: how many altitudes to plan.",
        ),
    },
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
@setting_options(FLEET_OPTIONS, _refuse_fleet)
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
@click.option(
    "--resume",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Plan only the targets of this earlier plan's folder that the --log flights did not "
    "photograph, with its own settings, home and DSM.",
)
@log_option("With --resume: a log of a flight of that plan (.tlog or DataFlash .bin).")
def plan_command(
    dem: str | None,
    targets: str | None,
    out: str,
    altitude_steps: int,
    as_json: bool,
    quiet: bool,
    export_gtsp: Path | None,
    do_upload: bool,
    connect: str,
    retries: int,
    resume: Path | None,
    logs: tuple[Path, ...],
    **options: Any,
) -> None:
    """Plan the shortest flight that photographs every target; write .plan, .waypoints, summary."""
    if resume is not None:
        if do_upload:
            raise SettingsError("--upload with --resume: upload the new plan with urpt-gcs upload")
        _plan_resumed(resume, logs, dem, targets, out, options, as_json, quiet)
        return
    if logs:
        raise SettingsError("--log belongs to --resume OUT: give the folder of the plan it flew")
    for flag, named in (("--dem", dem), ("--targets", targets)):
        if named is None:
            raise click.UsageError(f"Missing option '{flag}' (or give --resume OUT --log FLIGHT).")
    assert dem is not None and targets is not None
    from urpt_gcs.files.fleet_output import check_fleet_out
    from urpt_gcs.files.output import refuse_inputs
    from urpt_gcs.files.products import check_extra, check_out, write_products
    from urpt_gcs.files.report import summary_text
    from urpt_gcs.pipeline.planner import plan

    # The settings' options, by their keys (``min-clearance``).
    values = {o.key: options[o.key.replace("-", "_")] for o in (*PLAN_OPTIONS, *FLEET_OPTIONS)}
    altitude = values["altitude"]
    auto = altitude is not None and altitude.strip().lower() == "auto"
    fleet = _fleet(values)
    if fleet is not None:
        for flag, given in (
            ("--upload", do_upload),
            ("--export-gtsp", export_gtsp is not None),
            ("--altitude auto", auto),
        ):
            if given:
                fix = (
                    "upload each vehicle with urpt-gcs upload --fleet"
                    if flag == "--upload"
                    else f"plan one vehicle for {flag}, or drop it"
                )
                raise SettingsError(f"{flag} is not available for a fleet plan: {fix}")
    # Everything about the outputs that can be known now is checked before the planning.
    if do_upload:
        check_url(connect)
    # No output may replace an input: compared as files, whatever their names.
    inputs = {"--dem": dem, "--targets": targets}
    if values["fleet"] is not None:
        inputs["--fleet"] = values["fleet"]
    if fleet is not None:
        destinations = check_fleet_out(Path(out), len(fleet.vehicles))
    else:
        destinations = [check_out(Path(out))]
    export = None
    if export_gtsp is not None:
        export = check_extra(export_gtsp, "--export-gtsp", destinations[0])
    refuse_inputs(destinations if export is None else [*destinations, export], inputs)
    values["altitude"] = None
    if altitude is not None and not auto:
        try:
            values["altitude"] = float(altitude)
        except ValueError:
            raise SettingsError(
                f"--altitude {altitude!r} is not a number of metres: give one, or auto"
            ) from None
    settings = plan_settings(values)
    no_map = values["no-map"]
    # A ticking line when stderr is a terminal; else a line per stage on stdout, before
    # the summary, so stderr holds nothing but the error. Nothing with --quiet or --json.
    live = sys.stderr.isatty()
    stream = sys.stderr if live else sys.stdout
    if fleet is not None:
        _plan_fleet(
            Path(dem), Path(targets), settings, fleet, destinations, no_map, as_json, quiet, stream
        )
        return
    destination = destinations[0]
    with StageProgress(stream, settings.solve.time_limit_s, live=live) as progress:
        say = None if quiet or as_json else progress
        if auto:
            from urpt_gcs.pipeline.altitude import best_altitude

            result = best_altitude(Path(dem), Path(targets), settings, altitude_steps, progress=say)
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


def _plan_resumed(
    resume: Path,
    logs: tuple[Path, ...],
    dem: str | None,
    targets: str | None,
    out: str,
    options: Mapping[str, Any],
    as_json: bool,
    quiet: bool,
) -> None:
    """``plan --resume``: the targets of an earlier plan its flights missed, planned with its
    own settings and home, into ``out``."""
    from dataclasses import replace

    from urpt_gcs.files.output import refuse_inputs
    from urpt_gcs.files.products import check_out, write_products
    from urpt_gcs.files.report import summary_text
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.settings import settings_from_record
    from urpt_gcs.replay.flown import judge_flown, plan_dem, plan_summary, remaining_targets

    context = click.get_current_context()
    for o in (*PLAN_OPTIONS, *FLEET_OPTIONS):
        given = context.get_parameter_source(o.key.replace("-", "_"))
        if o.key != "no-map" and given == click.core.ParameterSource.COMMANDLINE:
            raise SettingsError(
                f"{o.flag} with --resume: the plan re-flies with {resume}'s own settings; drop "
                f"{o.flag}, or plan the targets afresh with --dem and --targets"
            )
    summary = plan_summary(resume)
    settings = settings_from_record(summary.get("settings") or {}, f"'{resume / 'summary.json'}'")
    home = summary["home"]
    settings = replace(settings, home=(home["lat_deg"], home["lon_deg"]))
    dem_path = plan_dem(summary, None if dem is None else Path(dem))
    destination = check_out(Path(out))
    inputs: dict[str, Path | str] = {f"--log {log}": log for log in logs}
    inputs["--dem"] = dem_path
    inputs["--resume"] = resume / "summary.json"
    if targets is not None:
        inputs["--targets"] = targets
    refuse_inputs([destination], inputs)
    flown = judge_flown(resume, logs, dem_path, None if targets is None else Path(targets))
    if not flown.missed:
        if not quiet:
            click.echo(
                f"every target of {resume} was photographed in the logs given: nothing to re-fly"
            )
        return
    live = sys.stderr.isatty()
    stream = sys.stderr if live else sys.stdout
    with StageProgress(stream, settings.solve.time_limit_s, live=live) as progress:
        say = None if quiet or as_json else progress
        if say is not None:
            say(f"re-planning the {len(flown.missed)} targets not photographed")
        result = plan(dem_path, remaining_targets(flown), settings, progress=say)
        data = write_products(result, destination, with_map=not options["no_map"])
    if as_json:
        click.echo(json.dumps(data, indent=2))
    elif not quiet:
        click.echo(summary_text(data))


def _fleet(values: Mapping[str, Any]) -> FleetSettings | None:
    """The fleet the options ask for; None for one vehicle without --fleet (the plain plan)."""
    vehicles, fleet_file = values["vehicles"], values["fleet"]
    if vehicles < 1:
        raise SettingsError(f"--vehicles {vehicles} is below 1: give how many vehicles fly")
    if vehicles > FLEET_MAX_VEHICLES:
        # Before a vehicle is built: a count of millions would fill the memory first.
        raise SettingsError(too_many_vehicles("--vehicles", vehicles))
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
        separation=values["separation"],
        layer_spacing_m=values["layer-spacing"],
        min_separation_m=values["min-separation"],
        source=source,
    )


def _plan_fleet(
    dem: Path,
    targets: Path,
    settings: PlanSettings,
    fleet: FleetSettings,
    destinations: list[Destination],
    no_map: bool,
    as_json: bool,
    quiet: bool,
    stream: TextIO,
) -> None:
    from urpt_gcs.files.fleet_output import fleet_summary_text, write_fleet_products
    from urpt_gcs.pipeline.fleet import plan_fleet

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
@out_option("Folder for site.tif and targets.kml.", default="missions/demo", path=False)
@click.option("--seed", type=int, default=7, show_default=True)
def demo_site_command(out: str, seed: int) -> None:
    """Generate the demo site: a Pix4D-like DSM and a KML of targets."""
    from urpt_gcs.site.demo import make_demo_site

    site = make_demo_site(Path(out), seed=seed)
    click.echo(f"wrote {site.dsm_path} and {site.targets_path}")
