"""Benchmark: how far inside the camera's view each stop's whole tolerance disc lies.

    .venv/bin/python benchmarks/tolerance_ring.py [--time-limit S] [--count N] [--dem-dir D]

Plans the demo (defaults, ``--position-tolerance 5`` and a frame camera), the real rasters
beside the checkout (``--count`` targets each, placed as the tests place them) and the two
mountain rasters (``--count`` seeded targets in 3 km around the centre, ``--endurance 30``, as
``band_mountains.py`` plans them) on one flight plane, and measures every written stop
against every target it is counted for: the margin of the continuous disc of
``--position-tolerance`` around the waypoint as written (1e-7 degree grid, the height above
home as written over home as written) against the boundary of what a photo holds,
``R - d - r`` for the cone (and the GSD distance), and for a frame the least of that and
``a - |u| - r``, ``b - |v| - r`` in the frame's axes at the written heading. Negative: part
of the disc leaves the picture. Terrain (line of sight) is not part of the margin. The
figures use the planner's ground heights and CRS but none of its checks, so the script
measures an older version too (``PYTHONPATH=old/tree``).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.band_sites import seeded_targets_csv  # noqa: E402
from support.targets import REAL_CASES, valid_targets  # noqa: E402

from urpt_gcs.flight.mission import photo_headings, photo_positions  # noqa: E402
from urpt_gcs.pipeline.area import latlon_to_xy  # noqa: E402
from urpt_gcs.pipeline.planner import plan  # noqa: E402
from urpt_gcs.pipeline.result import Plan  # noqa: E402
from urpt_gcs.pipeline.settings import PlanSettings  # noqa: E402
from urpt_gcs.site.camera import CAMERAS, grid_bearing_deg  # noqa: E402
from urpt_gcs.solvers import SolveSettings  # noqa: E402

# The stages whose times are printed (the others do not check the ring).
STAGES = ("margin", "refine", "sorties", "checks", "bound's tour")
# The mountain rasters, planned on the plane here (band_mountains.py follows the terrain).
MOUNTAINS = ("rbsf_ecuador_elev10m.tif", "arenal_aster_wgs84.tif")


@dataclass(frozen=True)
class Margins:
    """Per (stop, target counted at it): the disc's margin (metres) and the stop."""

    margin_m: np.ndarray
    stop: np.ndarray
    stops: int


def disc_margins(result: Plan) -> Margins:
    """The margin of every written stop's tolerance disc for every target it counts."""
    cam = result.camera
    r = result.settings.position_tolerance_m
    latlon = [p for mission in result.missions for p in photo_positions(mission)]
    xy = latlon_to_xy(result.crs, latlon)
    mission = result.missions[0]
    eye_m = mission.home.amsl_m + mission.altitude_rel_m
    stop, target = np.nonzero(result.tour.sees)
    dx = result.targets_xy[target, 0] - xy[stop, 0]
    dy = result.targets_xy[target, 1] - xy[stop, 1]
    h = eye_m - result.ground_m[target]
    reach = h * math.tan(math.radians(cam.fov_deg))
    far = cam.max_distance_m
    if math.isfinite(far):
        reach = np.minimum(reach, np.sqrt(np.maximum(far * far - h * h, 0.0)))
    margin = reach - np.hypot(dx, dy) - r
    if cam.frame is not None:
        true = [a for m in result.missions for a in (photo_headings(m) or [])]
        psi = np.radians(grid_bearing_deg(result.crs, xy, np.asarray(true))[stop])
        along = dx * np.sin(psi) + dy * np.cos(psi)
        across = dx * np.cos(psi) - dy * np.sin(psi)
        margin = np.minimum(margin, h * cam.frame.half_tan_across - np.abs(across) - r)
        margin = np.minimum(margin, h * cam.frame.half_tan_along - np.abs(along) - r)
    return Margins(margin, stop, len(xy))


def run(name: str, dem: Path, targets: Path, settings: PlanSettings) -> None:
    started = time.perf_counter()
    result = plan(dem, targets, settings)
    wall = time.perf_counter() - started
    if result.band_flight is not None:
        print(f"{name:40s} follows the terrain: not measured here")
        return
    m = disc_margins(result)
    leaving = m.margin_m < 0.0
    worst = float(m.margin_m.min()) if m.margin_m.size else math.nan
    times = "  ".join(f"{s} {result.timings_s[s]:5.2f} s" for s in STAGES if s in result.timings_s)
    print(
        f"{name:40s} tolerance {settings.position_tolerance_m:g} m  stops {m.stops:3d}  "
        f"pairs {m.margin_m.size:3d}  leaving {int(leaving.sum()):3d} "
        f"(stops {np.unique(m.stop[leaving]).size:2d})  worst margin {100.0 * worst:7.2f} cm  "
        f"flown {result.flown_length_m:8.1f} m"
    )
    print(f"{'':40s} {times}  wall {wall:6.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time-limit", type=float, default=5.0, help="solver seconds")
    parser.add_argument("--count", type=int, default=30, help="targets per real raster")
    parser.add_argument(
        "--dem-dir",
        type=Path,
        default=REPO.parent / "shared" / "dem",
        help="the real rasters (skipped where absent)",
    )
    parser.add_argument("--demo-only", action="store_true", help="skip the real rasters")
    args = parser.parse_args()
    solve = SolveSettings(time_limit_s=args.time_limit)
    demo_dem, demo_targets = REPO / "missions/demo/site.tif", REPO / "missions/demo/targets.kml"
    run("demo", demo_dem, demo_targets, PlanSettings(solve=solve))
    run("demo", demo_dem, demo_targets, PlanSettings(solve=solve, position_tolerance_m=5.0))
    frame = CAMERAS["phantom4rtk"].frame
    run("demo, phantom4rtk frame", demo_dem, demo_targets, PlanSettings(solve=solve, frame=frame))
    if args.demo_only:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for name, _, box in REAL_CASES:
            dem = args.dem_dir / name
            if not dem.exists():
                print(f"{name}: not found in {args.dem_dir}")
                continue
            pts = valid_targets(dem, args.count, seed=3, box_m=box)
            csv = Path(tmp) / f"{name}.csv"
            csv.write_text("name,lat,lon\n" + "".join(f"{n},{a:.9f},{b:.9f}\n" for n, a, b in pts))
            run(f"{name}, {args.count}", dem, csv, PlanSettings(solve=solve))
        for name in MOUNTAINS:
            dem = args.dem_dir / name
            if not dem.exists():
                print(f"{name}: not found in {args.dem_dir}")
                continue
            csv = Path(tmp) / f"{name}.csv"
            seeded_targets_csv(dem, args.count, 1, csv)
            settings = PlanSettings(solve=solve, endurance_min=30.0)
            run(f"{name}, {args.count}", dem, csv, settings)


if __name__ == "__main__":
    main()
