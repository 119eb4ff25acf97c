"""The bad-input catalogue: every sample in tests/data/bad/ named after the failure it causes.

Each case: exit status 1, exactly one line on stderr naming the input and what to do, no
traceback, and nothing written to the output folder.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main

BAD = Path(__file__).resolve().parent / "data" / "bad"
SITE = str(DEMO / "site.tif")
TARGETS = str(DEMO / "targets.kml")

# name: (arguments after `urpt-gcs plan`, words the message must contain)
PLAN_CASES: dict[str, tuple[list[str], list[str]]] = {
    "dem_absent": (["--dem", str(BAD / "dem_absent.tif")], ["dem_absent.tif", "does not exist"]),
    "dem_empty": (["--dem", str(BAD / "dem_empty.tif")], ["dem_empty.tif", "GeoTIFF"]),
    "dem_truncated": (["--dem", str(BAD / "dem_truncated.tif")], ["dem_truncated.tif"]),
    "dem_not_a_raster": (
        ["--dem", str(BAD / "dem_not_a_raster.tif")],
        ["dem_not_a_raster.tif", "not a readable raster"],
    ),
    "dem_is_a_folder": (["--dem", str(BAD)], ["is a folder"]),
    "dem_without_crs": (
        ["--dem", str(BAD / "dem_without_crs.tif")],
        ["dem_without_crs.tif", "coordinate reference system"],
    ),
    "dem_all_nodata": (
        ["--dem", str(BAD / "dem_all_nodata.tif")],
        ["dem_all_nodata.tif", "no elevation"],
    ),
    "dem_rotated": (["--dem", str(BAD / "dem_rotated.tif")], ["dem_rotated.tif", "north-up"]),
    "dem_geographic_across_utm_zones": (
        [
            "--dem",
            str(BAD / "dem_geographic_across_utm_zones.tif"),
            "--targets",
            str(BAD / "dem_geographic_across_utm_zones.csv"),
        ],
        ["dem_geographic_across_utm_zones.tif", "UTM zones"],
    ),
    "targets_absent": (
        ["--targets", str(BAD / "targets_absent.kml")],
        ["targets_absent.kml", "does not exist"],
    ),
    "targets_outside_dem": (
        ["--targets", str(BAD / "targets_outside_dem.csv")],
        ["Far away", "outside DEM"],
    ),
    "targets_on_nodata": (
        ["--targets", str(BAD / "targets_on_nodata.csv")],
        ["Unsurveyed corner", "nodata"],
    ),
    "duplicate_targets": (
        ["--targets", str(BAD / "duplicate_targets.kml")],
        ["duplicate_targets.kml", "same place"],
    ),
    "empty_kml": (["--targets", str(BAD / "empty.kml")], ["empty.kml", "empty"]),
    "kml_malformed": (
        ["--targets", str(BAD / "kml_malformed.kml")],
        ["kml_malformed.kml", "well-formed"],
    ),
    "kml_entity_expansion": (
        ["--targets", str(BAD / "kml_entity_expansion.kml")],
        ["kml_entity_expansion.kml", "entity"],
    ),
    "kml_external_entity": (
        ["--targets", str(BAD / "kml_external_entity.kml")],
        ["kml_external_entity.kml", "entity"],
    ),
    "kml_no_points": (
        ["--targets", str(BAD / "kml_no_points.kml")],
        ["kml_no_points.kml", "no Point"],
    ),
    "kmz_without_kml": (
        ["--targets", str(BAD / "kmz_without_kml.kmz")],
        ["kmz_without_kml.kmz", "without a .kml"],
    ),
    "kmz_not_a_zip": (["--targets", str(BAD / "kmz_not_a_zip.kmz")], ["kmz_not_a_zip.kmz", "zip"]),
    "geojson_polygons_only": (
        ["--targets", str(BAD / "geojson_polygons_only.geojson")],
        ["geojson_polygons_only.geojson", "no Point"],
    ),
    "csv_missing_column": (
        ["--targets", str(BAD / "csv_missing_column.csv")],
        ["csv_missing_column.csv", "'lon' column"],
    ),
    "csv_non_numeric": (
        ["--targets", str(BAD / "csv_non_numeric.csv")],
        ["csv_non_numeric.csv", "not a number"],
    ),
    "csv_nan_lat": (["--targets", str(BAD / "csv_nan_lat.csv")], ["csv_nan_lat.csv", "nan"]),
    "csv_lat_out_of_range": (
        ["--targets", str(BAD / "csv_lat_out_of_range.csv")],
        ["csv_lat_out_of_range.csv", "[-90, 90]"],
    ),
    "kml_lon_out_of_range": (
        ["--targets", str(BAD / "kml_lon_out_of_range.kml")],
        ["kml_lon_out_of_range.kml", "[-180, 180]"],
    ),
    "two_homes": (["--targets", str(BAD / "two_homes.kml")], ["two_homes.kml", "two homes"]),
    "only_home": (["--targets", str(BAD / "only_home.kml")], ["only_home.kml", "no targets"]),
    "unknown_extension": (
        ["--targets", str(BAD / "unknown_extension.txt")],
        ["unknown_extension.txt", ".kml"],
    ),
    "altitude_under_terrain": (["@altitude_under_terrain.args"], ["--altitude", "terrain"]),
    "fov_zero": (["@fov_zero.args"], ["--fov", "(0, 90)"]),
    "fov_90": (["@fov_90.args"], ["--fov", "(0, 90)"]),
    "samples_2": (["@samples_2.args"], ["--samples", "at least 3"]),
    "output_folder_is_a_file": (
        ["--out", str(BAD / "output_folder_is_a_file")],
        ["output_folder_is_a_file", "--out"],
    ),
    "seed_negative": (["@seed_negative.args"], ["--seed -1", "0 to 4294967295"]),
}


def _expand(args: list[str]) -> list[str]:
    out: list[str] = []
    for arg in args:
        if arg.startswith("@"):
            out += (BAD / arg[1:]).read_text().split()
        else:
            out.append(arg)
    return out


def run_case(args: list[str], out: Path) -> tuple[int, str]:
    """Run `urpt-gcs plan` with the demo site's inputs overridden by ``args``."""
    full = [
        "plan",
        "--dem",
        SITE,
        "--targets",
        TARGETS,
        "--out",
        str(out),
        "--time-limit",
        "0.5",
        "--no-map",
        *_expand(args),
    ]
    result = CliRunner().invoke(main, full)
    return result.exit_code, result.stderr


@pytest.mark.parametrize("case", sorted(PLAN_CASES))
def test_bad_input(case: str, tmp_path: Path) -> None:
    args, words = PLAN_CASES[case]
    out = tmp_path / "out"
    before = sorted(p.name for p in BAD.iterdir())
    code, stderr = run_case(args, out)
    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists()
    assert sorted(p.name for p in BAD.iterdir()) == before, "a sample folder was written to"


# name: (the file given to `urpt-gcs upload`, words the message must contain). The file is
# checked before any connection is tried.
UPLOAD_CASES: dict[str, tuple[str, list[str]]] = {
    "upload_not_a_plan": ("upload_not_a_plan.plan", ["upload_not_a_plan.plan", "JSON"]),
    "upload_unsupported_item": (
        "upload_unsupported_item.plan",
        ["upload_unsupported_item.plan", "ComplexItem", "flatten it"],
    ),
    "upload_hold_negative": (
        "upload_hold_negative.plan",
        [
            "upload_hold_negative.plan: mission item at index 2 (NAV_WAYPOINT)",
            "param1 (hold) -5 s is out of range (ArduPilot would keep 65531 s)",
            "give a hold of 0 to 65535 seconds",
        ],
    ),
    "upload_yaw_huge": (
        "upload_yaw_huge.plan",
        [
            "upload_yaw_huge.plan: mission item at index 2 (NAV_WAYPOINT)",
            "param4 (yaw) 1e+20 deg is out of range",
            "give a yaw of -360 to 360 degrees",
        ],
    ),
    "upload_altitude_below_home": (
        "upload_altitude_below_home.plan",
        [
            "upload_altitude_below_home.plan: mission item at index 2 (NAV_WAYPOINT)",
            "altitude (param7) -1000 m relative to home (488 m AMSL) is -512 m AMSL",
            "give an altitude of -988 m or more relative to home",
        ],
    ),
    "upload_nan_param": (
        "upload_nan_param.plan",
        [
            "upload_nan_param.plan: mission item at index 1 (DO_MOUNT_CONTROL)",
            "param1 (pitch) is NaN",
            "give a number",
        ],
    ),
    "upload_waypoints_duplicate_seq": (
        "upload_waypoints_duplicate_seq.waypoints",
        [
            "upload_waypoints_duplicate_seq.waypoints: line 7: seq 4, expected 5",
            "a line is repeated or missing",
        ],
    ),
    "upload_waypoints_seq_gap": (
        "upload_waypoints_seq_gap.waypoints",
        ["upload_waypoints_seq_gap.waypoints: line 7: seq 6, expected 5", "repeated or missing"],
    ),
}
NOBODY = "udpin://127.0.0.1:14999"  # nothing listens: a connection attempt would wait 10 s


def run_upload(path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[int, str, float]:
    """`urpt-gcs upload PATH` with a connection that must not be tried."""
    from urpt_gcs import mavsdk_link

    def no_connection(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a connection was attempted")

    monkeypatch.setattr(mavsdk_link, "connect", no_connection)
    started = time.monotonic()
    result = CliRunner().invoke(main, ["upload", str(path), "--connect", NOBODY, "--timeout", "10"])
    return result.exit_code, result.stderr, time.monotonic() - started


def assert_one_line(code: int, stderr: str, words: list[str]) -> None:
    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("urpt-gcs: error: "), stderr
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.mark.parametrize("case", sorted(UPLOAD_CASES))
def test_bad_upload_file(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    name, words = UPLOAD_CASES[case]
    code, stderr, elapsed_s = run_upload(BAD / name, monkeypatch)
    assert_one_line(code, stderr, words)
    assert elapsed_s < 5.0, "refused before the 10 s connect timeout"


@pytest.mark.parametrize("suffix", [".plan", ".waypoints"])
def test_bad_upload_too_many_items(
    suffix: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """65 559 items (as in the issue) would wrap MAVLink's uint16 count; too big to commit."""
    item = [0, 0, 0, 0, 47.3981, 8.5461, 40]
    count = 65_558  # and home: 65 559 on an ArduPilot
    path = tmp_path / f"upload_too_many_items{suffix}"
    if suffix == ".plan":
        takeoff = {"type": "SimpleItem", "command": 22, "frame": 3, "autoContinue": True}
        waypoint = {**takeoff, "command": 16, "params": item}
        plan = {
            "fileType": "Plan",
            "version": 1,
            "groundStation": "QGroundControl",
            "mission": {
                "version": 2,
                "firmwareType": 3,
                "vehicleType": 2,
                "cruiseSpeed": 5,
                "hoverSpeed": 5,
                "plannedHomePosition": [47.3977, 8.5456, 488.0],
                "items": [{**takeoff, "params": item}] + [waypoint] * (count - 1),
            },
            "geoFence": {"version": 2, "polygons": [], "circles": []},
            "rallyPoints": {"version": 2, "points": []},
        }
        path.write_text(json.dumps(plan, separators=(",", ":")))
    else:
        fields = "\t".join(str(v) for v in item)
        lines = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t47.3977\t8.5456\t488\t1"]
        lines += [f"{seq}\t0\t3\t16\t{fields}\t1" for seq in range(1, count + 1)]
        path.write_text("\n".join(lines) + "\n")
    code, stderr, elapsed_s = run_upload(path, monkeypatch)
    assert_one_line(
        code,
        stderr,
        [
            path.name,
            "65559 mission items (65558 and ArduPilot's home item) are more than the 65535",
            "plan fewer targets or split the mission into sorties",
        ],
    )
    assert elapsed_s < 5.0


def test_every_sample_file_is_in_the_catalogue() -> None:
    named = {a for args, _ in PLAN_CASES.values() for a in args}
    named |= {name for name, _ in UPLOAD_CASES.values()}
    used = {Path(a).name for a in named} | {a[1:] for a in named if a.startswith("@")}
    samples = {p.name for p in BAD.iterdir() if p.suffix != ".py"}
    # Samples the target reader's own tests cover in detail.
    reader_only = {
        "csv_header_only.csv",
        "geojson_bad_coordinates.geojson",
        "geojson_malformed.geojson",
        "geojson_not_geojson.json",
        "kml_bad_coordinates.kml",
        "dem_geographic_across_utm_zones.csv",
    }
    assert samples - used - reader_only == set()
