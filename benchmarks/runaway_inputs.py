"""Benchmark: peak memory and wall time of the inputs that used to run away, and the time to
parse 100 000 placemarks.

    .venv/bin/python benchmarks/runaway_inputs.py [--only NAME ...] [--placemarks N]

Each case runs ``urpt-gcs`` on the demo site in a child process (limited to 8 GiB of address
space and 300 s, so a regression cannot take the machine down) and reports its exit status,
wall time, peak resident memory (``ru_maxrss`` of that child, from ``os.wait4``) and the first
line of its stderr. FIFOs, links to devices and the oversized file are made in a temporary
folder. The parse figure is :func:`urpt_gcs.site.targets.read_targets` on a generated KML of
``--placemarks`` points, in this process.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from urpt_gcs.site.inputs import TARGETS_MAX_BYTES
from urpt_gcs.site.targets import read_targets

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "missions" / "demo"
BAD = REPO / "tests" / "data" / "bad"
_TIMEOUT_S = 300.0
_MEMORY_BYTES = 8 * 2**30


@dataclass(frozen=True, slots=True)
class Case:
    name: str
    args: Callable[[Path], list[str]]  # the command line, given a scratch folder


def _plan(tmp: Path, *extra: str) -> list[str]:
    base = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    return [*base, "--out", str(tmp / "out"), "--no-map", "--time-limit", "0.5", *extra]


def _made(tmp: Path, name: str, make: Callable[[Path], None]) -> str:
    path = tmp / name
    make(path)
    return str(path)


def _sparse(size: int) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        with path.open("wb") as fh:
            fh.truncate(size)

    return make


def _link(device: str) -> Callable[[Path], None]:
    return lambda path: path.symlink_to(device)


CASES = (
    Case("demo (16 targets, for scale)", lambda t: _plan(t)),
    Case("altitude_1e9", lambda t: _plan(t, "--altitude", "1e9")),
    Case("clearance_1e6", lambda t: _plan(t, "--clearance", "1e6")),
    Case(
        "targets_link_to_dev_zero",
        lambda t: _plan(t, "--targets", _made(t, "zero.kml", _link("/dev/zero"))),
    ),
    Case(
        "upload_link_to_dev_urandom",
        lambda t: [
            "upload",
            _made(t, "urandom.plan", _link("/dev/urandom")),
            "--connect",
            "udpin://127.0.0.1:14998",
        ],
    ),
    Case("targets_fifo", lambda t: _plan(t, "--targets", _made(t, "fifo.kml", os.mkfifo))),
    Case("dem_fifo", lambda t: _plan(t, "--dem", _made(t, "fifo.tif", os.mkfifo))),
    Case(
        "targets_too_large",
        lambda t: _plan(t, "--targets", _made(t, "big.kml", _sparse(TARGETS_MAX_BYTES + 2**20))),
    ),
    Case("dem_name_too_long", lambda t: _plan(t, "--dem", str(t / ("d" * 300 + ".tif")))),
    Case(
        "demo_300_targets",
        lambda t: _plan(t, "--targets", str(BAD / "demo_300_targets.csv")),
    ),
)


@dataclass(frozen=True, slots=True)
class Result:
    status: str
    wall_s: float
    peak_mib: float
    message: str


def _limit() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (_MEMORY_BYTES, _MEMORY_BYTES))


def run(args: list[str]) -> Result:
    """Run ``urpt-gcs ARGS`` in a limited child; its status, wall time and peak RSS."""
    code = "from urpt_gcs.cli import main; main()"
    started = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        child = subprocess.Popen(
            [sys.executable, "-c", code, *args],
            stdout=subprocess.DEVNULL,
            stderr=err,
            preexec_fn=_limit,
        )
        deadline = started + _TIMEOUT_S
        status = "timeout"
        usage = None
        while time.perf_counter() < deadline:
            pid, wait_status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                status = f"exit {os.waitstatus_to_exitcode(wait_status)}"
                break
            time.sleep(0.05)
        else:
            child.kill()
            _, _, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - started
        err.seek(0)
        lines = err.read().strip().splitlines()
    peak = usage.ru_maxrss / 1024.0 if usage is not None else float("nan")  # KiB on Linux
    return Result(status, wall, peak, lines[0] if lines else "")


def parse_seconds(n: int) -> float:
    """Seconds :func:`read_targets` takes on a KML of ``n`` distinct placemarks."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "many.kml"
        rows = (
            f"<Placemark><name>P{i}</name><Point><coordinates>"
            f"{8.0 + 1e-5 * (i % 1000):.6f},{47.0 + 1e-5 * (i // 1000):.6f},0"
            "</coordinates></Point></Placemark>\n"
            for i in range(n)
        )
        head = '<?xml version="1.0"?>\n<kml xmlns="http://www.opengis.net/kml/2.2"><Document>\n'
        path.write_text(head + "".join(rows) + "</Document></kml>\n")
        started = time.perf_counter()
        found = len(read_targets(path).targets)
        seconds = time.perf_counter() - started
    if found != n:
        raise SystemExit(f"read {found} of {n} placemarks")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="Run only these cases (by name).")
    parser.add_argument("--placemarks", type=int, default=100_000)
    options = parser.parse_args()
    cases = [c for c in CASES if not options.only or c.name in options.only]
    print(f"{'case':30} {'status':8} {'wall s':>7} {'peak MiB':>9}  first line of stderr")
    for case in cases:
        with tempfile.TemporaryDirectory() as folder:
            result = run(case.args(Path(folder)))
        print(
            f"{case.name:30} {result.status:8} {result.wall_s:7.2f} {result.peak_mib:9.0f}  "
            f"{result.message}",
            flush=True,
        )
    if options.placemarks:
        seconds = parse_seconds(options.placemarks)
        print(f"read_targets on {options.placemarks} placemarks: {seconds:.2f} s")


if __name__ == "__main__":
    main()
