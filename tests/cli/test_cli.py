"""The command line: bad input gives one clear line, exit 1 and no output files."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
import pyproj
import pytest
from click.testing import CliRunner
from conftest import STAGE_LINE, WriteDem

from urpt_gcs.cli import main

ORIGIN = (500_000.0, 5_200_000.0)
TO_GEO = pyproj.Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)


def _latlon(x: float, y: float) -> tuple[float, float]:
    lon, lat = TO_GEO.transform(x, y)
    return lat, lon


def _csv(path: Path, points: list[tuple[str, float, float]]) -> Path:
    path.write_text("name,lat,lon\n" + "".join(f"{n},{a:.9f},{b:.9f}\n" for n, a, b in points))
    return path


@pytest.fixture
def site(tmp_path: Path, write_dem: WriteDem) -> dict[str, Path]:
    """A 100 m x 100 m flat field at 300 m with a nodata strip along the west edge."""
    z = np.full((200, 200), 300.0)
    z[:, :20] = -10000.0
    dem = write_dem(z, res=0.5, origin=ORIGIN)
    inside = [
        ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
        ("B", *_latlon(ORIGIN[0] + 70, ORIGIN[1] - 60)),
        ("Home", *_latlon(ORIGIN[0] + 50, ORIGIN[1] - 90)),
    ]
    return {"dem": dem, "targets": _csv(tmp_path / "t.csv", inside), "tmp": tmp_path}


def _run(args: list[str]):
    return CliRunner().invoke(main, args)


def _assert_clean_failure(result, out: Path, *words: str) -> None:
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists(), "a failed run left output behind"


def test_good_run_writes_every_output(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
            "--json",
        ]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["targets"] == 2
    assert data["home"]["source"] == "placemark 'Home'"
    assert sorted(p.name for p in out.iterdir()) == [
        "map.html",
        "map.png",
        "mission.plan",
        "mission.waypoints",
        "plan.geojson",
        "plan.kml",
        "summary.json",
    ]
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_home_flag_overrides_and_missing_home_is_reported(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    lat, lon = _latlon(ORIGIN[0] + 60, ORIGIN[1] - 20)
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
            "--json",
            "--home",
            f"{lat},{lon}",
        ]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["home"]["source"] == "--home"
    assert data["home"]["lat_deg"] == pytest.approx(lat, abs=1e-7)
    no_home = _csv(
        site["tmp"] / "nohome.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("B", *_latlon(ORIGIN[0] + 70, ORIGIN[1] - 60)),
        ],
    )
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(no_home),
            "--out",
            str(site["tmp"] / "out2"),
            "--time-limit",
            "0.5",
        ]
    )
    assert result.exit_code == 0, result.output
    assert "centroid of the targets" in result.stdout


def test_missing_dem(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    result = _run(
        ["plan", "--dem", "nowhere.tif", "--targets", str(site["targets"]), "--out", str(out)]
    )
    _assert_clean_failure(result, out, "nowhere.tif", "--dem")


def test_dem_that_is_not_a_raster(site: dict[str, Path]) -> None:
    bogus = site["tmp"] / "notes.tif"
    bogus.write_text("these are not elevations\n")
    out = site["tmp"] / "out"
    result = _run(
        ["plan", "--dem", str(bogus), "--targets", str(site["targets"]), "--out", str(out)]
    )
    _assert_clean_failure(result, out, "notes.tif", "not a readable raster")


def test_dem_without_crs(site: dict[str, Path], write_dem: WriteDem) -> None:
    dem = write_dem(np.full((50, 50), 10.0), name="nocrs.tif", crs=None)
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(dem), "--targets", str(site["targets"]), "--out", str(out)])
    _assert_clean_failure(result, out, "nocrs.tif", "coordinate reference system")


def test_all_nodata_dem(site: dict[str, Path], write_dem: WriteDem) -> None:
    dem = write_dem(np.full((200, 200), -9999.0), name="empty.tif", nodata=-9999.0, origin=ORIGIN)
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(dem), "--targets", str(site["targets"]), "--out", str(out)])
    _assert_clean_failure(result, out, "empty.tif", "no elevation")


def test_target_outside_the_dem(site: dict[str, Path]) -> None:
    far = _csv(
        site["tmp"] / "far.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("Far", *_latlon(ORIGIN[0] + 900, ORIGIN[1] - 40)),
        ],
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(far), "--out", str(out)])
    _assert_clean_failure(result, out, "Far", "outside DEM")


def test_target_on_nodata(site: dict[str, Path]) -> None:
    hole = _csv(
        site["tmp"] / "hole.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("Hole", *_latlon(ORIGIN[0] + 3, ORIGIN[1] - 40)),
        ],
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(hole), "--out", str(out)])
    _assert_clean_failure(result, out, "Hole", "nodata")


def test_target_file_without_points(site: dict[str, Path]) -> None:
    kml = site["tmp"] / "lines.kml"
    kml.write_text(
        '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2"><Document>'
        "<Placemark><name>road</name><LineString><coordinates>8,47 8.1,47.1</coordinates>"
        "</LineString></Placemark></Document></kml>"
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(kml), "--out", str(out)])
    _assert_clean_failure(result, out, "lines.kml", "no Point")


def test_malformed_kml(site: dict[str, Path]) -> None:
    kml = site["tmp"] / "broken.kml"
    kml.write_text('<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark>')
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(kml), "--out", str(out)])
    _assert_clean_failure(result, out, "broken.kml", "XML")


def test_altitude_at_or_below_terrain(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    for altitude in ("300", "250"):
        result = _run(
            [
                "plan",
                "--dem",
                str(site["dem"]),
                "--targets",
                str(site["targets"]),
                "--out",
                str(out),
                "--altitude",
                altitude,
            ]
        )
        _assert_clean_failure(result, out, "--altitude", "terrain")


@pytest.mark.parametrize("fov", ["0", "90", "-5", "120", "nan"])
def test_fov_outside_range(site: dict[str, Path], fov: str) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--fov",
            fov,
        ]
    )
    _assert_clean_failure(result, out, "--fov", "(0, 90)")


@pytest.mark.parametrize("samples", ["2", "0", "-4"])
def test_too_few_samples(site: dict[str, Path], samples: str) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--samples",
            samples,
        ]
    )
    _assert_clean_failure(result, out, "--samples", "at least 3")


def test_unwritable_output_leaves_nothing(site: dict[str, Path]) -> None:
    blocker = site["tmp"] / "file"
    blocker.write_text("x")
    out = blocker / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
        ]
    )
    _assert_clean_failure(result, out, "--out")


def test_stage_progress_ticks_only_for_slow_stages() -> None:
    from urpt_gcs.progress import StageProgress

    stream = io.StringIO()
    with StageProgress(stream, time_limit_s=2.0, live=True) as progress:
        progress("reading targets")  # fast: nothing shown
        progress("solving (10 viewpoints)")
        time.sleep(1.4)
    text = stream.getvalue()
    assert "reading targets" not in text
    assert "solving (10 viewpoints)" in text and "of 2 s" in text


class _TimedStream(io.StringIO):
    """A stream that notes when each write came."""

    def __init__(self) -> None:
        super().__init__()
        self.times: list[float] = []

    def write(self, text: str) -> int:
        self.times.append(time.monotonic())
        return super().write(text)


def _ticks_every_second(stream: _TimedStream, started: float, ended: float) -> None:
    """Once the quiet first second is over, every further whole second saw a redraw."""
    for k in range(1, int(ended - started)):
        window = (started + k, started + k + 1)
        assert any(window[0] <= t < window[1] for t in stream.times), (k, stream.times)


def test_the_display_ticks_every_second_through_a_long_stage() -> None:
    from urpt_gcs.progress import StageProgress

    stream = _TimedStream()
    with StageProgress(stream, time_limit_s=3.0, live=True) as progress:
        progress("solving (10 viewpoints)")
        started = time.monotonic()
        time.sleep(3.5)  # a slow stage
        ended = time.monotonic()
    _ticks_every_second(stream, started, ended)
    assert "of 3 s" in stream.getvalue()


def test_the_display_ticks_while_ortools_holds_the_interpreter() -> None:
    from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix
    from urpt_gcs.progress import StageProgress
    from urpt_gcs.solvers import SolveSettings, solve

    rng = np.random.default_rng(0)
    points = rng.uniform(0, 1000, (300, 2))
    covers = np.zeros((300, 30), dtype=bool)
    covers[np.arange(300), np.arange(300) % 30] = True
    home = np.hypot(*(points - 500.0).T)
    # With a depot, one search for the whole time limit.
    instance = Instance(
        covers=Covers.from_dense(covers),
        distance=euclidean_matrix(points),
        depot_distance=np.vstack([home, home]),
        points_xy=points,
    )
    stream = _TimedStream()
    with StageProgress(stream, time_limit_s=3.0, live=True) as progress:
        progress("solving (300 viewpoints)")
        started = time.monotonic()
        solve(instance, "ortools", SolveSettings(time_limit_s=3.0))
        ended = time.monotonic()
    _ticks_every_second(stream, started, ended)


def test_the_display_ticks_while_the_exact_dp_runs() -> None:
    from support.instances import random_instance

    from urpt_gcs.progress import StageProgress
    from urpt_gcs.solvers.exact import search_exact, warm_up

    warm_up()
    instance = random_instance(1, n=200, m=16, depot=True, overlap=0.0)
    stream = _TimedStream()
    with StageProgress(stream, time_limit_s=3.0, live=True) as progress:
        progress("solving (200 viewpoints)")
        started = time.monotonic()
        # Seeded with the worst tour, so that nothing is pruned and the DP runs to the limit.
        search_exact(instance, list(range(200)), deadline=time.perf_counter() + 3.0)
        ended = time.monotonic()
    _ticks_every_second(stream, started, ended)


def test_without_a_terminal_each_stage_prints_one_line_with_its_time(
    site: dict[str, Path],
) -> None:
    args = ["plan", "--dem", str(site["dem"]), "--targets", str(site["targets"])]
    result = _run([*args, "--out", str(site["tmp"] / "out"), "--time-limit", "0.5"])
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    lines = [line for line in result.stdout.splitlines() if line.startswith("... ")]
    assert lines and all(STAGE_LINE.fullmatch(line) for line in lines), result.stdout
    # The stage lines come first, then the summary.
    assert result.stdout.startswith(lines[0])
    stages = [line[4 : line.rindex(":")] for line in lines]
    assert stages[:4] == [
        "reading targets",
        "reading terrain",
        "visibility of 2 targets",
        "checking viewpoints",
    ]
    assert stages[4].startswith("preparing the ") and stages[5].startswith("solving (")
    assert stages[6:] == [
        "stops keeping their targets in the picture within 1.5 m",
        "moving the stops within what they see",
        "ordering the stops for sorties (up to 0.1 s)",
        "checking the missions",
        "preparing the bound (compiled on first use)",
        "bounding the shortest possible flight (up to 0.2 s)",
        "reading a tour off the bound",
        "writing outputs",
    ]
    for quiet in ("--quiet", "--json"):
        again = _run([*args, "--out", str(site["tmp"] / quiet), "--time-limit", "0.5", quiet])
        assert again.exit_code == 0 and again.stderr == "", again.stderr


# --- what escapes a command: one line all the same ------------------------------------------


def _root_with(exc: BaseException):
    import click

    from urpt_gcs.cli._root import RootGroup

    @click.group(cls=RootGroup)
    def root() -> None:
        pass

    @root.command()
    def boom() -> None:
        raise exc

    return CliRunner().invoke(root, ["boom"])


@pytest.mark.parametrize(
    ("exc", "expected"),
    [
        (
            OSError(36, "File name too long", "out/" + "x" * 300),
            "urpt-gcs: error: 'out/xxxxxx",
        ),
        (OSError(28, "No space left on device"), "urpt-gcs: error: No space left on device: free"),
        (
            OSError(13, "Permission denied", "out", None, "out.tmp"),
            "urpt-gcs: error: 'out' -> 'out.tmp'",
        ),
        (
            MemoryError("Unable to allocate 40.1 GiB for an array with shape (5, 2) and type f8"),
            "urpt-gcs: error: out of memory (Unable to allocate 40.1 GiB for an array",
        ),
    ],
)
def test_os_and_memory_errors_are_one_line(exc: BaseException, expected: str) -> None:
    result = _root_with(exc)
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(expected), result.stderr
    assert "Traceback" not in result.stderr
    if isinstance(exc, OSError) and exc.errno == 36:
        assert "File name too long: give a shorter name" in lines[0]
        assert len(lines[0]) < 200


def test_ctrl_c_in_a_command_is_one_line_and_130() -> None:
    result = _root_with(KeyboardInterrupt())
    assert result.exit_code == 130
    assert result.stderr == "urpt-gcs: interrupted\n"


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["demo-site", "--seed", "-1"], "--seed -1 is out of range; use 0 to 4294967295"),
        (
            ["sitl", "--seed", "-1", "--listen", "udpout://127.0.0.1:14998"],
            "--seed -1 is out of range; use 0 to 4294967295",
        ),
        (["bench", "gtsplib", ".", "--runs", "0"], "--runs 0 is below 1"),
    ],
)
def test_every_seed_is_checked(args: list[str], expected: str) -> None:
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], result.stderr


def test_seed_above_32_bits_is_refused(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    args = ["--dem", str(site["dem"]), "--targets", str(site["targets"]), "--out", str(out)]
    result = _run(["plan", *args, "--seed", str(2**32)])
    _assert_clean_failure(result, out, "--seed 4294967296 is out of range; use 0 to 4294967295")


# --- Ctrl-C on the installed program ---------------------------------------------------------


def _installed() -> Path:
    import sys

    program = Path(sys.executable).parent / "urpt-gcs"
    if not program.exists():
        pytest.skip("urpt-gcs is not installed beside this interpreter")
    return program


def _interrupt(tmp_path: Path, when: str, env: dict[str, str] | None = None) -> tuple[int, str]:
    """Start `urpt-gcs plan` on the demo site, send SIGINT at ``when``; exit status, stderr."""
    import signal
    import subprocess
    import time

    from conftest import DEMO

    args = [str(_installed()), "plan", "--dem", str(DEMO / "site.tif")]
    args += ["--targets", str(DEMO / "targets.kml"), "--out", str(tmp_path / "out"), "--no-map"]
    # A terminal never ignores Ctrl-C; a shell's background job (how a runner may start the
    # suite) does, and the child would inherit that.
    process = subprocess.Popen(
        args,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    maps = Path(f"/proc/{process.pid}/maps")
    if when == "during import":
        # numpy is the first heavy library the command line loads; rasterio, numba and the
        # planner come after it.
        deadline = time.monotonic() + 30.0
        while "numpy" not in maps.read_text() and time.monotonic() < deadline:
            time.sleep(0.002)
    elif when != "at once":
        time.sleep(float(when))
    process.send_signal(signal.SIGINT)
    _out, err = process.communicate(timeout=120)
    return process.returncode, err


def test_ctrl_c_at_once_is_never_a_traceback(tmp_path: Path) -> None:
    import signal

    code, err = _interrupt(tmp_path, "at once")
    # So early, the interpreter may not have its own handler yet and dies of the signal
    # itself (a shell shows 130 for that too), silently.
    assert code in (130, -signal.SIGINT), err
    assert err in ("", "urpt-gcs: interrupted\n"), err


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc")
def test_ctrl_c_while_modules_load_is_one_line_and_130(tmp_path: Path) -> None:
    code, err = _interrupt(tmp_path, "during import")
    assert (code, err) == (130, "urpt-gcs: interrupted\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("when", ["1.0", "2.0", "3.0", "4.5", "6.0"])
def test_ctrl_c_while_planning_is_one_line_and_130(when: str, tmp_path: Path) -> None:
    """Also while numba compiles (a cold cache), where Ctrl-C lands in callbacks from C."""
    import os

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    code, err = _interrupt(tmp_path, when, env)
    assert (code, err) == (130, "urpt-gcs: interrupted\n")


def test_ctrl_c_still_removes_the_temporary_cache_folder(tmp_path: Path) -> None:
    """Ctrl-C exits without the interpreter's shutdown; the exit handlers must still run."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    (tmp_path / "cache").write_text("a file where the cache folder would be\n")
    (tmp_path / "tmp").mkdir()
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"), TMPDIR=str(tmp_path / "tmp"))
    code, err = _interrupt(tmp_path, "3.0", env)
    assert (code, err) == (130, "urpt-gcs: interrupted\n")
    assert list((tmp_path / "tmp").iterdir()) == []
