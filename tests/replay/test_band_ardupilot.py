"""A plan inside a height band over the Ecuadorian Andes flown on ArduPilot's own ArduCopter
SITL (``../shared/ardupilot``, on 127.0.0.1, stopped by its pid when done): every target
photographed, the track inside the band within the firmware's tracking error, measured."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
import pyproj
import pytest
from conftest import REAL_DEMS, SHARED, needs_shared
from support.band_sites import seeded_targets_csv
from test_band_replay import write_band_plan

from urpt_gcs.flight.mission import RELATIVE_ALT_FRAMES, below_home, photo_positions
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.replay.ardupilot import launch
from urpt_gcs.replay.band_track import BAND_TRACKING_TOLERANCE_M, HOME_RADIUS_M
from urpt_gcs.replay.fly import ReplaySettings, replay
from urpt_gcs.replay.judge import report_text
from urpt_gcs.solvers import SolveSettings

BINARY = SHARED / "ardupilot" / "arducopter"
DEM = REAL_DEMS / "rbsf_ecuador_elev10m.tif"
SPEEDUP = 20.0
FLOOR, CEILING = 30.0, 120.0
# A small site on the slopes of the raster's centre: one sortie of about 10 min, five
# waypoints without a photo following the terrain.
TARGETS, WINDOW_M = 8, 800.0
pytestmark = [
    pytest.mark.sitl_real,
    pytest.mark.skipif(not os.access(BINARY, os.X_OK), reason=f"no ArduCopter SITL at {BINARY}"),
    needs_shared("dem/rbsf_ecuador_elev10m.tif"),
]


def _tracking_errors_m(
    fixes: list[tuple[float, float, float]], path: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each fix's (x, y, z) 3-D distance from the planned polyline (n, 3), and the height
    of the fix above (+) or below (-) the polyline's point nearest it."""
    a, b = path[:-1], path[1:]
    ab = b - a
    distance, vertical = [], []
    for p in fixes:
        q = np.asarray(p)
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        near = a + ab * t[:, None]
        k = int(np.linalg.norm(near - q, axis=1).argmin())
        distance.append(float(np.linalg.norm(near[k] - q)))
        vertical.append(float(q[2] - near[k, 2]))
    return np.asarray(distance), np.asarray(vertical)


def test_an_ecuador_band_plan_on_arducopter(tmp_path: Path) -> None:
    csv = tmp_path / "targets.csv"
    # Home at the lowest point of the window, every target uphill of it: ArduPilot's SITL
    # knows no terrain and holds the ground flat at home's altitude, so a waypoint below home
    # (the band over a valley writes them, down to -420 m over this raster's centre) is under
    # its ground, never reached, and the mission never ends.
    seeded_targets_csv(DEM, TARGETS, seed=3, out=csv, window_m=WINDOW_M, home_lowest=True)
    started = time.monotonic()
    result = plan(
        DEM, csv, PlanSettings(agl_band_m=(FLOOR, CEILING), solve=SolveSettings(time_limit_s=2.0))
    )
    print(f"\nplanned in {time.monotonic() - started:.1f} s wall")
    assert result.band_flight is not None and result.band_flight.inserted >= 1
    assert len(result.missions) == 1
    for mission in result.missions:
        heights = [item.z for item in mission.items if item.frame in RELATIVE_ALT_FRAMES]
        assert heights and min(heights) > 0.0, "a waypoint below home: SITL's ground is flat"
        assert not below_home(mission)
    files = write_band_plan(result, tmp_path / "out")
    to_xy = pyproj.Transformer.from_crs("EPSG:4326", result.crs, always_xy=True)
    with launch(BINARY, result.missions[0].home, SPEEDUP) as sitl:
        assert "127.0.0.1" in sitl.url
        for k, (path, mission) in enumerate(zip(files, result.missions, strict=True)):
            started = time.monotonic()
            report = replay(
                DEM, csv, path, ReplaySettings(speedup=SPEEDUP, connect=sitl.url, timeout_s=300.0)
            )
            print(f"\n{report_text(report)}\n  wall {time.monotonic() - started:.1f} s")
            assert all(row.photo is not None for row in report.targets), report.problems
            assert len(report.flight.photos) == len(photo_positions(mission))
            assert report.band is not None and report.band.judged > 0
            # The firmware's tracking: fixes away from home against the planned 3-D path.
            home = mission.home
            hx, hy = to_xy.transform(home.lon_deg, home.lat_deg)
            fixes = []
            for p in report.flight.track:
                x, y = to_xy.transform(p.lon_deg, p.lat_deg)
                if math.hypot(x - hx, y - hy) > HOME_RADIUS_M:
                    fixes.append((x, y, home.amsl_m + p.alt_rel_m))
            distance, vertical = _tracking_errors_m(fixes, result.band_flight.paths_xyz[k])
            print(
                f"  sortie {k + 1}: {len(report.flight.photos)} photos, "
                f"{result.band_flight.inserted} waypoints follow the terrain; track "
                f"{report.band.lowest_m:.2f} to {report.band.highest_m:.2f} m above the "
                f"surface over {report.band.judged} fixes, {report.band.below_m:.2f} m under "
                f"the floor, {report.band.above_m:.2f} m over the ceiling; from the planned "
                f"path up to {distance.max():.2f} m (95 % within "
                f"{np.percentile(distance, 95):.2f} m), in height up to "
                f"{np.abs(vertical).max():.2f} m (95 % within "
                f"{np.percentile(np.abs(vertical), 95):.2f} m)"
            )
            assert report.band.below_m <= BAND_TRACKING_TOLERANCE_M
            assert report.band.above_m <= BAND_TRACKING_TOLERANCE_M
            assert np.abs(vertical).max() <= BAND_TRACKING_TOLERANCE_M
            assert report.ok, report.problems
