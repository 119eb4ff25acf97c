"""The height band on the two mountain rasters against the constant plane.

``python benchmarks/band_mountains.py SHARED_DEM_DIR [--targets 20 100] [--endurance 30]``
writes seeded random targets in a 3 km window around each raster's centre, with Home at the
centre (``tests/support/band_sites.py``, the same sites the tests plan), plans each site
inside ``--agl 30:120`` and on the constant plane, and prints one row per plan: stops,
waypoints inserted, sorties, flight time, horizontal length, the lowest and highest height
above the surface along the written paths (band) or the plane's worst height above the
ground (plane), the certified gaps, and the wall time. Figures of past runs are in
``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from support.band_sites import seeded_targets_csv

from urpt_gcs import PlanSettings, plan
from urpt_gcs.errors import UrptError

SITES = {"ecuador": "rbsf_ecuador_elev10m.tif", "arenal": "arenal_aster_wgs84.tif"}


def _row(name: str, mode: str, dem: Path, targets: Path, settings: PlanSettings) -> str:
    started = time.perf_counter()
    try:
        p = plan(dem, targets, settings)
    except UrptError as exc:
        return f"| {name} | {mode} | refused: {exc} |"
    wall = time.perf_counter() - started
    minutes = f"{int(p.flight_time_s // 60)} min {p.flight_time_s % 60:02.0f} s"
    bf = p.band_flight
    if bf is not None:
        heights = f"{bf.lowest_m:.1f}-{bf.highest_m:.1f} m over the surface"
        gap_t = (p.flight_time_s - bf.time_bound_s) / bf.time_bound_s * 100.0
        gaps = f"{p.flown_gap * 100:.1f} % (time {gap_t:.1f} %)"
        stops = f"{len(bf.stops_xyz)} ({bf.inserted} inserted)"
    else:
        assert p.tour.points_xy is not None
        ground = p.terrain.sample(p.tour.points_xy[:, 0], p.tour.points_xy[:, 1])
        worst = float(np.max(p.camera.altitude_m - ground))
        heights = f"up to {worst:.0f} m over the ground"
        gaps = f"{p.flown_gap * 100:.1f} %"
        stops = str(len(p.tour.order))
    return (
        f"| {name} | {mode} | {stops} | {len(p.sorties)} | {minutes} | "
        f"{p.flown_length_m / 1000:.2f} km | {heights} | {gaps} | {wall:.1f} s |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("dem_dir", type=Path)
    parser.add_argument("--targets", type=int, nargs="+", default=[20, 100])
    parser.add_argument("--endurance", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=1)
    a = parser.parse_args()
    print("| site | mode | stops | sorties | flight | horizontal | heights | gap | wall |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for site, file in SITES.items():
            dem = a.dem_dir / file
            for count in a.targets:
                targets = Path(tmp) / f"{site}{count}.csv"
                seeded_targets_csv(dem, count, a.seed, targets)
                base = dataclasses.replace(PlanSettings(), endurance_min=a.endurance)
                band = dataclasses.replace(base, agl_band_m=(30.0, 120.0))
                name = f"{site}, {count}"
                print(_row(name, "band 30:120", dem, targets, band), flush=True)
                print(_row(name, "plane", dem, targets, base), flush=True)


if __name__ == "__main__":
    main()
