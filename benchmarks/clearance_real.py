"""Benchmark: leg clearances on the real rasters, reported against an independent measure.

    .venv/bin/python benchmarks/clearance_real.py [--min-clearance M]

For each raster beside the checkout (``../shared/dem``), plans targets placed as the tests
place them, writes the mission, and compares per leg: the clearance the plan reports (exact
on the bilinear surface), the one dense independent samples of the written ``.waypoints``
give (``tests/support/independent.py``, every 1/256 cell), and what sampling every half cell along
the leg, as the tool once did, would have reported.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.independent import leg_clearances, load_raster, read_waypoints_file  # noqa: E402
from support.targets import REAL_CASES, valid_targets  # noqa: E402

from urpt_gcs.files.products import write_products  # noqa: E402
from urpt_gcs.pipeline.planner import plan  # noqa: E402
from urpt_gcs.pipeline.result import Plan  # noqa: E402
from urpt_gcs.pipeline.settings import PlanSettings  # noqa: E402
from urpt_gcs.solvers import SolveSettings  # noqa: E402


def half_cell_sampled(result: Plan) -> np.ndarray:
    """Least clearance per leg from bilinear samples every half cell along it."""
    terrain, out = result.terrain, []
    eye = result.mission.home.amsl_m + result.altitude_rel_m
    for sortie in result.sorties:
        path = np.vstack(
            [[result.home_xy], result.tour.points_xy[sortie.first : sortie.stop], [result.home_xy]]
        )
        for a, b in itertools.pairwise(path):
            n = max(int(np.ceil(np.hypot(*(b - a)) / (terrain.cell_m / 2.0))), 1)
            t = np.linspace(0.0, 1.0, n + 1)
            z = terrain.sample(a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)
            out.append(eye - np.nanmax(z) if np.isfinite(z).any() else np.nan)
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-clearance", type=float, default=10.0)
    args = parser.parse_args()
    shared = REPO.parent / "shared" / "dem"
    if not shared.is_dir():
        sys.exit(f"no real rasters at {shared}: this benchmark needs ../shared/dem")
    print(
        f"{'raster':36s} {'legs':>4s} {'reported min':>12s} {'independent':>11s} "
        f"{'max |diff|':>10s} {'half-cell min':>13s} {'overstated by':>13s}"
    )
    for name, count, box_m in REAL_CASES:
        dem = shared / name
        targets = valid_targets(dem, count, seed=3, box_m=box_m)
        with tempfile.TemporaryDirectory() as tmp:
            csv = Path(tmp) / "targets.csv"
            csv.write_text(
                "name,lat,lon\n" + "".join(f"{n},{la:.9f},{lo:.9f}\n" for n, la, lo in targets)
            )
            settings = PlanSettings(
                solve=SolveSettings(time_limit_s=2.0), min_clearance_m=args.min_clearance
            )
            result = plan(dem, csv, settings)
            out = Path(tmp) / "out"
            write_products(result, out, with_map=False)
            flown = [read_waypoints_file(f) for f in sorted(out.glob("mission*.waypoints"))]
        dense = leg_clearances(load_raster(dem), flown, cells_per_sample=1 / 256)
        independent = np.array([c for sortie in dense for c in sortie])
        reported = np.array([leg.min_clearance_m for leg in result.legs])
        sampled = half_cell_sampled(result)
        print(
            f"{name:36s} {len(reported):4d} {np.nanmin(reported):12.3f} "
            f"{np.nanmin(independent):11.3f} {np.nanmax(np.abs(reported - independent)):10.4f} "
            f"{np.nanmin(sampled):13.3f} {np.nanmax(sampled - reported):13.3f}"
        )


if __name__ == "__main__":
    main()
