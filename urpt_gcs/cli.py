"""The ``urpt-gcs`` command line: a thin layer over the library.

Only :class:`urpt_gcs.errors.UrptError` is caught: its message goes to stderr on one line and
the exit status is 1. Usage errors (unknown flags, a word where a number belongs) exit 2.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import click

from urpt_gcs import __version__
from urpt_gcs.errors import SettingsError, UrptError
from urpt_gcs.link import DEFAULT_URL
from urpt_gcs.mission import FIRMWARES, Mission, MissionSettings
from urpt_gcs.planner import PlanSettings
from urpt_gcs.progress import StageProgress
from urpt_gcs.solvers import SOLVER_CHOICES, SolveSettings


def _fail(exc: UrptError) -> None:
    message = " ".join(str(exc).split())
    click.echo(f"urpt-gcs: error: {message}", err=True)
    sys.exit(1)


def _upload_and_report(
    mission: Mission, url: str, retries: int, timeout_s: float, quiet: bool
) -> None:
    """Upload with a verified read-back; one line on success, exit 1 on failure."""
    from urpt_gcs.link import upload

    progress = (lambda msg: click.echo(f"... {msg}", err=True)) if sys.stderr.isatty() else None
    try:
        report = upload(mission, url, retries=retries, timeout_s=timeout_s, progress=progress)
    except UrptError as exc:
        _fail(exc)
        return
    for warning in report.warnings:
        click.echo(f"urpt-gcs: warning: {warning}", err=True)
    if not quiet:
        tries = f"{report.attempts} attempts" if report.attempts > 1 else "1 attempt"
        click.echo(
            f"uploaded {report.items} items to {report.url} ({report.autopilot}); read back "
            f"identical in {report.elapsed_s:.2f} s ({tries})"
        )


def _parse_home(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        lat, lon = (float(p) for p in parts)
    except ValueError:
        raise SettingsError(
            f"--home {text!r} is not LAT,LON: give it as e.g. --home 47.3977,8.5456"
        ) from None
    return lat, lon


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="urpt-gcs")
def main() -> None:
    """Plan, check and upload drone missions that photograph every target on real terrain."""


@main.command("plan")
@click.option("--dem", "dem", required=True, help="DSM/DEM GeoTIFF of the site (e.g. from Pix4D).")
@click.option(
    "--targets", "targets", required=True, help="Targets: KML/KMZ, GeoJSON or CSV (name,lat,lon)."
)
@click.option("--out", "out", default="out", show_default=True, help="Folder for the outputs.")
@click.option(
    "--fov",
    "fov",
    type=float,
    default=30.0,
    show_default=True,
    help="Camera half-angle from nadir, degrees.",
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
    type=float,
    default=None,
    help="Flight-plane altitude in the DEM's vertical datum, metres.",
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
    help="Seconds the solver may search.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for randomised solvers.")
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
    out: str,
    fov: float,
    samples: int,
    altitude: float | None,
    clearance: float,
    min_clearance: float,
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
    as_json: bool,
    quiet: bool,
    export_gtsp: Path | None,
    do_upload: bool,
    connect: str,
    retries: int,
) -> None:
    """Plan the shortest flight that photographs every target; write .plan, .waypoints, summary."""
    from urpt_gcs.planner import plan
    from urpt_gcs.products import write_products
    from urpt_gcs.report import summary_text

    try:
        settings = PlanSettings(
            fov_deg=fov,
            samples=samples,
            altitude_m=altitude,
            clearance_m=clearance,
            min_clearance_m=min_clearance,
            max_agl_m=max_agl,
            strict=strict,
            endurance_min=endurance,
            home=_parse_home(home),
            solver=solver,
            solve=SolveSettings(time_limit_s=time_limit, seed=seed),
            mission=MissionSettings(
                firmware=firmware,  # type: ignore[arg-type]  # validated in __post_init__
                hold_s=hold,
                cruise_speed_m_s=speed,
                hover_speed_m_s=speed,
            ),
        )
        if sys.stderr.isatty() and not (quiet or as_json):
            with StageProgress(sys.stderr, time_limit) as progress:
                result = plan(Path(dem), Path(targets), settings, progress=progress)
        else:
            result = plan(Path(dem), Path(targets), settings)
        data = write_products(result, Path(out), with_map=not no_map)
        if export_gtsp is not None:
            from urpt_gcs.formats.gtsplib import export_gtsplib

            export_gtsplib(
                result.instance, export_gtsp, comment=f"urpt-gcs plan of {Path(targets).name}"
            )
    except UrptError as exc:
        _fail(exc)
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
        _upload_and_report(result.missions[0], connect, retries, 10.0, quiet or as_json)


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
    from urpt_gcs.demo import make_demo_site

    try:
        site = make_demo_site(Path(out), seed=seed)
    except UrptError as exc:
        _fail(exc)
        return
    click.echo(f"wrote {site.dsm_path} and {site.targets_path}")


@main.group("bench")
def bench_group() -> None:
    """Benchmarks: the solvers on published instance sets, beside published results."""


@bench_group.command("gtsplib")
@click.argument("directory", type=click.Path(path_type=Path))
@click.option(
    "--time-limit",
    type=float,
    default=None,
    help="Seconds per solve [default: 3x GLNS's published mean time, else 10].",
)
@click.option("--runs", type=int, default=1, show_default=True, help="Runs (seeds) per solver.")
@click.option("--only", default=None, metavar="NAME[,NAME]", help="Run only these instances.")
@click.option(
    "--out", "out", type=click.Path(path_type=Path), default=None, help="Folder for results.csv."
)
@click.option(
    "--solver",
    default=None,
    metavar="NAME[,NAME]",
    help="Solver(s) to compare [default: heuristic]; OR-Tools always runs as the baseline.",
)
def bench_gtsplib_command(
    directory: Path,
    time_limit: float | None,
    runs: int,
    only: str | None,
    out: Path | None,
    solver: str | None,
) -> None:
    """Solve GTSPLIB files in DIRECTORY; compare with best_known.csv and glns_default.csv."""
    from urpt_gcs.bench.gtsplib import format_table, run_gtsplib

    def names(text: str | None) -> list[str]:
        return [part.strip() for part in (text or "").split(",") if part.strip()]

    interactive = sys.stderr.isatty()
    try:
        rows = run_gtsplib(
            directory,
            solvers=names(solver),
            time_limit_s=time_limit,
            runs=runs,
            only=names(only) or None,
            out_dir=out,
            progress=(lambda msg: click.echo(f"... {msg}", err=True)) if interactive else None,
        )
    except UrptError as exc:
        _fail(exc)
        return
    click.echo(format_table(rows))


@bench_group.command("paper")
@click.option("--quick", is_flag=True, help="A small subset of the study (what CI runs).")
@click.option(
    "--out", "out", type=click.Path(path_type=Path), default=None, help="Folder for results.csv."
)
@click.option(
    "--heuristic-time",
    type=float,
    default=1.0,
    show_default=True,
    help="Seconds the heuristic gets per instance.",
)
def bench_paper_command(quick: bool, out: Path | None, heuristic_time: float) -> None:
    """Reproduce the paper's simulation study: 540 instances on random TIN terrains."""
    from urpt_gcs.bench.paper import format_tables, run_paper

    interactive = sys.stderr.isatty()
    try:
        rows = run_paper(
            quick=quick,
            out_dir=out,
            heuristic_s=heuristic_time,
            progress=(lambda msg: click.echo(f"... {msg}", err=True)) if interactive else None,
        )
    except UrptError as exc:
        _fail(exc)
        return
    click.echo(format_tables(rows))


@main.command("upload")
@click.argument("mission_file", metavar="PLAN", type=click.Path(path_type=Path))
@click.option(
    "--connect",
    default=DEFAULT_URL,
    show_default=True,
    help="MAVSDK connection string (udpin://, udpout://, tcpout://, serial://).",
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
    type=float,
    default=10.0,
    show_default=True,
    help="Seconds to wait for the autopilot's heartbeat.",
)
def upload_command(mission_file: Path, connect: str, retries: int, timeout: float) -> None:
    """Upload a .plan (or .waypoints, as ArduPilot) and verify the vehicle reads it back."""
    from urpt_gcs.sitl.replay import read_mission

    try:
        mission = read_mission(mission_file)
    except UrptError as exc:
        _fail(exc)
        return
    _upload_and_report(mission, connect, retries, timeout, quiet=False)


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
    from urpt_gcs.sitl import SitlServer, VehicleSettings, parse_home

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
    except UrptError as exc:
        _fail(exc)
    except KeyboardInterrupt:
        click.echo("simulator stopped", err=True)


@sitl_group.command("replay")
@click.option("--dem", "dem", required=True, type=click.Path(path_type=Path), help="DSM GeoTIFF.")
@click.option(
    "--targets", "targets", required=True, type=click.Path(path_type=Path), help="Target file."
)
@click.option(
    "--plan",
    "plan_file",
    required=True,
    type=click.Path(path_type=Path),
    help="Mission to fly: .plan or .waypoints.",
)
@click.option("--speedup", type=float, default=50.0, show_default=True, help="Simulated s per s.")
@click.option(
    "--fov", type=float, default=30.0, show_default=True, help="Camera half-angle, degrees."
)
@click.option(
    "--min-clearance",
    type=float,
    default=10.0,
    show_default=True,
    help="Least height above the terrain on cruise legs, m.",
)
@click.option(
    "--takeoff",
    type=click.Choice(["auto-options", "guided"]),
    default="auto-options",
    show_default=True,
    help="Take off in AUTO (AUTO_OPTIONS=2) or in GUIDED before AUTO.",
)
@click.option("--timeout", type=float, default=None, help="Wall-clock limit for the flight, s.")
@click.option(
    "--connect",
    default=None,
    help="Fly on this vehicle (e.g. ArduPilot SITL, tcpout://127.0.0.1:5760) instead of the "
    "built-in simulator; give its --speedup.",
)
def sitl_replay_command(
    dem: Path,
    targets: Path,
    plan_file: Path,
    speedup: float,
    fov: float,
    min_clearance: float,
    takeoff: str,
    timeout: float | None,
    connect: str | None,
) -> None:
    """Fly a mission on the simulated copter via MAVSDK; check photos and clearance on the DEM."""
    from urpt_gcs.sitl.judge import report_text
    from urpt_gcs.sitl.replay import ReplaySettings, replay

    progress = (lambda msg: click.echo(f"... {msg}", err=True)) if sys.stderr.isatty() else None
    try:
        settings = ReplaySettings(
            speedup=speedup,
            fov_deg=fov,
            min_clearance_m=min_clearance,
            takeoff=takeoff,  # type: ignore[arg-type]  # click.Choice checked it
            timeout_s=timeout,
            connect=connect,
        )
        report = replay(dem, targets, plan_file, settings, progress)
    except UrptError as exc:
        _fail(exc)
        return
    click.echo(report_text(report))
    if not report.ok:
        more = f" (and {len(report.problems) - 1} more)" if len(report.problems) > 1 else ""
        click.echo(f"urpt-gcs: error: replay failed: {report.problems[0]}{more}", err=True)
        sys.exit(1)
