"""A plan inside a height band flown end to end on the simulated copter through the replay
path, and judged: every target photographed from the altitude each photo was taken at, the
track inside the band at every fix away from home."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import WriteDem
from support.band_sites import RIDGE_CELL_M, RIDGE_ORIGIN, ridge_surface, ridge_targets_csv

from urpt_gcs.files.formats import waypoints_text
from urpt_gcs.flight.mission import photo_positions, waypoint_positions
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.replay.band_track import BAND_TRACKING_TOLERANCE_M
from urpt_gcs.replay.fly import ReplaySettings, replay
from urpt_gcs.replay.judge import expected_checks, judge, report_text
from urpt_gcs.solvers import SolveSettings

FLOOR, CEILING = 30.0, 120.0

__all__ = ["band_summary", "write_band_plan"]


def band_summary(result: Plan) -> dict[str, object]:
    """What the judge reads of a band plan's ``summary.json``: its camera, its stops (the
    photo waypoints) with what each sees, and the band."""
    names = [t.name for t in result.targets.targets]
    stops = []
    for number, (sortie, mission) in enumerate(
        zip(result.sorties, result.missions, strict=True), start=1
    ):
        positions = photo_positions(mission)
        assert len(positions) == sortie.stop - sortie.first
        for (lat, lon), k in zip(positions, range(sortie.first, sortie.stop), strict=True):
            stops.append(
                {
                    "order": k + 1,
                    "sortie": number,
                    "lat_deg": lat,
                    "lon_deg": lon,
                    "sees": [names[t] for t in np.flatnonzero(result.tour.sees[k]).tolist()],
                }
            )
    assert result.band_flight is not None
    return {
        "fov_deg": result.settings.fov_deg,
        "min_clearance_m": result.settings.min_clearance_m,
        "stops": stops,
        "sorties": [{"sortie": n} for n in range(1, len(result.missions) + 1)],
        "band": {
            "floor_m": result.band_flight.band.floor_m,
            "ceiling_m": result.band_flight.band.ceiling_m,
        },
    }


def write_band_plan(result: Plan, out: Path) -> list[Path]:
    """The missions as ``mission_<k>.waypoints`` and the summary beside them."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for k, mission in enumerate(result.missions, start=1):
        path = out / f"mission_{k}.waypoints"
        path.write_text(waypoints_text(mission), encoding="utf-8")
        files.append(path)
    (out / "summary.json").write_text(json.dumps(band_summary(result)), encoding="utf-8")
    return files


@pytest.fixture
def ridge_plan(tmp_path: Path, write_dem: WriteDem) -> tuple[Path, Path, Plan, list[Path]]:
    dem = write_dem(ridge_surface(), res=RIDGE_CELL_M, origin=RIDGE_ORIGIN)
    csv = tmp_path / "targets.csv"
    ridge_targets_csv(csv)
    result = plan(
        dem, csv, PlanSettings(agl_band_m=(FLOOR, CEILING), solve=SolveSettings(time_limit_s=2.0))
    )
    return dem, csv, result, write_band_plan(result, tmp_path / "out")


def test_a_band_plan_flown_on_the_simulated_copter(
    ridge_plan: tuple[Path, Path, Plan, list[Path]],
) -> None:
    dem, csv, result, files = ridge_plan
    assert result.band_flight is not None and result.band_flight.inserted >= 1
    (path,) = files
    mission = result.missions[0]
    # The terrain-following waypoints are flown through, but the summary's stops are the photos.
    assert len(waypoint_positions(mission)) > len(photo_positions(mission))
    report = replay(dem, csv, path, ReplaySettings(speedup=200.0))
    text = report_text(report)
    print("\n" + text)
    assert report.ok, report.problems
    assert report.expected.band == (FLOOR, CEILING)
    assert "summary.json for mission_1.waypoints" in report.expected.source
    assert not report.expected.warnings
    assert all(row.photo is not None for row in report.targets)
    assert len(report.targets) == len(result.targets.targets)
    assert report.band is not None and report.band.judged > 0
    assert report.band.below_m <= BAND_TRACKING_TOLERANCE_M
    assert report.band.above_m <= BAND_TRACKING_TOLERANCE_M
    assert "band      30:120 m: track" in text
    # The photos were judged at the altitudes they were taken at, which differ.
    heights = {round(p.alt_rel_m) for p in report.flight.photos}
    assert len(heights) > 1

    # The same flight judged lower: the band check fails it, naming the floor.
    lowered = dataclasses.replace(
        report.flight,
        track=tuple(
            dataclasses.replace(p, alt_rel_m=p.alt_rel_m - (report.band.lowest_m - FLOOR) - 3.0)
            for p in report.flight.track
        ),
    )
    worse = judge(lowered, mission, dem, csv, report.expected, str(path))
    assert worse.band is not None
    assert worse.band.below_m == pytest.approx(3.0, abs=1e-6)
    assert not worse.ok
    assert any("under the band's floor 30 m" in p for p in worse.problems)
    # ... and as a plan on one plane (no band in the summary) it is not judged against one.
    plane = dataclasses.replace(report.expected, band=None)
    assert judge(lowered, mission, dem, csv, plane, str(path)).band is None


def test_a_summary_with_a_bad_band_warns(
    ridge_plan: tuple[Path, Path, Plan, list[Path]],
) -> None:
    _dem, _csv, result, files = ridge_plan
    summary_path = files[0].parent / "summary.json"
    data = json.loads(summary_path.read_text())
    data["band"] = {"floor_m": 120, "ceiling_m": "thirty"}
    summary_path.write_text(json.dumps(data))
    expected = expected_checks(files[0], result.missions[0], None, None)
    assert expected.band is None
    assert any("no usable height band" in w for w in expected.warnings)
    data.pop("band")
    summary_path.write_text(json.dumps(data))
    expected = expected_checks(files[0], result.missions[0], None, None)
    assert expected.band is None and not expected.warnings
