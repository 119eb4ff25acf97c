"""What the certificate proves about flights cut into sorties by the endurance.

``python benchmarks/sortie_bound.py [--dem-dir SHARED_DEM_DIR] [--scale 300] [--time-limit 5]``

Plans, each under a battery ``--endurance``: the demo site at 5 min, Arenal with 20 seeded
targets at 20 min (``tests/support/band_sites.py``, the constant plane; only with
``--dem-dir``) and the synthetic scale site of ``urpt-gcs bench scale`` with ``--scale``
targets at 20 min. One row per plan: the sorties flown and the fewest the bound allows, the
length flown against the bound of one closed flight and against the certified bound (which
adds what the endurance forces, :mod:`urpt_gcs.bound.sorties`), the flight time against its
bound, and the wall time of the plan and of its bound. Figures of past runs are in
``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from support.band_sites import seeded_targets_csv

from urpt_gcs import PlanSettings, plan
from urpt_gcs.bench.scale import make_scale_site
from urpt_gcs.errors import UrptError
from urpt_gcs.solvers import SolveSettings

DEMO = Path(__file__).resolve().parents[1] / "missions" / "demo"


def _minutes(seconds: float) -> str:
    return f"{int(seconds // 60)} min {seconds % 60:02.0f} s"


def _row(name: str, dem: Path, targets: Path, settings: PlanSettings) -> str:
    started = time.perf_counter()
    try:
        p = plan(dem, targets, settings)
    except UrptError as exc:
        return f"| {name} | refused: {exc} |"
    wall = time.perf_counter() - started
    c = p.certificate
    if c is None or c.sorties is None:
        return f"| {name} | no certificate |"
    s = c.sorties
    flown = p.flown_length_m
    return (
        f"| {name} | {len(p.sorties)} / {s.sorties} | {flown / 1000:.2f} km | "
        f"{s.single_m / 1000:.2f} km ({(flown - s.single_m) / s.single_m * 100:.1f} %) | "
        f"{c.lower_bound_m / 1000:.2f} km ({p.flown_gap * 100:.1f} %) | "
        f"{_minutes(p.flight_time_s)} / {_minutes(s.flight_time_s)} "
        f"({(p.flight_time_s - s.flight_time_s) / s.flight_time_s * 100:.1f} %) | "
        f"{wall:.1f} s ({c.seconds:.1f} s) |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--dem-dir", type=Path, default=None)
    parser.add_argument("--scale", type=int, default=300)
    parser.add_argument("--time-limit", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    a = parser.parse_args()
    base = PlanSettings(solve=SolveSettings(time_limit_s=a.time_limit))
    print(
        "| site | sorties flown / at least | flown | against one flight's bound | "
        "certified bound (gap) | flight time / bound (gap) | wall (bound) |"
    )
    print("|---|---|---|---|---|---|---|")
    demo = dataclasses.replace(base, endurance_min=5.0)
    print(_row("demo, 5 min", DEMO / "site.tif", DEMO / "targets.kml", demo), flush=True)
    twenty = dataclasses.replace(base, endurance_min=20.0)
    with tempfile.TemporaryDirectory() as tmp:
        if a.dem_dir is not None:
            dem = a.dem_dir / "arenal_aster_wgs84.tif"
            targets = Path(tmp) / "arenal20.csv"
            seeded_targets_csv(dem, 20, a.seed, targets)
            print(_row("arenal 20, 20 min", dem, targets, twenty), flush=True)
        if a.scale > 0:
            site = make_scale_site(Path(tmp) / "scale", 10_000, a.scale, a.seed)
            name = f"scale {a.scale}, 20 min"
            print(_row(name, site.dsm_path, site.targets_path, twenty), flush=True)


if __name__ == "__main__":
    main()
