"""`urpt-gcs batch`: jobs files, and sites planned on a local Dask cluster as `plan` plans them."""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Iterator
from dataclasses import asdict, replace
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from conftest import DEMO, REAL_DEMS, needs_shared
from distributed import Client
from support.independent import check_mission
from support.targets import kml_targets, valid_targets

from urpt_gcs.batch.cluster import map_jobs, open_client
from urpt_gcs.batch.jobs import PLAN_KEYS, check_inputs, read_jobs, run_batch
from urpt_gcs.bench.paper import Row, run_paper
from urpt_gcs.cli import main
from urpt_gcs.cli.plan import plan_command
from urpt_gcs.errors import ClusterError, JobsFileError, SettingsError
from urpt_gcs.pipeline.options import FLEET_OPTIONS, PLAN_OPTIONS
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings

# What differs between two runs of the same plan: times, and where the files were written.
# Times, and the certified bound (its pieces are refined until the clock says stop).
VOLATILE = {"timings_s", "solve_s", "files", "refine_s", "bound", "lower_bound_m", "gap_pct"}


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_sweeps_expand_into_named_jobs_with_their_settings(tmp_path: Path) -> None:
    jobs_file = _write(
        tmp_path / "jobs.toml",
        """
[plan]
time-limit = 2
no-map = true

[cameras.wide]
fov = 40

[[site]]
name = "quarry"
dem = "q/dsm.tif"
targets = "q/t.kml"
samples = 24
[site.sweep]
altitude = [80, 100.5]
camera = ["wide"]

[[site]]
name = "dam"
dem = "/data/dam.tif"
targets = "dam.csv"
[site.sweep]
fov = [25, 35]
""",
    )
    jobs = read_jobs(jobs_file, tmp_path / "out")
    assert [j.name for j in jobs] == [
        "quarry-alt80-wide",
        "quarry-alt100.5-wide",
        "dam-fov25",
        "dam-fov35",
    ]
    first = jobs[0]
    assert first.dem == str(tmp_path / "q" / "dsm.tif")
    assert first.targets == str(tmp_path / "q" / "t.kml")
    assert first.out == str(tmp_path / "out" / "quarry-alt80-wide")
    assert first.with_map is False
    assert (first.settings.altitude_m, first.settings.fov_deg) == (80.0, 40.0)
    assert first.settings.samples == 24
    assert first.settings.solve.time_limit_s == 2.0
    assert jobs[1].settings.altitude_m == 100.5
    assert jobs[2].dem == "/data/dam.tif"
    assert [j.settings.fov_deg for j in jobs[2:]] == [25.0, 35.0]
    assert jobs[2].settings.samples == 36  # the plan default, not the other site's


def test_frame_cameras_in_a_jobs_file_are_the_plan_command_s(tmp_path: Path) -> None:
    """A camera table may name a preset or a sensor, lens and image with headings and a GSD;
    each job's frame is the one `urpt-gcs plan` makes of the same flags."""
    jobs_file = _write(
        tmp_path / "jobs.toml",
        """
[cameras.wide]
fov = 40
[cameras.p4]
camera = "phantom4rtk"
gsd = 2.5
headings = 2
[cameras.own]
sensor = "17.3x13"
focal = 12.29
image = "5280x3956"

[[site]]
name = "q"
dem = "d.tif"
targets = "t.kml"
fov = 20
[site.sweep]
camera = ["wide", "p4", "own"]
""",
    )
    wide, p4, own = read_jobs(jobs_file, tmp_path / "out")
    assert (wide.settings.frame, wide.settings.fov_deg) == (None, 40.0)

    from urpt_gcs.site.camera import frame_from_flags

    assert p4.settings.frame == frame_from_flags("phantom4rtk", None, None, None)
    assert (p4.settings.gsd_cm, p4.settings.headings) == (2.5, 2)
    assert own.settings.frame == frame_from_flags(None, "17.3x13", 12.29, "5280x3956")
    assert own.settings.gsd_cm is None and own.settings.frame is not None
    assert [j.name for j in (wide, p4, own)] == ["q-wide", "q-p4", "q-own"]
    both = _write(tmp_path / "both.toml", SITE + 'camera = "mavic3e"\nfov = 30\n')
    with pytest.raises(JobsFileError, match=r"both.toml: \[\[site\]\] 'a'.*give one"):
        read_jobs(both, tmp_path / "out2")


def test_defaults_are_those_of_the_plan_command(tmp_path: Path) -> None:
    """The CLI, a jobs file and the library take one table's defaults (a job's threads aside)."""
    context = click.Context(plan_command)
    flags = {
        opt.lstrip("-"): param.get_default(context)
        for param in plan_command.params
        for opt in param.opts
    }
    table = {o.key: None if o.unset else o.default for o in (*PLAN_OPTIONS, *FLEET_OPTIONS)}
    assert {key: flags[key] for key in table} == table
    assert set(PLAN_KEYS) == {o.key for o in PLAN_OPTIONS}
    library = PlanSettings()
    for o in PLAN_OPTIONS:
        if not o.setting:
            continue
        group, _, name = o.setting.rpartition(".")
        value = getattr(getattr(library, group) if group else library, name)
        assert value == ((not o.default) if o.invert else o.default), o.key
    job = read_jobs(_write(tmp_path / "jobs.toml", SITE), tmp_path / "out")[0]
    assert job.settings == replace(library, workers=1)  # a job's threads: one per worker


SITE = '[[site]]\nname = "a"\ndem = "d.tif"\ntargets = "t.kml"\n'


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[[site]\n", "not valid TOML"),
        ("[plan]\nfov = 30\n", "no [[site]] table"),
        ('[[site]]\nname = "a"\ndem = "d.tif"\n', "[[site]] 1 has no 'targets'"),
        (SITE + "fvo = 30\n", "[[site]] 'a': unknown key 'fvo': did you mean 'fov'?"),
        (SITE + 'fov = "wide"\n', "[[site]] 'a', key 'fov': 'wide' is not a number"),
        (SITE + "fov = 95\n", "[[site]] 'a' (job a): fov 95"),
        ("[plan]\nstrict = 1\n" + SITE, "[plan], key 'strict': 1 is not true or false"),
        (SITE + "[site.sweep]\naltitude = 80\n", "key 'altitude': give a list of values"),
        (SITE + '[site.sweep]\ncamera = ["tele"]\n', "no [cameras.tele] table"),
        (SITE + "[site.sweep]\nfov = [30, 30.0]\n", "a value is given twice"),
        (SITE + SITE, "two jobs are named 'a'"),
        (SITE.replace('"a"', '"../up"'), "key 'name': '../up' is the job's folder name"),
    ],
)
def test_a_bad_jobs_file_is_refused_naming_file_table_and_key(
    tmp_path: Path, text: str, expected: str
) -> None:
    jobs_file = _write(tmp_path / "jobs.toml", text)
    with pytest.raises(JobsFileError) as caught:
        read_jobs(jobs_file, tmp_path / "out")
    message = str(caught.value)
    assert message.startswith(f"{jobs_file}: ")
    assert expected in message
    assert "\n" not in message


def test_a_jobs_file_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    # As Notepad saves UTF-8: the mark is no TOML statement.
    jobs_file = tmp_path / "jobs.toml"
    jobs_file.write_bytes(b"\xef\xbb\xbf" + SITE.encode())
    (job,) = read_jobs(jobs_file, tmp_path / "out")
    assert (job.site, Path(job.dem).name, Path(job.targets).name) == ("a", "d.tif", "t.kml")


def test_cli_refuses_a_missing_dem_before_starting_a_cluster(tmp_path: Path) -> None:
    jobs_file = _write(
        tmp_path / "jobs.toml",
        f'[[site]]\nname = "demo"\ndem = "nowhere.tif"\ntargets = "{DEMO / "targets.kml"}"\n',
    )
    result = CliRunner().invoke(main, ["batch", str(jobs_file), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert lines == [
        f"urpt-gcs: error: [[site]] 'demo', dem '{tmp_path / 'nowhere.tif'}': this computer "
        "cannot read it: check the path"
    ]
    assert not (tmp_path / "out").exists()


def test_workers_and_scheduler_together_are_a_usage_error(tmp_path: Path) -> None:
    jobs_file = _write(tmp_path / "jobs.toml", SITE)
    args = ["batch", str(jobs_file), "--out", "o", "--scheduler", "tcp://x:1", "--workers", "2"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2
    with pytest.raises(SettingsError), open_client("tcp://x:1", 2):
        pass


def test_serial_jobs_report_a_failure_and_go_on() -> None:
    ends = map_jobs(abs, [-1, 2])
    assert ends == [1, 2]
    with pytest.raises(TypeError):
        map_jobs(abs, [-1, "x", 3])


@pytest.fixture(scope="module")
def client() -> Iterator[Client]:
    with open_client(workers=2) as opened:
        yield opened


def _comparable(summary: dict[str, object]) -> dict[str, object]:
    return {k: v for k, v in summary.items() if k not in VOLATILE}


@needs_shared(REAL_DEMS)
def test_three_sites_on_two_workers_equal_serial_plans_and_pass_the_check(
    tmp_path: Path, client: Client
) -> None:
    odm = REAL_DEMS / "odm_dsm_utm51n.tif"
    codem = REAL_DEMS / "codem_aoi_dsm_utm16n_egm2008.tif"
    points = {
        "odm": valid_targets(odm, 5, seed=11),
        "codem": valid_targets(codem, 4, seed=12),
    }
    for name, targets in points.items():
        _write(
            tmp_path / f"{name}.csv",
            "name,lat,lon\n" + "".join(f"{n},{a:.9f},{o:.9f}\n" for n, a, o in targets),
        )
    points["demo"] = kml_targets(DEMO / "targets.kml")
    # Compile the kernels into the disk cache the workers read before any plan is timed: on a
    # cold cache a worker would spend part of a time-limited stage compiling.
    plan(DEMO / "site.tif", DEMO / "targets.kml")
    # The time limit bounds the searches, which end on their own well before it: a plan is
    # then a function of its inputs, wherever it runs.
    jobs_file = _write(
        tmp_path / "jobs.toml",
        f"""
[plan]
time-limit = 10
no-map = true

[[site]]
name = "demo"
dem = "{DEMO / "site.tif"}"
targets = "{DEMO / "targets.kml"}"

[[site]]
name = "odm"
dem = "{odm}"
targets = "odm.csv"
[site.sweep]
altitude = [150, 160, 170]

[[site]]
name = "codem"
dem = "{codem}"
targets = "codem.csv"

[[site]]
name = "low"
dem = "{DEMO / "site.tif"}"
targets = "{DEMO / "targets.kml"}"
altitude = 300
""",
    )
    out = tmp_path / "batch"
    jobs = read_jobs(jobs_file, out)
    ended: list[str] = []
    rows = run_batch(jobs, out, client, lambda k, n, row: ended.append(row.job))
    names = ["demo", "odm-alt150", "odm-alt160", "odm-alt170", "codem", "low"]
    assert [r.job for r in rows] == names
    assert sorted(ended) == sorted(names)
    assert [r.status for r in rows] == ["ok"] * 5 + ["failed"]
    assert rows[-1].error.startswith("altitude 300 m is at or below the terrain")
    assert not (out / "low").exists()
    assert {r.worker for r in rows} <= {w for w in client.scheduler_info()["workers"]}
    table = list(csv.DictReader((out / "batch.csv").open()))
    assert [t["job"] for t in table] == names
    assert [t["status"] for t in table] == [r.status for r in rows]

    runner = CliRunner()
    for row, job in zip(rows[:5], jobs[:5], strict=True):
        batch_dir = out / row.job
        mission_files = sorted(batch_dir.glob("mission*.waypoints"))
        assert mission_files
        fov = job.settings.fov_deg
        assert check_mission(Path(job.dem), mission_files, points[job.site], fov, 10.0) == []
        # The same plan from `urpt-gcs plan`, here, one after the other.
        serial_dir = tmp_path / "serial" / row.job
        args = ["plan", "--dem", job.dem, "--targets", job.targets, "--out", str(serial_dir)]
        args += ["--time-limit", "10", "--no-map", "--quiet"]
        if job.settings.altitude_m is not None:
            args += ["--altitude", str(job.settings.altitude_m)]
        result = runner.invoke(main, args)
        assert result.exit_code == 0, result.output
        assert sorted(p.name for p in serial_dir.iterdir()) == sorted(
            p.name for p in batch_dir.iterdir()
        )
        for serial in serial_dir.iterdir():
            mine = batch_dir / serial.name
            if serial.name == "summary.json":
                a, b = json.loads(serial.read_text()), json.loads(mine.read_text())
                assert _comparable(a) == _comparable(b)
                assert [Path(f).name for f in a["files"]] == [Path(f).name for f in b["files"]]
                assert all(Path(f).parent == batch_dir for f in b["files"])
                assert row.tour_length_m == b["tour_length_m"]
                assert row.targets == len(points[job.site])
            else:
                assert serial.read_bytes() == mine.read_bytes(), serial.name
    assert {r.altitude_m for r in rows[1:4]} == {150.0, 160.0, 170.0}


def test_a_path_the_workers_cannot_read_is_refused_up_front(tmp_path: Path, client: Client) -> None:
    missing = tmp_path / "on-my-laptop-only.tif"
    jobs_file = _write(
        tmp_path / "jobs.toml",
        f'[[site]]\nname = "x"\ndem = "{missing}"\ntargets = "{DEMO / "targets.kml"}"\n',
    )
    jobs = read_jobs(jobs_file, tmp_path / "out")
    # With --scheduler the files are looked for on the workers only.
    with pytest.raises(ClusterError) as caught:
        check_inputs(jobs, client, remote=True)
    assert re.fullmatch(
        rf"\[\[site\]\] 'x', dem '{re.escape(str(missing))}': worker tcp://127\.0\.0\.1:\d+ "
        r"cannot read it: put it where every worker reads it .*",
        str(caught.value),
    )
    with pytest.raises(ClusterError):
        run_batch(jobs, tmp_path / "out", client, remote=True)
    assert not (tmp_path / "out").exists()


def _to_the_last_bits(row: dict[str, object]) -> dict[str, object]:
    """The row, its floats equal up to rounding: each process sums in its own order."""
    return {k: pytest.approx(v, rel=1e-12) if isinstance(v, float) else v for k, v in row.items()}


def test_paper_bench_on_the_cluster_equals_the_serial_run(client: Client) -> None:
    grid = [(0, 4, 30.0, 20), (1, 6, 20.0, 20), (3, 4, 40.0, 30)]
    serial = run_paper(grid=grid, heuristic_s=0.5)
    clustered = run_paper(grid=grid, heuristic_s=0.5, client=client)

    def fixed(row: Row) -> dict[str, object]:
        # Times, the certified bound, whose search stops on the clock, and the refined tour,
        # which is read off that search's relaxed tour when shorter.
        clocked = ("exact_s", "heuristic_s", "refine_s", "bound_s", "certified_bound", "refined")
        return {k: v for k, v in asdict(row).items() if k not in (*clocked, "bound_method")}

    assert [fixed(r) for r in serial] == [_to_the_last_bits(fixed(r)) for r in clustered]
    for row in (*serial, *clustered):
        assert row.certified_bound <= row.refined <= row.optimum * (1.0 + 1e-9)
    assert [(r.terrain, r.m, r.fov_deg, r.d) for r in clustered] == grid


def test_the_readme_jobs_file_reads_as_it_says(tmp_path: Path) -> None:
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```toml\n(.*?)^```", readme, re.DOTALL | re.MULTILINE)
    block = [b for b in blocks if "[[site]]" in b]
    assert len(block) == 1
    jobs = read_jobs(_write(tmp_path / "jobs.toml", block[0]), tmp_path / "DIR")
    assert [j.name for j in jobs] == ["quarry-alt80", "quarry-alt100", "quarry-alt120"]
    assert {j.settings.fov_deg for j in jobs} == {35.0}
    assert jobs[0].dem == str(tmp_path / "quarry" / "dsm.tif")


def test_cli_on_a_running_scheduler(tmp_path: Path, client: Client) -> None:
    points = kml_targets(DEMO / "targets.kml")[:4]
    _write(
        tmp_path / "four.csv",
        "name,lat,lon\n" + "".join(f"{n},{a:.9f},{o:.9f}\n" for n, a, o in points),
    )
    jobs_file = _write(
        tmp_path / "jobs.toml",
        f'[plan]\nno-map = true\n[[site]]\nname = "four"\ndem = "{DEMO / "site.tif"}"\n'
        'targets = "four.csv"\n'
        f'[[site]]\nname = "none"\ndem = "{DEMO / "site.tif"}"\ntargets = "four.csv"\n'
        "min-clearance = 500\n",
    )
    out = tmp_path / "out"
    address = client.scheduler_info()["address"]
    args = ["batch", str(jobs_file), "--out", str(out), "--scheduler", address]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines() == [
        f"urpt-gcs: error: 1 of 2 jobs failed (none): see {out / 'batch.csv'}"
    ]
    assert f"2 jobs on 2 workers at {address}" in result.stdout
    assert re.search(r"\[\d/2\] four ok, \d+ m, 1 sortie \(\d+\.\d s, on tcp://", result.stdout)
    assert re.search(r"\[\d/2\] none failed \(.*\): .*clearance", result.stdout)
    rows = {row["job"]: row for row in csv.DictReader((out / "batch.csv").open())}
    assert rows["four"]["status"] == "ok" and rows["four"]["targets"] == "4"
    assert rows["none"]["status"] == "failed" and rows["none"]["tour_length_m"] == ""
    assert sorted(p.name for p in out.iterdir()) == ["batch.csv", "four"]
    # The client's view of the cluster stays up: the batch closed only its own client.
    assert client.submit(abs, -3).result() == 3


def test_cetsp_bench_on_the_cluster_equals_the_serial_run(tmp_path: Path, client: Client) -> None:
    from urpt_gcs.bench.cetsp import run_cetsp

    (tmp_path / "instances").mkdir()
    discs = {
        "square": "10 0 1\n10 10 1\n0 10 1\n",
        "line": "5 0 1.5\n12 1 1\n20 -1 2\n27 0 1\n",
        "ring": "".join(f"{8 * math.cos(a):.3f} {8 * math.sin(a):.3f} 1.2\n" for a in range(6)),
    }
    for name, text in discs.items():
        (tmp_path / "instances" / f"{name}.txt").write_text(f"# {name} depot=0,0\n{text}")
    serial = run_cetsp(tmp_path, time_limit_s=1.0)
    clustered = run_cetsp(tmp_path, time_limit_s=1.0, client=client)

    # The tours are the same; the bound refines its pieces until the clock runs out, so how
    # far it rises depends on the machine, but it bounds the tour either way.
    timed = ("time_s", "lower_bound", "gap_pct")

    def fixed(row: object) -> dict[str, object]:
        return {k: v for k, v in asdict(row).items() if k not in timed}  # type: ignore[call-overload]

    assert [fixed(r) for r in serial] == [_to_the_last_bits(fixed(r)) for r in clustered]
    assert all(0.0 < r.lower_bound <= r.length for r in [*serial, *clustered])
    assert sorted(r.instance for r in clustered) == sorted(discs)
