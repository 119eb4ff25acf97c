"""Benchmark: plan the demo site and the real rasters beside the checkout; print timings.

    .venv/bin/python benchmarks/plan_sites.py [--time-limit S] [--count N] [--camera NAME]

Targets on the real rasters are placed deterministically on valid ground (same rule as the
tests). Reports wall time per stage, visibility time per target, the tour before and after
refinement, the certified lower bound of the shortest possible flight and the gap. With
``--camera`` (``phantom4rtk``, ``mavic3e``) every site is planned with that frame camera
(4 headings) instead of the 30-degree cone.
"""

from __future__ import annotations

import argparse
import math
import resource
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.targets import REAL_CASES, valid_targets  # noqa: E402

from urpt_gcs.pipeline.planner import plan  # noqa: E402
from urpt_gcs.pipeline.settings import PlanSettings  # noqa: E402
from urpt_gcs.site.camera import camera_preset  # noqa: E402
from urpt_gcs.solvers import SolveSettings  # noqa: E402


def run(name: str, dem: Path, targets: Path, settings: PlanSettings) -> None:
    started = time.perf_counter()
    result = plan(dem, targets, settings)
    wall = time.perf_counter() - started
    t = result.timings_s
    m = len(result.targets.targets)
    print(
        f"{name:36s} targets {m:3d}  viewpoints {result.instance.n_viewpoints:5d}  "
        f"visibility {1000 * t['visibility'] / m:6.2f} ms/target  "
        f"cover sets {t['viewpoints']:6.3f} s  "
        f"solve {t['solve']:6.2f} s  wall {wall:6.2f} s"
    )
    done, cert = result.refinement, result.certificate
    before = result.tour.length if done is None else done.before_m
    after = result.tour.length if done is None else done.after_m
    print(
        f"{'':36s} discrete {before:8.1f} m  refined {after:8.1f} m "
        f"({0.0 if done is None else done.shortened_pct:5.2f} % shorter, "
        f"{t.get('refine', 0.0):5.2f} s)  flown {result.flown_length_m:8.1f} m  certified bound "
        f"{result.lower_bound_m:8.1f} m ({'-' if cert is None else cert.method}, "
        f"{t['bound']:5.2f} s)  gap {100 * result.flown_gap:7.2f} %  outer/inner area "
        f"{math.nan if cert is None else cert.area_ratio:5.3f}  optimal over the candidates "
        f"{result.optimal_over_candidates}"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--time-limit", type=float, default=5.0)
    parser.add_argument("--count", type=int, default=None, help="targets per real raster")
    parser.add_argument("--camera", default=None, help="a frame camera by name")
    args = parser.parse_args()
    frame = None if args.camera is None else camera_preset(args.camera).frame
    settings = PlanSettings(solve=SolveSettings(time_limit_s=args.time_limit), frame=frame)
    run("demo", REPO / "missions/demo/site.tif", REPO / "missions/demo/targets.kml", settings)
    with tempfile.TemporaryDirectory() as tmp:
        for name, count, box in REAL_CASES:
            dem = REPO.parent / "shared" / "dem" / name
            pts = valid_targets(dem, args.count or count, seed=3, box_m=box)
            csv = Path(tmp) / f"{name}.csv"
            csv.write_text("name,lat,lon\n" + "".join(f"{n},{a:.9f},{b:.9f}\n" for n, a, b in pts))
            run(name, dem, csv, settings)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {peak:.0f} MiB")


if __name__ == "__main__":
    main()
