"""Plans inside a height band (``--agl``), checked independently on the written missions:
every target seen from a photo waypoint at its own altitude, every leg inside the band by
dense samples of the DSM (:mod:`support.independent`, which shares no code with urpt_gcs)."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO, REAL_DEMS, WriteDem, needs_shared
from support.band_sites import (
    RIDGE_CELL_M,
    RIDGE_ORIGIN,
    ridge_surface,
    ridge_targets_csv,
    seeded_targets_csv,
)
from support.independent import band_excursions, check_mission, read_waypoints_file

from urpt_gcs.cli import main
from urpt_gcs.files.formats import waypoints_text
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.solvers import SolveSettings

FLOOR, CEILING = 30.0, 120.0
FAST = SolveSettings(time_limit_s=2.0)
# Dense samples of a leg read the raster in its own CRS, along a straight line in latitude
# and longitude: where the planner works in a projected grid (a geographic raster is planned
# through a fitted affine map), heights may differ by this much.
SAMPLE_SLACK_M = 0.05


def write_missions(result: Plan, out: Path) -> list[Path]:
    """Each sortie's mission as ``mission_<k>.waypoints`` (the mission files alone)."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for k, mission in enumerate(result.missions, start=1):
        path = out / f"mission_{k}.waypoints"
        path.write_text(waypoints_text(mission), encoding="utf-8")
        files.append(path)
    return files


def check_band_plan(
    dem: Path, result: Plan, out: Path, targets: list[tuple[str, float, float]]
) -> tuple[float, float]:
    """The independent checks of a band plan; the lowest and highest height sampled."""
    files = write_missions(result, out)
    assert result.band_flight is not None
    assert check_mission(dem, files, targets, fov_deg=result.settings.fov_deg) == []
    # Photos only at the stops, each stop once, and every waypoint without one inserted.
    flown = [read_waypoints_file(f) for f in files]
    assert sum(len(f.photo_waypoints) for f in flown) == len(result.band_flight.stops_xyz)
    inserted = sum(len(f.waypoints) - len(f.photo_waypoints) for f in flown)
    # (each sortie's last waypoint is over home, without a photo)
    assert inserted == result.band_flight.inserted + len(files)
    excursions = band_excursions(dem, files, FLOOR, CEILING, slack_m=SAMPLE_SLACK_M)
    assert excursions.outside == []
    # The planner's exact extremes bound the samples (the samples can only miss the extreme).
    assert result.band_flight.lowest_m <= excursions.lowest_m + SAMPLE_SLACK_M
    assert result.band_flight.highest_m >= excursions.highest_m - SAMPLE_SLACK_M
    return excursions.lowest_m, excursions.highest_m


def test_ridge_and_valley_inside_the_band(tmp_path: Path, write_dem: WriteDem) -> None:
    dem = write_dem(ridge_surface(), res=RIDGE_CELL_M, origin=RIDGE_ORIGIN)
    csv = tmp_path / "targets.csv"
    targets = ridge_targets_csv(csv)
    started = time.monotonic()
    result = plan(dem, csv, PlanSettings(agl_band_m=(FLOOR, CEILING), solve=FAST))
    took = time.monotonic() - started
    low, high = check_band_plan(dem, result, tmp_path / "band", targets)
    assert result.band_flight is not None
    # No straight leg between two stops on either side of the ridge stays in the band:
    # the flight must have been bent to follow it.
    assert result.band_flight.inserted >= 1
    print(
        f"ridge: {took:.1f} s, {result.band_flight.inserted} inserted waypoints, "
        f"{len(result.missions)} sorties, {low:.2f} to {high:.2f} m above the surface"
    )
    # The same site on one constant plane flies far above the ceiling somewhere (over the
    # valley and the plain, with the plane above the crest): the reason for the band.
    flat = plan(dem, csv, PlanSettings(solve=FAST))
    files = write_missions(flat, tmp_path / "plane")
    assert check_mission(dem, files, targets, fov_deg=flat.settings.fov_deg) == []
    plane = band_excursions(dem, files, FLOOR, CEILING)
    assert plane.highest_m > CEILING
    assert plane.outside


def test_straight_legs_over_the_ridge_are_caught(tmp_path: Path, write_dem: WriteDem) -> None:
    """The dense check is able to fail: the band plan's missions with every waypoint that
    follows the terrain taken out leave the band over the ridge."""
    dem = write_dem(ridge_surface(), res=RIDGE_CELL_M, origin=RIDGE_ORIGIN)
    csv = tmp_path / "targets.csv"
    ridge_targets_csv(csv)
    result = plan(dem, csv, PlanSettings(agl_band_m=(FLOOR, CEILING), solve=FAST))
    files = write_missions(result, tmp_path / "band")
    stripped = []
    for path in files:
        lines = path.read_text().splitlines()
        keep = lines[:2]
        for k, line in enumerate(lines[2:], start=2):
            fields = line.split("\t")
            after = lines[k + 1].split("\t") if k + 1 < len(lines) else None
            waypoint = fields[3] == "16"
            photo = after is not None and after[3] in ("203", "2000")
            if not waypoint or photo:
                keep.append(line)
        renumbered = [keep[0]] + [
            "\t".join([str(seq), *line.split("\t")[1:]]) for seq, line in enumerate(keep[1:])
        ]
        out = tmp_path / "stripped" / path.name
        out.parent.mkdir(exist_ok=True)
        out.write_text("\n".join(renumbered) + "\n")
        stripped.append(out)
    assert band_excursions(dem, stripped, FLOOR, CEILING).outside


# (raster, the window the targets are drawn in): on Arenal's flanks a 3 km window puts
# stops more than the 20 minutes of the default endurance away from home.
MOUNTAINS = [
    pytest.param(
        "rbsf_ecuador_elev10m.tif", 3000.0, marks=needs_shared("dem/rbsf_ecuador_elev10m.tif")
    ),
    pytest.param(
        "arenal_aster_wgs84.tif", 2000.0, marks=needs_shared("dem/arenal_aster_wgs84.tif")
    ),
]


@pytest.mark.parametrize(("name", "window_m"), MOUNTAINS)
def test_real_mountains_inside_the_band(tmp_path: Path, name: str, window_m: float) -> None:
    _mountain(tmp_path, name, 20, window_m, 30.0)


# Mountain sites fly a 30-minute battery: at 20 minutes a stop far from home may not fit
# alone, with the climbs following the terrain to it and back.
@pytest.mark.parametrize("name", [p.values[0] for p in MOUNTAINS])
def test_real_mountains_at_100_targets_inside_the_band(tmp_path: Path, name: str) -> None:
    if not (REAL_DEMS / name).exists():
        pytest.skip(f"needs ../shared/dem/{name} (not present on this machine)")
    _mountain(tmp_path, name, 100, 3000.0, 30.0)


def _mountain(
    tmp_path: Path, name: str, count: int, window_m: float, endurance_min: float | None
) -> None:
    dem = REAL_DEMS / name
    csv = tmp_path / "targets.csv"
    targets = seeded_targets_csv(dem, count, seed=1, out=csv, window_m=window_m)
    settings = PlanSettings(agl_band_m=(FLOOR, CEILING), solve=FAST)
    if endurance_min is not None:
        settings = dataclasses.replace(settings, endurance_min=endurance_min)
    result = plan(dem, csv, settings)
    low, high = check_band_plan(dem, result, tmp_path / "out", targets)
    assert result.band_flight is not None
    # The flight flown is one of those the time bound is below, sorties and all.
    assert result.band_flight.time_bound_s <= result.flight_time_s
    # The sorties proven are no more than flown, and their horizontal bound (the returns
    # home included) no more than the horizontal length flown.
    cert = result.certificate
    assert cert is not None and cert.sorties is not None
    assert 1 <= cert.sorties.sorties <= len(result.missions)
    assert cert.lower_bound_m <= math.fsum(s.length_m for s in result.sorties) * (1 + 1e-9)
    print(
        f"{name}, {count} targets: {result.band_flight.inserted} inserted waypoints, "
        f"{len(result.missions)} sorties, {low:.2f} to {high:.2f} m above the surface"
    )


BAD_BANDS = [
    (["--agl", "120:30"], ["--agl", "floor must be below the ceiling"]),
    (["--agl", "x"], ["--agl", "FLOOR:CEILING"]),
    (["--agl", "30:120", "--altitude", "100"], ["--agl", "--altitude"]),
    (["--agl", "30:120", "--vehicles", "2"], ["--agl", "one vehicle"]),
]


@pytest.mark.parametrize(("args", "words"), BAD_BANDS)
def test_bad_band_settings(tmp_path: Path, args: list[str], words: list[str]) -> None:
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main,
        [
            "plan",
            "--dem",
            str(DEMO / "site.tif"),
            "--targets",
            str(DEMO / "targets.kml"),
            "--out",
            str(out),
            *args,
        ],
    )
    assert result.exit_code not in (0, None), result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("urpt-gcs: error: "), result.stderr
    assert "Traceback" not in result.stderr
    assert result.exception is None or isinstance(result.exception, SystemExit)
    for word in words:
        assert word in lines[0]
    assert not out.exists()
