"""``urpt-gcs upload`` and ``urpt-gcs sitl``: the mission on a vehicle."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import click

from urpt_gcs.cli._root import main, terminal_progress, upload_and_report
from urpt_gcs.cli.options import NON_NEGATIVE, POSITIVE, Finite
from urpt_gcs.errors import SettingsError
from urpt_gcs.vehicle.protocol import DEFAULT_URL

if TYPE_CHECKING:
    from urpt_gcs.replay.fly import ReplaySettings

__all__ = ["sitl_group", "sitl_replay_command", "upload_command"]


@main.command("upload")
@click.argument("mission_file", metavar="PLAN", required=False, type=click.Path(path_type=Path))
@click.option(
    "--connect",
    "connects",
    multiple=True,
    help="MAVSDK connection string (udpin://, udpout://, tcpout://, serial://) "
    f"[default: {DEFAULT_URL}]; with --fleet, one per vehicle in vehicle order.",
)
@click.option(
    "--fleet",
    "fleet_dir",
    type=click.Path(path_type=Path),
    default=None,
    help="Upload every vehicle's mission of a fleet plan (the --out folder of plan --vehicles).",
)
@click.option(
    "--sysid",
    default=None,
    metavar="ID,ID,...",
    help="With --fleet: the vehicles' MAVLink system ids on the one --connect link.",
)
@click.option(
    "--sortie",
    type=int,
    default=None,
    help="With --fleet: the sortie to upload to a vehicle that has several [default: 1].",
)
@click.option(
    "--retries",
    type=int,
    default=3,
    show_default=True,
    help="Whole uploads tried again after a timeout, refusal or differing read-back.",
)
@click.option(
    "--timeout",
    type=POSITIVE,
    default=10.0,
    show_default=True,
    help="Seconds to wait for the autopilot's heartbeat.",
)
def upload_command(
    mission_file: Path | None,
    connects: tuple[str, ...],
    fleet_dir: Path | None,
    sysid: str | None,
    sortie: int | None,
    retries: int,
    timeout: float,
) -> None:
    """Upload a .plan (or .waypoints, as ArduPilot) and verify the vehicle reads it back.

    A .plan's geofence goes up after the mission, as a fence mission, and is read back too.
    With --fleet, each vehicle of a fleet plan gets its own mission, verified on its own.
    """
    from urpt_gcs.files.mission_file import read_fence, read_mission
    from urpt_gcs.files.plan_check import summary_warning

    if fleet_dir is not None:
        if mission_file is not None:
            raise SettingsError("give PLAN or --fleet OUT, not both")
        _upload_fleet(fleet_dir, connects, sysid, 1 if sortie is None else sortie, retries, timeout)
        return
    if mission_file is None:
        raise SettingsError("no mission given: urpt-gcs upload PLAN, or --fleet OUT")
    if sysid is not None:
        raise SettingsError("--sysid names the vehicles of a --fleet upload: add --fleet OUT")
    if sortie is not None:
        raise SettingsError(
            f"--sortie {sortie} picks a sortie of a --fleet upload: upload that sortie's own "
            "file (mission_N.plan), or add --fleet OUT"
        )
    if len(connects) > 1:
        raise SettingsError("several --connect are for --fleet: give one for a single mission")
    mission = read_mission(mission_file, flag="urpt-gcs upload")
    fence = read_fence(mission_file)
    warning = summary_warning(mission_file, mission)
    if warning is not None:
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    url = connects[0] if connects else DEFAULT_URL
    upload_and_report(mission, url, retries, timeout, quiet=False, fence=fence)


def _upload_fleet(
    folder: Path,
    connects: tuple[str, ...],
    sysid: str | None,
    sortie: int,
    retries: int,
    timeout: float,
) -> None:
    from urpt_gcs.files.fleet_folder import read_fleet
    from urpt_gcs.vehicle.fleet_upload import parse_system_ids, report_lines, upload_fleet
    from urpt_gcs.vehicle.link import UploadSettings

    fleet = read_fleet(folder)
    ids = parse_system_ids(sysid) if sysid is not None else None
    urls = connects or (DEFAULT_URL,)
    report = upload_fleet(
        fleet, urls, ids, UploadSettings(retries, timeout), terminal_progress(), sortie
    )
    for entry in report.vehicles:
        for warning in entry.report.warnings if entry.report is not None else ():
            click.echo(f"urpt-gcs: warning: {entry.vehicle.name}: {warning}", err=True)
    for line in report_lines(report, folder):
        click.echo(line)
    if not report.ok:
        names = ", ".join(v.vehicle.name for v in report.failed)
        them = "them" if len(report.failed) > 1 else "it"
        click.echo(
            f"urpt-gcs: error: {names} not verified: do not fly {them} until uploaded again",
            err=True,
        )
        sys.exit(1)


@main.group("sitl", invoke_without_command=True)
@click.option(
    "--listen",
    default="udpout://127.0.0.1:14550",
    show_default=True,
    help="The simulator's end: udpout://HOST:PORT, udpin://HOST:PORT or tcpin://HOST:PORT.",
)
@click.option("--home", default=None, metavar="LAT,LON,ALT", help="Home; ALT in m AMSL.")
@click.option("--speedup", type=float, default=1.0, show_default=True, help="Simulated s per s.")
@click.option("--loss", type=float, default=0.0, show_default=True, help="Packet loss each way.")
@click.option("--latency", type=float, default=0.0, show_default=True, help="Delay each way, ms.")
@click.option(
    "--drop-after",
    type=int,
    default=None,
    help="Go silent for a few seconds after receiving this many mission items (once).",
)
@click.option("--px4", is_flag=True, help="Identify as PX4: no home item at seq 0.")
@click.option(
    "--capacity", type=int, default=700, show_default=True, help="Most mission items held."
)
@click.option(
    "--boot",
    type=float,
    default=0.0,
    show_default=True,
    help="Seconds after start that uploads and arming are refused, as ArduPilot does.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the packet loss.")
@click.pass_context
def sitl_group(
    ctx: click.Context,
    listen: str,
    home: str | None,
    speedup: float,
    loss: float,
    latency: float,
    drop_after: int | None,
    px4: bool,
    capacity: int,
    boot: float,
    seed: int,
) -> None:
    """Run a simulated ArduCopter on a MAVLink connection until Ctrl-C.

    `urpt-gcs sitl replay` flies a mission on one and checks it against the terrain.
    """
    if ctx.invoked_subcommand is not None:
        return
    from urpt_gcs.sim import SitlServer, VehicleSettings, parse_home

    try:
        settings = VehicleSettings(
            speedup=speedup,
            loss=loss,
            latency_ms=latency,
            drop_after=drop_after,
            px4=px4,
            capacity=capacity,
            boot_s=boot,
            seed=seed,
        )
        if home is not None:
            settings = replace(settings, home=parse_home(home))
        server = SitlServer(settings, listen)
        where = settings.home
        click.echo(
            f"simulated {'PX4' if px4 else 'ArduCopter'} quadrotor on {listen}, home "
            f"{where.lat_deg:.7f},{where.lon_deg:.7f} at {where.amsl_m:g} m, speed-up "
            f"{speedup:g}x; Ctrl-C stops it",
            err=True,
        )
        server.serve()
    except KeyboardInterrupt:
        click.echo("simulator stopped", err=True)


@sitl_group.command("replay")
@click.option("--dem", "dem", required=True, type=click.Path(path_type=Path), help="DSM GeoTIFF.")
@click.option(
    "--targets", "targets", required=True, type=click.Path(path_type=Path), help="Target file."
)
@click.option(
    "--plan",
    "plan_files",
    multiple=True,
    type=click.Path(path_type=Path),
    help="Mission to fly: .plan or .waypoints, or a plan's --out folder (every sortie); "
    "repeat for several sorties.",
)
@click.option(
    "--fleet",
    "fleet_dir",
    type=click.Path(path_type=Path),
    default=None,
    help="Fly every vehicle of a fleet plan at once (the --out folder of plan --vehicles) and "
    "check their separation.",
)
@click.option(
    "--speedup", type=POSITIVE, default=50.0, show_default=True, help="Simulated s per s."
)
@click.option(
    "--fov",
    type=Finite(0.0, 90.0, min_open=True, max_open=True),
    default=None,
    help="Camera half-angle, degrees [default: as planned (the .plan, or summary.json beside a "
    ".waypoints), else 30].",
)
@click.option(
    "--min-clearance",
    type=NON_NEGATIVE,
    default=None,
    help="Least height above the terrain on cruise legs, m [default: as planned, else 10].",
)
@click.option(
    "--takeoff",
    type=click.Choice(["auto-options", "guided"]),
    default="auto-options",
    show_default=True,
    help="Take off in AUTO (AUTO_OPTIONS=2) or in GUIDED before AUTO.",
)
@click.option("--timeout", type=POSITIVE, default=None, help="Wall-clock limit for the flight, s.")
@click.option(
    "--connect",
    default=None,
    help="Fly on this vehicle (e.g. ArduPilot SITL, tcpout://127.0.0.1:5760) instead of the "
    "built-in simulator; give its --speedup.",
)
@click.option(
    "--ardupilot",
    "ardupilot",
    is_flag=False,
    flag_value="",
    default=None,
    metavar="PATH",
    help="Start ArduCopter SITL (the arducopter binary or its folder; alone: "
    "$URPT_ARDUPILOT) at the plan's home, fly on it, stop it.",
)
@click.option(
    "--px4",
    "px4",
    is_flag=False,
    flag_value="",
    default=None,
    metavar="PATH",
    help="Start PX4's SITL from PATH (the folder with run.sh; without PATH, $URPT_PX4) and "
    "fly the PX4 mission on it at --speedup.",
)
def sitl_replay_command(
    dem: Path,
    targets: Path,
    plan_files: tuple[Path, ...],
    fleet_dir: Path | None,
    speedup: float,
    fov: float | None,
    min_clearance: float | None,
    takeoff: str,
    timeout: float | None,
    connect: str | None,
    ardupilot: str | None,
    px4: str | None,
) -> None:
    """Fly a mission via MAVSDK on the simulated copter, ArduCopter SITL or PX4 SITL; check
    photos and clearance on the DEM.

    A plan of one sortie is checked on every target of --targets; each sortie of several on
    the targets it was planned to photograph, and all of them together on every target.
    """
    from urpt_gcs.files.mission_file import mission_files
    from urpt_gcs.replay.ardupilot import ENV_VAR, resolve_binary
    from urpt_gcs.replay.fly import ReplaySettings, replay, replay_set
    from urpt_gcs.replay.judge import report_text, set_report_text
    from urpt_gcs.replay.px4 import find_build

    progress = terminal_progress()
    binary = None
    if ardupilot is not None:
        binary = resolve_binary(ardupilot or os.environ.get(ENV_VAR))
    settings = ReplaySettings(
        px4=find_build(px4) if px4 is not None else None,
        speedup=speedup,
        fov_deg=fov,
        min_clearance_m=min_clearance,
        takeoff=takeoff,  # type: ignore[arg-type]  # click.Choice checked it
        timeout_s=timeout,
        connect=connect,
        ardupilot=binary,
    )
    if fleet_dir is not None:
        if plan_files:
            raise SettingsError("give --plan or --fleet, not both")
        _replay_fleet(dem, targets, fleet_dir, settings, progress)
        return
    if not plan_files:
        raise SettingsError("no mission given: --plan PLAN (or --fleet OUT for a fleet)")
    files = mission_files(plan_files)
    if len(files) == 1:
        report = replay(dem, targets, files[0], settings, progress)
        reports, text, ok = [report], report_text(report), report.ok
        problems = list(report.problems)
    else:
        together = replay_set(dem, targets, files, settings, progress)
        reports, text, ok = list(together.reports), set_report_text(together), together.ok
        problems = [*together.problems]
        problems += [f"{r.plan}: {p}" for r in together.reports for p in r.problems]
    for warning in (w for r in reports for w in r.expected.warnings):
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    click.echo(text)
    if not ok:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        click.echo(f"urpt-gcs: error: replay failed: {problems[0]}{more}", err=True)
        sys.exit(1)


def _replay_fleet(
    dem: Path,
    targets: Path,
    folder: Path,
    settings: ReplaySettings,
    progress: Callable[[str], None] | None,
) -> None:
    from urpt_gcs.files.fleet_folder import read_fleet
    from urpt_gcs.replay.fleet import fleet_report_text, replay_fleet

    report = replay_fleet(dem, targets, read_fleet(folder), settings, progress)
    for warning in (w for r in report.together.reports for w in r.expected.warnings):
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    click.echo(fleet_report_text(report))
    if not report.ok:
        problems = [*report.problems, *report.together.problems]
        problems += [f"{r.plan}: {p}" for r in report.together.reports for p in r.problems]
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        click.echo(f"urpt-gcs: error: fleet replay failed: {problems[0]}{more}", err=True)
        sys.exit(1)
