"""Benchmark: how long the solve stage takes, per solver, against ``--time-limit``.

    .venv/bin/python benchmarks/time_limits.py [--time-limit S] [--repeat N]

Plans the demo site (16 targets) and 40 targets placed deterministically on valid ground of
the same DSM (the tests' rule), with each solver, ``--repeat`` times. Reports the wall time
of the solve stage (from its announcement to its end, as the progress bar sees it; the
compile stage is separate), its ratio to the limit, the longest pause between two ticks of a
0.1 s background ticker during the solve and during any stage of the plan (what a progress
display would show), the tour and whether it is proven. Timings on a shared machine are
noisy: repeat and read the spread.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.targets import valid_targets  # noqa: E402

from urpt_gcs.errors import UrptError  # noqa: E402
from urpt_gcs.pipeline.planner import plan  # noqa: E402
from urpt_gcs.pipeline.settings import PlanSettings  # noqa: E402
from urpt_gcs.solvers import SolveSettings  # noqa: E402

DEMO = REPO / "missions" / "demo"
SOLVERS = ("exact", "heuristic", "approx", "ortools")
_TICK_S = 0.1


@dataclass
class _Ticker:
    """Notes the stage announcements and a tick every 0.1 s from a background thread."""

    stages: list[tuple[float, str]] = field(default_factory=list)
    ticks: list[float] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def __call__(self, stage: str) -> None:
        self.stages.append((time.perf_counter(), stage))

    def run(self) -> None:
        while not self.stop.wait(_TICK_S):
            self.ticks.append(time.perf_counter())

    def longest_pauses(self, ended: float) -> dict[str, float]:
        """The longest time without a tick in each stage, by stage name."""
        ends = [*(t for t, _ in self.stages[1:]), ended]
        out = {}
        for (start, name), end in zip(self.stages, ends, strict=True):
            marks = [start, *(t for t in self.ticks if start < t < end), end]
            out[name] = max(b - a for a, b in itertools.pairwise(marks))
        return out


def run(dem: Path, targets: Path, solver: str, limit_s: float) -> str:
    ticker = _Ticker()
    thread = threading.Thread(target=ticker.run, daemon=True)
    thread.start()
    settings = PlanSettings(solver=solver, solve=SolveSettings(time_limit_s=limit_s))
    try:
        result = plan(dem, targets, settings, progress=ticker)
    except UrptError as exc:
        return f"refused: {exc}"
    finally:
        ticker.stop.set()
        thread.join()
    pauses = ticker.longest_pauses(time.perf_counter())
    solving = next(v for k, v in pauses.items() if k.startswith("solving"))
    solve_s = result.timings_s["solve"]
    tour = result.tour
    return (
        f"solve {solve_s:5.2f} s ({solve_s / limit_s:4.0%} of the limit)  "
        f"longest pause {solving:4.2f} s (any stage {max(pauses.values()):4.2f} s)  "
        f"compile {result.timings_s['compile']:5.2f} s  tour {tour.length:7.1f} m  "
        f"proven {tour.proven_optimal!s:5s}"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--time-limit", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    dem = DEMO / "site.tif"
    with tempfile.TemporaryDirectory() as tmp:
        forty = Path(tmp) / "forty.csv"
        points = valid_targets(dem, 40, seed=3)
        forty.write_text("name,lat,lon\n" + "".join(f"{n},{a:.9f},{b:.9f}\n" for n, a, b in points))
        for site, targets in (("demo (16 targets)", DEMO / "targets.kml"), ("40 targets", forty)):
            for solver in SOLVERS:
                times = []
                for k in range(args.repeat):
                    line = run(dem, targets, solver, args.time_limit)
                    print(f"{site:18s} {solver:9s} run {k + 1}: {line}", flush=True)
                    if line.startswith("refused"):
                        break
                    times.append(float(line.split()[1]))
                if times:
                    print(
                        f"{site:18s} {solver:9s} solve stage min {min(times):.2f} / median "
                        f"{statistics.median(times):.2f} / max {max(times):.2f} s at "
                        f"--time-limit {args.time_limit:g}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
