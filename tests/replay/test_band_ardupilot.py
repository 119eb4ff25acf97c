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
pytestmark = [
    pytest.mark.sitl_real,
    pytest.mark.skipif(not os.access(BINARY, os.X_OK), reason=f"no ArduCopter SITL at {BINARY}"),
    needs_shared("dem/rbsf_ecuador_elev10m.tif"),
]


def _tracking_error_m(report_track: list[tuple[float, float, float]], path: np.ndarray) -> float:
    """The greatest 3-D distance of a fix (x, y, z) from the planned polyline (n, 3)."""
    a, b = path[:-1], path[1:]
    ab = b - a
    worst = 0.0
    for p in report_track:
        q = np.asarray(p)
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        d = np.linalg.norm(a + ab * t[:, None] - q, axis=1).min()
        worst = max(worst, float(d))
    return worst


@pytest.mark.xfail(
    reason="ArduCopter SITL did not land this plan within 600 s of wall time (first runs, "
    "undiagnosed): see the branch's report",
    strict=False,
)
def test_an_ecuador_band_plan_on_arducopter(tmp_path: Path) -> None:
    csv = tmp_path / "targets.csv"
    seeded_targets_csv(DEM, 8, seed=2, out=csv, window_m=1200.0)
    result = plan(
        DEM, csv, PlanSettings(agl_band_m=(FLOOR, CEILING), solve=SolveSettings(time_limit_s=2.0))
    )
    assert result.band_flight is not None and result.band_flight.inserted >= 1
    files = write_band_plan(result, tmp_path / "out")
    to_xy = pyproj.Transformer.from_crs("EPSG:4326", result.crs, always_xy=True)
    with launch(BINARY, result.missions[0].home, SPEEDUP) as sitl:
        assert "127.0.0.1" in sitl.url
        for k, (path, mission) in enumerate(zip(files, result.missions, strict=True)):
            started = time.monotonic()
            report = replay(
                DEM, csv, path, ReplaySettings(speedup=SPEEDUP, connect=sitl.url, timeout_s=600.0)
            )
            print(f"\n{report_text(report)}\n  wall {time.monotonic() - started:.1f} s")
            assert all(row.photo is not None for row in report.targets), report.problems
            assert report.band is not None
            # The firmware's tracking error: fixes away from home against the planned path.
            home = mission.home
            hx, hy = to_xy.transform(home.lon_deg, home.lat_deg)
            fixes = []
            for p in report.flight.track:
                x, y = to_xy.transform(p.lon_deg, p.lat_deg)
                if math.hypot(x - hx, y - hy) > HOME_RADIUS_M:
                    fixes.append((x, y, home.amsl_m + p.alt_rel_m))
            error = _tracking_error_m(fixes, result.band_flight.paths_xyz[k])
            print(
                f"  sortie {k + 1}: {result.band_flight.inserted} waypoints follow the terrain; "
                f"track {report.band.lowest_m:.2f} to {report.band.highest_m:.2f} m above the "
                f"surface, {report.band.below_m:.2f} m under the floor, "
                f"{report.band.above_m:.2f} m over the ceiling; tracking error up to "
                f"{error:.2f} m from the planned path"
            )
            assert report.band.below_m <= BAND_TRACKING_TOLERANCE_M
            assert report.band.above_m <= BAND_TRACKING_TOLERANCE_M
            assert report.ok, report.problems
