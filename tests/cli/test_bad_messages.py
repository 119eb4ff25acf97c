"""Messages that must advise what the operator's own settings allow, in cases the catalogue
(test_bad_inputs.py) cannot reach from the command line alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyproj
import pytest
from click.testing import CliRunner
from conftest import DEMO, WriteDem

import urpt_gcs.pipeline.separation as separation
from urpt_gcs.cli import main


def _plan(out: Path, *args: str) -> tuple[int, str]:
    base = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    result = CliRunner().invoke(
        main, [*base, "--out", str(out), "--no-map", "--time-limit", "0.5", *args]
    )
    return result.exit_code, result.stderr


def test_a_clash_in_altitude_mode_advises_the_layers_not_altitude_mode(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # No start delay allowed: two vehicles from one home meet as they climb.
    monkeypatch.setattr(separation, "MAX_DELAY_SHARE", 0.0)
    code, stderr = _plan(tmp_path / "out", "--vehicles", "2", "--separation", "altitude")
    assert code == 1, stderr
    (line,) = stderr.strip().splitlines()
    assert "come within" in line
    assert line.endswith("or raise --layer-spacing")
    assert "--separation altitude" not in line
    assert not (tmp_path / "out").exists()


def test_a_replay_timeout_under_a_second_is_named_as_given() -> None:
    # It was printed rounded to whole seconds: "did not land within 0 s".
    args = [
        "sitl",
        "replay",
        "--dem",
        str(DEMO / "site.tif"),
        "--targets",
        str(DEMO / "targets.kml"),
        "--plan",
        str(Path(__file__).resolve().parents[1] / "data" / "demo_plan" / "mission.plan"),
        "--timeout",
        "0.5",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    (line,) = result.stderr.strip().splitlines()
    assert "did not land within 0.5 s of wall time" in line


# A site grid as a surveyor may export it: Transverse Mercator about the site, no EPSG code.
_SITE_GRID = "+proj=tmerc +lat_0=47 +lon_0=9.4 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m"


def test_a_dem_in_a_custom_crs_is_named_in_a_few_words(tmp_path: Path, write_dem: WriteDem) -> None:
    """Planned on a DEM in a CRS of no authority, the summary and summary.json name it in a
    few words; it was printed as its 900-character WKT."""
    rows, cols = np.mgrid[0:400, 0:400]
    z = 400.0 + 10.0 * np.sin(cols / 40.0) + 8.0 * np.cos(rows / 30.0)
    dem = write_dem(z, crs=_SITE_GRID, res=1.0, origin=(-200.0, 200.0))
    to_lon_lat = pyproj.Transformer.from_crs(_SITE_GRID, "EPSG:4326", always_xy=True)
    targets = tmp_path / "targets.csv"
    lines = ["name,lat,lon"]
    for k, (x, y) in enumerate([(-100, -100), (50, 80), (120, -60), (-60, 120)], start=1):
        lon, lat = to_lon_lat.transform(x, y)
        lines.append(f"T{k},{lat:.8f},{lon:.8f}")
    targets.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"

    args = ["plan", "--dem", str(dem), "--targets", str(targets), "--out", str(out)]
    result = CliRunner().invoke(main, [*args, "--no-map", "--time-limit", "0.5"])

    assert result.exit_code == 0, result.output
    (dem_line,) = [line for line in result.stdout.splitlines() if line.startswith("dem ")]
    assert dem_line.endswith("planned in a custom Transverse Mercator CRS"), dem_line
    assert max(len(line) for line in result.stdout.splitlines()) < 200
    summary = json.loads((out / "summary.json").read_text())
    dem_record = summary["dem"]
    assert dem_record["crs_name"] == dem_record["source_crs"] == "a custom Transverse Mercator CRS"
