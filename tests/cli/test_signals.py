"""Ctrl-C and SIGTERM at random moments of a plan that runs worker processes.

``plan --altitude auto`` plans the lowest plane here, then the other altitudes in worker
processes. Each round starts it in a session of its own, sends SIGINT to the whole group (as a
terminal's Ctrl-C does) or SIGTERM to the main process alone or to the group, at a random
moment (from the start, or once the workers run), and checks the four things an operator
depends on: one line and no traceback from any process, the exit status of the signal, no
process of the session left running, and no leaked semaphore reported.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import DEMO

ROUNDS = 8
# Each round must end within this after its signal; a hang fails instead of blocking.
END_WITHIN_S = 90.0
# A fresh process compiles the planner's kernels when the cache is cold: minutes on 2 cores.
START_WITHIN_S = 600.0
# The stage line printed as the workers start.
WORKERS_START = "... planning the lowest plane"


def _plan(out: Path, *more: str) -> list[str]:
    """``plan`` of the demo site into ``out``, without a map."""
    site = ["--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    return ["plan", *site, "--out", str(out), "--no-map", *more]


def _session(sid: int) -> list[int]:
    """Live processes of session ``sid`` (zombies left out: they hold no resources)."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            stat = Path(f"/proc/{name}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if fields[0] != "Z" and int(fields[3]) == sid:
            found.append(int(name))
    return found


def _round(rng: random.Random, mode: str, at_workers: bool, out: Path) -> None:
    args = [sys.executable, "-m", "urpt_gcs", *_plan(out, "--altitude", "auto")]
    args += ["--altitude-steps", "4"]
    # stderr to a file: a process that outlives the plan would hold a pipe open for ever.
    errors = out.with_name(out.name + ".stderr")
    with errors.open("w") as sink:
        child = subprocess.Popen(
            args, stdout=subprocess.PIPE, stderr=sink, text=True, start_new_session=True
        )
    started = threading.Event()
    lines: list[str] = []

    def read() -> None:
        assert child.stdout is not None
        for line in child.stdout:
            lines.append(line)
            if line.startswith(WORKERS_START):
                started.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        if at_workers:
            started.wait(START_WITHIN_S)
            time.sleep(rng.uniform(0.0, 3.0))
        else:
            time.sleep(rng.uniform(0.3, 6.0))
        if mode == "SIGINT to the group":
            os.killpg(child.pid, signal.SIGINT)
        elif mode == "SIGTERM to the main process":
            os.kill(child.pid, signal.SIGTERM)
        else:
            os.killpg(child.pid, signal.SIGTERM)
        try:
            child.wait(END_WITHIN_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{mode}: the plan still ran {END_WITHIN_S:g} s after the signal")
        reader.join(10.0)
        stderr = errors.read_text()
        time.sleep(0.5)  # a killed child's exit reaches /proc a moment later
        left = _session(child.pid)
    finally:
        if _session(child.pid):
            os.killpg(child.pid, signal.SIGKILL)
    what = f"{mode}, {'once the workers ran' if at_workers else 'from the start'}"
    assert "Traceback" not in stderr, f"{what}: {stderr}"
    assert "leaked semaphore" not in stderr, f"{what}: {stderr}"
    assert left == [], f"{what}: processes {left} outlived the plan"
    if child.returncode == 0:
        return  # it finished before the signal landed
    expected = 130 if mode.startswith("SIGINT") else 143
    assert child.returncode == expected, f"{what}: exit {child.returncode}, {stderr}"
    assert stderr.strip().splitlines() == ["urpt-gcs: interrupted"], f"{what}: {stderr}"


def test_signals_at_random_moments_leave_one_line_and_no_process(tmp_path: Path) -> None:
    rng = random.Random(41)
    modes = ["SIGINT to the group", "SIGTERM to the main process", "SIGTERM to the group"]
    for n in range(ROUNDS):
        _round(rng, modes[n % 3], at_workers=n % 2 == 1, out=tmp_path / f"out{n}")


def _start(args: list[str], out: Path, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """``python -m urpt_gcs ARGS`` in a session of its own, stdout and stderr to files."""
    with out.with_suffix(".stdout").open("w") as so, out.with_suffix(".stderr").open("w") as se:
        return subprocess.Popen(
            [sys.executable, "-m", "urpt_gcs", *args],
            stdout=so,
            stderr=se,
            text=True,
            start_new_session=True,
            env=env,
        )


def _stopped(child: subprocess.Popen[str], out: Path) -> str:
    """SIGTERM to the main process alone; its stderr once it and its session have ended."""
    os.kill(child.pid, signal.SIGTERM)
    try:
        child.wait(END_WITHIN_S)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        pytest.fail(f"still running {END_WITHIN_S:g} s after SIGTERM")
    time.sleep(0.5)
    left = _session(child.pid)
    if left:
        os.killpg(child.pid, signal.SIGKILL)
    assert left == [], f"processes {left} outlived the command"
    return out.with_suffix(".stderr").read_text()


def _wait_for(what: str, found: object, within_s: float = END_WITHIN_S) -> None:
    deadline = time.monotonic() + within_s
    while not (found() if callable(found) else found):
        if time.monotonic() > deadline:
            pytest.fail(f"{what} did not happen within {within_s:g} s")
        time.sleep(0.2)


def test_a_batch_stopped_by_sigterm_writes_its_results(tmp_path: Path) -> None:
    # Before, SIGTERM left the job folders it had committed and no batch.csv.
    altitudes = ", ".join(str(480 + 5 * k) for k in range(12))
    jobs = tmp_path / "jobs.toml"
    jobs.write_text(
        f'[plan]\ntime-limit = 1\nno-map = true\n[[site]]\nname = "demo"\n'
        f'dem = "{DEMO / "site.tif"}"\ntargets = "{DEMO / "targets.kml"}"\n'
        f"[site.sweep]\naltitude = [{altitudes}]\n"
    )
    out = tmp_path / "out"
    child = _start(["batch", str(jobs), "--out", str(out), "--workers", "2"], tmp_path / "run")
    log = tmp_path / "run.stdout"
    _wait_for("the first job's end", lambda: "[1/12]" in log.read_text(), START_WITHIN_S)
    stderr = _stopped(child, tmp_path / "run")
    if child.returncode == 0:
        return  # every job ended before the signal
    assert child.returncode == 143, stderr
    assert stderr.strip().splitlines() == ["urpt-gcs: interrupted"], stderr
    rows = (out / "batch.csv").read_text().splitlines()
    assert len(rows) == 13  # the header and every job, the unfinished ones marked
    assert any(",ok," in row for row in rows[1:])


def test_bench_scale_stopped_by_sigterm_leaves_no_raster(tmp_path: Path) -> None:
    # Before, SIGTERM left the generated raster in the temporary folder.
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    args = ["bench", "scale", "--targets", "20", "--size", "3000"]
    child = _start(args, tmp_path / "run", env)
    _wait_for(
        "the site's raster", lambda: any(scratch.glob("urpt-scale-*/site.tif")), START_WITHIN_S
    )
    time.sleep(1.0)
    stderr = _stopped(child, tmp_path / "run")
    assert child.returncode in (0, 143), stderr
    assert list(scratch.iterdir()) == [], "the bench left files in the temporary folder"


def test_ctrl_c_as_the_summary_ends_is_no_silent_kill(tmp_path: Path) -> None:
    # Before, Ctrl-C while the interpreter shut down killed the process by the signal, with
    # no line: a status that said the run failed after it had written everything.
    out = tmp_path / "out"
    args = _plan(out, "--time-limit", "0.5")
    child = subprocess.Popen(
        [sys.executable, "-m", "urpt_gcs", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    assert child.stdout is not None
    for line in child.stdout:
        if line.rstrip().endswith("summary.json"):  # the summary's last line
            os.killpg(child.pid, signal.SIGINT)
            break
    child.stdout.read()
    assert child.wait(END_WITHIN_S) in (0, 130)
    assert (out / "summary.json").is_file()
