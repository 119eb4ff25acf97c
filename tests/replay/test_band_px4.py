"""A plan inside a height band over the Ecuadorian Andes flown on PX4's own SITL (the SIH
quadrotor in ``../shared/px4``, started on 127.0.0.1 in a scratch folder by the replay and
stopped by its pid): every target photographed (the judge, from CAMERA_IMAGE_CAPTURED), the
track inside the band within the firmware's tracking error, measured against the planned path.

SIH simulates FLAT ground at the home altitude. A band plan over a valley writes waypoints
below home (a negative height above home), which the simulated vehicle can never reach: it
would land on SIH's ground there instead. The site is therefore a window on a slope with home
at its lowest cell and every target uphill, and the test first asserts that every written
height above home is positive.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pyproj
import pytest
from conftest import REAL_DEMS, SHARED, needs_shared
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.band_sites import cell_targets_csv

from urpt_gcs.files.products import write_products
from urpt_gcs.flight.mission import MissionSettings, photo_positions
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.replay.band_track import BAND_TRACKING_TOLERANCE_M, HOME_RADIUS_M
from urpt_gcs.replay.fly import ReplaySettings, read_mission, replay
from urpt_gcs.replay.judge import report_text
from urpt_gcs.solvers import SolveSettings

PX4 = SHARED / "px4"
DEM = REAL_DEMS / "rbsf_ecuador_elev10m.tif"
SPEEDUP = 10.0  # PX4's photo messages were all received at 10x on 2 cores (test_real_px4)
FLOOR, CEILING = 30.0, 120.0
# (row, column) cells of the raster. Home is the lowest cell of the 500 m window rows 80-129,
# columns 160-209 (2048.6 m; the window rises to about 200 m above it to the south-east); the
# six targets lie uphill inside it, 110 m or more from its edges on home's side, so every stop
# and every leg is over ground no lower than home (outside the window the valleys fall more
# than 100 m below it). The tour climbs out over one waypoint without a photo and comes back
# down over another, to the last waypoint over home, from which PX4's RTL lands.
HOME_CELL = (80, 160)
TARGET_CELLS = ((115, 203), (121, 187), (123, 205), (124, 171), (105, 191), (98, 182))
# How closely PX4 SITL keeps to the planned 3-D path away from home (first runs: at most
# 1.2 m in height and 1.4 m in 3-D, 95 % of fixes within 0.5 m and 1.0 m), with a margin.
ALTITUDE_TRACKING_M = 2.0
PATH_TRACKING_M = 3.0
pytestmark = [
    pytest.mark.sitl_real,
    pytest.mark.skipif(
        not (PX4 / "run.sh").is_file(), reason=f"no PX4 SITL build (run.sh) in {PX4}"
    ),
    needs_shared("dem/rbsf_ecuador_elev10m.tif"),
]


def _path_errors_m(fixes: np.ndarray, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each fix's (n, 3) offset from the nearest point of the planned polyline ``path``
    (m, 3): its 3-D length, and its vertical part (the fix above the path, positive).

    The vertical part is taken at the nearest point in 3-D, not below the fix: where the path
    climbs or drops steeply (over a waypoint without a photo right beside a stop) a fix half a
    metre aside would otherwise be metres above or below the path."""
    a, b = path[:-1], path[1:]
    ab = b - a
    length = np.empty(len(fixes))
    up = np.empty(len(fixes))
    for i, q in enumerate(fixes):
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        offsets = q - (a + ab * t[:, None])
        k = int(np.argmin(np.linalg.norm(offsets, axis=1)))
        length[i] = np.linalg.norm(offsets[k])
        up[i] = offsets[k, 2]
    return length, up


def test_an_ecuador_band_plan_on_px4(tmp_path: Path) -> None:
    csv = tmp_path / "targets.csv"
    targets = cell_targets_csv(DEM, HOME_CELL, TARGET_CELLS, csv)
    result = plan(
        DEM,
        csv,
        PlanSettings(
            agl_band_m=(FLOOR, CEILING),
            solve=SolveSettings(time_limit_s=2.0),
            mission=MissionSettings(firmware="px4"),
        ),
    )
    assert result.band_flight is not None and result.band_flight.inserted >= 1
    (planned,) = result.missions  # one sortie
    # The products `urpt-gcs plan --agl 30:120 --firmware px4` writes: mission.plan (a
    # .waypoints file cannot say it is PX4's, nor carry the gimbal command's NaN rates) and the
    # summary.json beside it, whose "band" the judge reads.
    write_products(result, tmp_path / "out", with_map=False)
    path = tmp_path / "out" / "mission.plan"
    assert result.flight_time_s < 600.0, "well under any endurance"

    # SIH's ground is flat at home's altitude: a waypoint below home (a valley's) could never
    # be reached. Every written height above home, the take-off's included, is positive.
    mission = read_mission(path)
    assert mission.firmware == "px4"
    located = [
        item
        for item in mission.items
        if item.command in (mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_WAYPOINT)
    ]
    heights = [item.params[6] for item in located]
    assert all(item.frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT for item in located)
    assert min(heights) > 0.0, heights
    stops = photo_positions(mission)
    assert len(located) - 1 > len(stops), "waypoints without a photo follow the terrain"

    started = time.monotonic()
    report = replay(DEM, csv, path, ReplaySettings(speedup=SPEEDUP, px4=PX4))
    wall_s = time.monotonic() - started
    print(f"\n{report_text(report)}")
    assert report.expected.band == (FLOOR, CEILING)
    flight = report.flight
    assert flight.upload.autopilot == "px4"
    assert len(report.targets) == len(targets)
    assert all(row.photo is not None for row in report.targets), report.problems
    assert sorted(p.index for p in flight.photos) == list(range(len(stops))), "one photo a stop"
    # Each photo beside its stop, at the stop's own height above home.
    stop_heights = [
        item.params[6]
        for item in located
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT and item.params[0] > 0.0
    ]
    photos = sorted(flight.photos, key=lambda p: p.index)
    photo_dz = [p.alt_rel_m - h for p, h in zip(photos, stop_heights, strict=True)]
    assert max(map(abs, photo_dz)) <= ALTITUDE_TRACKING_M, photo_dz

    # RTL from over home (the last waypoint): landed there.
    last = flight.track[-1]
    lx, ly = pyproj.Transformer.from_crs("EPSG:4326", result.crs, always_xy=True).transform(
        last.lon_deg, last.lat_deg
    )
    hx, hy = pyproj.Transformer.from_crs("EPSG:4326", result.crs, always_xy=True).transform(
        planned.home.lon_deg, planned.home.lat_deg
    )
    assert math.hypot(lx - hx, ly - hy) < 2.0 and abs(last.alt_rel_m) < 1.0, "landed at home"

    # The band against our DSM, the fixes over home (take-off, landing) left out.
    assert report.band is not None
    assert report.band.judged > 100
    assert report.band.below_m <= BAND_TRACKING_TOLERANCE_M
    assert report.band.above_m <= BAND_TRACKING_TOLERANCE_M

    # The tracking error against the planned 3-D path, away from home.
    to_xy = pyproj.Transformer.from_crs("EPSG:4326", result.crs, always_xy=True)
    home = planned.home
    hx, hy = to_xy.transform(home.lon_deg, home.lat_deg)
    fixes = []
    for p in flight.track:
        x, y = to_xy.transform(p.lon_deg, p.lat_deg)
        if math.hypot(x - hx, y - hy) > HOME_RADIUS_M:
            fixes.append((x, y, home.amsl_m + p.alt_rel_m))
    dist3, dz = _path_errors_m(np.asarray(fixes), result.band_flight.paths_xyz[0])
    print(
        f"  {result.band_flight.inserted} waypoints follow the terrain; written heights "
        f"{min(heights):.2f} to {max(heights):.2f} m above home; track "
        f"{report.band.lowest_m:.2f} to {report.band.highest_m:.2f} m above the surface, "
        f"{report.band.below_m:.2f} m under the floor, {report.band.above_m:.2f} m over the "
        f"ceiling; altitude error max {np.abs(dz).max():.2f} m, 95th percentile "
        f"{np.percentile(np.abs(dz), 95):.2f} m (mean {dz.mean():+.2f} m); 3-D distance from "
        f"the path max {dist3.max():.2f} m, 95th percentile {np.percentile(dist3, 95):.2f} m; "
        f"{len(flight.photos)} photos, up to {max(map(abs, photo_dz)):.2f} m off their stops' "
        f"heights; {len(fixes)} fixes; simulated {flight.sim_time_s:.0f} s, "
        f"wall {wall_s:.1f} s"
    )
    assert np.abs(dz).max() <= ALTITUDE_TRACKING_M
    assert dist3.max() <= PATH_TRACKING_M
    assert report.ok, report.problems
