"""The command line: bad input gives one clear line, exit 1 and no output files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyproj
import pytest
from click.testing import CliRunner
from conftest import WriteDem

from urpt_gcs.cli import main

ORIGIN = (500_000.0, 5_200_000.0)
TO_GEO = pyproj.Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)


def _latlon(x: float, y: float) -> tuple[float, float]:
    lon, lat = TO_GEO.transform(x, y)
    return lat, lon


def _csv(path: Path, points: list[tuple[str, float, float]]) -> Path:
    path.write_text("name,lat,lon\n" + "".join(f"{n},{a:.9f},{b:.9f}\n" for n, a, b in points))
    return path


@pytest.fixture
def site(tmp_path: Path, write_dem: WriteDem) -> dict[str, Path]:
    """A 100 m x 100 m flat field at 300 m with a nodata strip along the west edge."""
    z = np.full((200, 200), 300.0)
    z[:, :20] = -10000.0
    dem = write_dem(z, res=0.5, origin=ORIGIN)
    inside = [
        ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
        ("B", *_latlon(ORIGIN[0] + 70, ORIGIN[1] - 60)),
        ("Home", *_latlon(ORIGIN[0] + 50, ORIGIN[1] - 90)),
    ]
    return {"dem": dem, "targets": _csv(tmp_path / "t.csv", inside), "tmp": tmp_path}


def _run(args: list[str]):
    return CliRunner().invoke(main, args)


def _assert_clean_failure(result, out: Path, *words: str) -> None:
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists(), "a failed run left output behind"


def test_good_run_writes_every_output(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
            "--json",
        ]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["targets"] == 2
    assert data["home"]["source"] == "placemark 'Home'"
    assert sorted(p.name for p in out.iterdir()) == [
        "map.png",
        "mission.plan",
        "mission.waypoints",
        "plan.geojson",
        "plan.kml",
        "summary.json",
    ]
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_home_flag_overrides_and_missing_home_is_reported(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    lat, lon = _latlon(ORIGIN[0] + 60, ORIGIN[1] - 20)
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
            "--json",
            "--home",
            f"{lat},{lon}",
        ]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["home"]["source"] == "--home"
    assert data["home"]["lat_deg"] == pytest.approx(lat, abs=1e-7)
    no_home = _csv(
        site["tmp"] / "nohome.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("B", *_latlon(ORIGIN[0] + 70, ORIGIN[1] - 60)),
        ],
    )
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(no_home),
            "--out",
            str(site["tmp"] / "out2"),
            "--time-limit",
            "0.5",
        ]
    )
    assert result.exit_code == 0, result.output
    assert "centroid of the targets" in result.stdout


def test_missing_dem(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    result = _run(
        ["plan", "--dem", "nowhere.tif", "--targets", str(site["targets"]), "--out", str(out)]
    )
    _assert_clean_failure(result, out, "nowhere.tif", "--dem")


def test_dem_that_is_not_a_raster(site: dict[str, Path]) -> None:
    bogus = site["tmp"] / "notes.tif"
    bogus.write_text("these are not elevations\n")
    out = site["tmp"] / "out"
    result = _run(
        ["plan", "--dem", str(bogus), "--targets", str(site["targets"]), "--out", str(out)]
    )
    _assert_clean_failure(result, out, "notes.tif", "not a readable raster")


def test_dem_without_crs(site: dict[str, Path], write_dem: WriteDem) -> None:
    dem = write_dem(np.full((50, 50), 10.0), name="nocrs.tif", crs=None)
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(dem), "--targets", str(site["targets"]), "--out", str(out)])
    _assert_clean_failure(result, out, "nocrs.tif", "coordinate reference system")


def test_all_nodata_dem(site: dict[str, Path], write_dem: WriteDem) -> None:
    dem = write_dem(np.full((200, 200), -9999.0), name="empty.tif", nodata=-9999.0, origin=ORIGIN)
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(dem), "--targets", str(site["targets"]), "--out", str(out)])
    _assert_clean_failure(result, out, "empty.tif", "no elevation")


def test_target_outside_the_dem(site: dict[str, Path]) -> None:
    far = _csv(
        site["tmp"] / "far.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("Far", *_latlon(ORIGIN[0] + 900, ORIGIN[1] - 40)),
        ],
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(far), "--out", str(out)])
    _assert_clean_failure(result, out, "Far", "outside DEM")


def test_target_on_nodata(site: dict[str, Path]) -> None:
    hole = _csv(
        site["tmp"] / "hole.csv",
        [
            ("A", *_latlon(ORIGIN[0] + 40, ORIGIN[1] - 40)),
            ("Hole", *_latlon(ORIGIN[0] + 3, ORIGIN[1] - 40)),
        ],
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(hole), "--out", str(out)])
    _assert_clean_failure(result, out, "Hole", "nodata")


def test_target_file_without_points(site: dict[str, Path]) -> None:
    kml = site["tmp"] / "lines.kml"
    kml.write_text(
        '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2"><Document>'
        "<Placemark><name>road</name><LineString><coordinates>8,47 8.1,47.1</coordinates>"
        "</LineString></Placemark></Document></kml>"
    )
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(kml), "--out", str(out)])
    _assert_clean_failure(result, out, "lines.kml", "no Point")


def test_malformed_kml(site: dict[str, Path]) -> None:
    kml = site["tmp"] / "broken.kml"
    kml.write_text('<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark>')
    out = site["tmp"] / "out"
    result = _run(["plan", "--dem", str(site["dem"]), "--targets", str(kml), "--out", str(out)])
    _assert_clean_failure(result, out, "broken.kml", "XML")


def test_altitude_at_or_below_terrain(site: dict[str, Path]) -> None:
    out = site["tmp"] / "out"
    for altitude in ("300", "250"):
        result = _run(
            [
                "plan",
                "--dem",
                str(site["dem"]),
                "--targets",
                str(site["targets"]),
                "--out",
                str(out),
                "--altitude",
                altitude,
            ]
        )
        _assert_clean_failure(result, out, "--altitude", "terrain")


@pytest.mark.parametrize("fov", ["0", "90", "-5", "120", "nan"])
def test_fov_outside_range(site: dict[str, Path], fov: str) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--fov",
            fov,
        ]
    )
    _assert_clean_failure(result, out, "--fov", "(0, 90)")


@pytest.mark.parametrize("samples", ["2", "0", "-4"])
def test_too_few_samples(site: dict[str, Path], samples: str) -> None:
    out = site["tmp"] / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--samples",
            samples,
        ]
    )
    _assert_clean_failure(result, out, "--samples", "at least 3")


def test_unwritable_output_leaves_nothing(site: dict[str, Path]) -> None:
    blocker = site["tmp"] / "file"
    blocker.write_text("x")
    out = blocker / "out"
    result = _run(
        [
            "plan",
            "--dem",
            str(site["dem"]),
            "--targets",
            str(site["targets"]),
            "--out",
            str(out),
            "--time-limit",
            "0.5",
        ]
    )
    _assert_clean_failure(result, out, "--out")


def test_stage_progress_ticks_only_for_slow_stages() -> None:
    import io
    import time

    from urpt_gcs.progress import StageProgress

    stream = io.StringIO()
    with StageProgress(stream, time_limit_s=2.0) as progress:
        progress("reading targets")  # fast: nothing shown
        progress("solving (10 viewpoints)")
        time.sleep(1.4)
    text = stream.getvalue()
    assert "reading targets" not in text
    assert "solving (10 viewpoints)" in text and "of 2 s" in text
