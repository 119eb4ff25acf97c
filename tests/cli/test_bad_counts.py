"""Files and counts that would hang or fill the memory are refused before anything is built:
the batch's jobs file (a FIFO, a link to a device, a file over the cap), ``--workers`` over
what the computer can run, ``bench scale --size`` and ``--targets`` beyond what it can make.

Each case runs in a child process with a time and memory limit, so that a regression fails
instead of hanging or eating the machine: exit 1, one line naming the input and the fix.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import DEMO
from test_bad_inputs import run_cli

from urpt_gcs.site.inputs import SETTINGS_FILE_MAX_BYTES


def _jobs(path: Path) -> None:
    path.write_text(
        f'[[site]]\nname = "demo"\ndem = "{DEMO / "site.tif"}"\n'
        f'targets = "{DEMO / "targets.kml"}"\n'
    )


def _sparse(path: Path) -> None:
    with path.open("wb") as fh:
        fh.truncate(SETTINGS_FILE_MAX_BYTES + 1)


JOBS_FILES: dict[str, tuple[Callable[[Path], None], list[str]]] = {
    "fifo": (os.mkfifo, ["jobs file", "FIFO", "regular file"]),
    "link_to_dev_zero": (lambda p: p.symlink_to("/dev/zero"), ["character device"]),
    "too_large": (_sparse, ["jobs file", "over the 4.0 MiB limit"]),
}


def _one_line(code: int, stderr: str, words: list[str]) -> None:
    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    for word in words:
        assert word in lines[0], lines[0]


@pytest.mark.parametrize("case", sorted(JOBS_FILES))
def test_a_jobs_file_that_is_not_a_bounded_regular_file_is_refused(
    case: str, tmp_path: Path
) -> None:
    make, words = JOBS_FILES[case]
    jobs = tmp_path / f"jobs_{case}.toml"
    make(jobs)
    code, stderr = run_cli(["batch", str(jobs), "--out", str(tmp_path / "out")], in_child=True)
    _one_line(code, stderr, [jobs.name, *words])
    assert not (tmp_path / "out").exists()


def test_workers_beyond_four_per_core_are_refused_before_a_cluster_starts(
    tmp_path: Path,
) -> None:
    jobs = tmp_path / "jobs.toml"
    _jobs(jobs)
    args = ["batch", str(jobs), "--out", str(tmp_path / "out"), "--workers", "100000"]
    code, stderr = run_cli(args, in_child=True)
    most = 4 * (os.cpu_count() or 1)
    _one_line(code, stderr, ["--workers 100000", f"give at most {most}"])
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--size", "1000000"], ["--size 1000000", "500..30000 px"]),
        (["--size", "100"], ["--size 100", "500..30000 px"]),
        (["--targets", "0"], ["--targets 0", "1..100000"]),
        (["--targets", "100,100000000"], ["--targets 100000000", "1..100000"]),
    ],
)
def test_bench_scale_refuses_a_size_or_count_it_cannot_make(
    args: list[str], words: list[str], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    code, stderr = run_cli(["bench", "scale", *args, "--out", str(out)], in_child=True)
    _one_line(code, stderr, words)
    assert not out.exists()


@pytest.mark.parametrize(
    ("bench", "runner"),
    [
        (["paper", "--quick"], "urpt_gcs.bench.paper.run_paper"),
        (["cetsp", "{tmp}"], "urpt_gcs.bench.cetsp.run_cetsp"),
        (["gtsplib", "{tmp}"], "urpt_gcs.bench.gtsplib.run_gtsplib"),
        (["scale", "--targets", "5"], "urpt_gcs.bench.scale.run_scale"),
    ],
)
def test_a_bench_refuses_an_out_that_is_a_file_before_it_runs(
    bench: list[str], runner: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def ran(*args: object, **kwargs: object) -> None:
        pytest.fail(f"{runner} ran before --out was checked")

    monkeypatch.setattr(runner, ran)
    out = tmp_path / "results_here"
    out.write_text("the operator's file\n")
    args = ["bench", *(a.replace("{tmp}", str(tmp_path)) for a in bench), "--out", str(out)]
    code, stderr = run_cli(args, in_child=False)
    _one_line(code, stderr, [f"--out '{out}'", "is a file, not a folder"])
    assert out.read_text() == "the operator's file\n"


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["bench", "paper", "--quick", "--heuristic-time", "nan"], "--heuristic-time"),
        (["bench", "paper", "--quick", "--heuristic-time", "-1"], "--heuristic-time"),
        (["bench", "paper", "--quick", "--bound-time", "inf"], "--bound-time"),
        (["upload", "plan.plan", "--timeout", "nan"], "--timeout"),
    ],
)
def test_a_number_that_is_not_finite_or_in_range_is_a_usage_error_naming_its_flag(
    args: list[str], flag: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Before, NaN passed and was refused after the study, named as --time-limit.
    monkeypatch.setattr(
        "urpt_gcs.bench.paper.run_paper", lambda *a, **k: pytest.fail("the bench ran")
    )
    code, stderr = run_cli(args, in_child=False)
    assert code == 2, stderr
    assert f"Invalid value for '{flag}'" in stderr
    assert "Traceback" not in stderr
