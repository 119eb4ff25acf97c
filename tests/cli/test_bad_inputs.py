"""The bad-input catalogue: every sample in tests/data/bad/ named after the failure it causes.

Each case: exit status 1, exactly one line on stderr naming the input and what to do, no
traceback, and nothing written: run once with no --out yet (it is not created) and once with
an --out holding an earlier plan's outputs (they are left byte for byte, and nothing else
appears beside them). ``{tmp}`` in a case's arguments is that run's own folder.

Samples that cannot be committed (FIFOs, links to devices, a file over a size cap) are made at
run time in a folder of their own: an argument ``%name`` stands for the path ``RUNTIME[name]``
makes. Those cases run the CLI in a child process with a time and memory limit, so that a
regression fails instead of hanging or eating the machine.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main
from urpt_gcs.site.inputs import SETTINGS_FILE_MAX_BYTES, TARGETS_MAX_BYTES

BAD = Path(__file__).resolve().parents[1] / "data" / "bad"
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
    # A cone of metres was once printed as "1.3e+03 cm".
    "cone_narrower_than_the_tolerance": (
        ["--position-tolerance", "20", "--fov", "20"],
        ["--fov 20 sees only 12.90 m around", "--position-tolerance"],
    ),
    "samples_2": (["@samples_2.args"], ["--samples", "at least 3"]),
    "output_folder_is_a_file": (
        ["--out", str(BAD / "output_folder_is_a_file")],
        ["output_folder_is_a_file", "--out"],
    ),
    # A wall one pixel wide between West and East, 5 m above the plane: between two samples
    # half a cell apart it reads as 1.3 m under the plane; its true top is found.
    "leg_through_thin_wall": (
        [
            "--dem",
            str(BAD / "dem_thin_wall.tif"),
            "--targets",
            str(BAD / "thin_wall.csv"),
            "--altitude",
            "160",
        ],
        ["cuts 5.0 m into the terrain", "raise --altitude"],
    ),
    "fov_narrower_than_waypoint_grid": (
        ["--fov", "0.001", "--position-tolerance", "0"],
        ["--fov 0.001", "1e-7 degree"],
    ),
    "fov_narrower_than_position_tolerance": (
        ["--fov", "1"],
        ["--fov 1", "twice the 1.5 m", "lower --position-tolerance"],
    ),
    "dem_complex": (
        ["--dem", str(BAD / "dem_complex.tif")],
        ["dem_complex.tif", "complex numbers", "real-valued band"],
    ),
    "dem_multiband": (
        ["--dem", str(BAD / "dem_multiband.tif")],
        ["dem_multiband.tif", "has 2 bands", "--band N (1 to 2)"],
    ),
    "dem_band_out_of_range": (
        ["--dem", str(BAD / "dem_multiband.tif"), "--band", "3"],
        ["dem_multiband.tif", "no band 3", "--band 1 to 2"],
    ),
    "dem_vertical_unit_not_a_length": (
        ["--dem", str(BAD / "dem_vertical_unit_not_a_length.tif")],
        ["dem_vertical_unit_not_a_length.tif", "'degree', not a length", "gdal_edit.py -a_srs"],
    ),
    "dem_below_minus_1000": (
        ["--dem", str(BAD / "dem_below_minus_1000.tif")],
        ["dem_below_minus_1000.tif", "valid range [-1000, 9000] m", "vertical unit", "nodata"],
    ),
    "out_inside_a_file": (
        ["--out", str(BAD / "output_folder_is_a_file" / "out")],
        ["output_folder_is_a_file", "is a file, not a folder", "--out"],
    ),
    "out_name_too_long": (
        ["--out", "{tmp}/" + "x" * 300],
        ["--out", "a name of 300 bytes", "choose a shorter --out"],
    ),
    "out_path_too_long": (
        ["--out", "{tmp}/" + "/".join(["y" * 200] * 25)],
        ["--out", "bytes long", "choose a shorter --out"],
    ),
    # sysfs refuses new entries even to root.
    "export_gtsp_unwritable": (
        ["--export-gtsp", "/sys/urpt-gcs.gtsp"],
        ["--export-gtsp", "/sys/urpt-gcs.gtsp", "'/sys' is not writable"],
    ),
    "export_gtsp_folder_uncreatable": (
        ["--export-gtsp", "/sys/urpt-gcs/demo.gtsp"],
        ["--export-gtsp", "cannot be created", "'/sys' is not writable"],
    ),
    "export_gtsp_inside_a_file": (
        ["--export-gtsp", str(BAD / "output_folder_is_a_file" / "demo.gtsp")],
        ["--export-gtsp", "output_folder_is_a_file", "is a file, not a folder"],
    ),
    "export_gtsp_name_too_long": (
        ["--export-gtsp", "{tmp}/" + "g" * 300 + ".gtsp"],
        ["--export-gtsp", "a name of 305 bytes"],
    ),
    "export_gtsp_is_a_plan_output": (
        ["--export-gtsp", "{tmp}/out/summary.json"],
        ["--export-gtsp", "summary.json", "the plan's own outputs"],
    ),
    "targets_fifo": (
        ["--targets", "%targets_fifo.kml"],
        ["targets_fifo.kml", "FIFO", "not a regular file", "--targets"],
    ),
    "dem_fifo": (["--dem", "%dem_fifo.tif"], ["dem_fifo.tif", "FIFO", "--dem"]),
    "targets_link_to_dev_zero": (
        ["--targets", "%targets_link_to_dev_zero.kml"],
        ["targets_link_to_dev_zero.kml", "a link to '/dev/zero', a character device"],
    ),
    "altitude_1e9": (
        ["--altitude", "1e9"],
        ["--altitude", "DEM window", "GiB", "lower --altitude/--clearance or narrow the camera"],
    ),
    "clearance_1e6": (
        ["--clearance", "1e6"],
        ["--clearance", "DEM window", "GiB", "lower --altitude/--clearance or narrow the camera"],
    ),
    "targets_too_large": (
        ["--targets", "%targets_too_large.kml"],
        ["targets_too_large.kml", "is 65.0 MiB, over the 64.0 MiB limit", "split"],
    ),
    "dem_name_too_long": (
        ["--dem", str(BAD / ("d" * 300 + ".tif"))],
        ["DEM", "a name of 304 characters", "too long", "--dem"],
    ),
    "targets_100000": (
        ["--targets", "%targets_100000.csv"],
        ["100000 targets in", "targets_100000.csv", "GiB", "plan fewer targets at a time"],
    ),
    "seed_negative": (["@seed_negative.args"], ["--seed -1", "0 to 4294967295"]),
    "dem_not_georeferenced": (
        ["--dem", str(BAD / "dem_not_georeferenced.tif")],
        ["dem_not_georeferenced.tif", "coordinate reference system", "gdal_edit.py -a_srs"],
    ),
    "dem_without_geotransform": (
        ["--dem", str(BAD / "dem_without_geotransform.tif")],
        ["dem_without_geotransform.tif", "no geotransform", "export it georeferenced"],
    ),
    "csv_lat_lon_swapped": (
        ["--targets", str(BAD / "csv_lat_lon_swapped.csv")],
        ["csv_lat_lon_swapped.csv", "North gate", "did you swap lat and lon?", "Swap the lat"],
    ),
    "csv_one_row_swapped": (
        ["--targets", str(BAD / "csv_one_row_swapped.csv")],
        ["csv_one_row_swapped.csv", "'Hilltop'", "outside DEM", "did you swap lat and lon?"],
    ),
    "csv_lat_over_90_swapped": (
        ["--targets", str(BAD / "csv_lat_over_90_swapped.csv")],
        ["csv_lat_over_90_swapped.csv", "[-90, 90]", "did you swap lat and lon?"],
    ),
    "home_lat_lon_swapped": (
        ["@home_lat_lon_swapped.args"],
        ["--home 9.4230907,47.6887616", "did you swap lat and lon?", "--home 47.6887616,9.4230907"],
    ),
    "home_lat_over_90_swapped": (
        ["@home_lat_over_90_swapped.args"],
        ["--home 100.5018,13.7563", "did you swap lat and lon?", "--home 13.7563,100.5018"],
    ),
    "geojson_crs_unknown": (
        ["--targets", str(BAD / "geojson_crs_unknown.geojson")],
        ["geojson_crs_unknown.geojson", "'EPSG:999999' that is not known", "in WGS84"],
    ),
    "geojson_crs_link": (
        ["--targets", str(BAD / "geojson_crs_link.geojson")],
        ["geojson_crs_link.geojson", "does not name a CRS", "in WGS84"],
    ),
    "fleet_unknown_key": (
        ["--fleet", str(BAD / "fleet_unknown_key.toml")],
        ["fleet_unknown_key.toml", "[[vehicle]] 1", "unknown key 'spead_m_s'", "speed_m_s"],
    ),
    "fleet_home_without_lon": (
        ["--fleet", str(BAD / "fleet_home_without_lon.toml")],
        ["fleet_home_without_lon.toml", "[[vehicle]] 1", "add home_lon"],
    ),
    "fleet_speed_not_a_number": (
        ["--fleet", str(BAD / "fleet_speed_not_a_number.toml")],
        ["fleet_speed_not_a_number.toml", "speed_m_s = 'fast' is not a number", "m/s"],
    ),
    "fleet_speed_zero": (
        ["--fleet", str(BAD / "fleet_speed_zero.toml")],
        ["fleet_speed_zero.toml", "[[vehicle]] 2", "speed_m_s = 0", "0.1 to 50"],
    ),
    "fleet_not_toml": (
        ["--fleet", str(BAD / "fleet_not_toml.toml")],
        ["fleet_not_toml.toml", "not valid TOML"],
    ),
    "fleet_no_vehicle_table": (
        ["--fleet", str(BAD / "fleet_no_vehicle_table.toml")],
        ["fleet_no_vehicle_table.toml", "'vehicles'", "[[vehicle]]"],
    ),
    "fleet_home_off_dem": (
        ["--fleet", str(BAD / "fleet_home_off_dem.toml")],
        ["home (vehicle 2 of --fleet", "fleet_home_off_dem.toml", "outside DEM"],
    ),
    "fleet_vehicles_disagree": (
        ["--fleet", str(BAD / "fleet_home_off_dem.toml"), "--vehicles", "3"],
        ["--vehicles 3", "2 vehicles of --fleet", "make them agree"],
    ),
    # Refused before the plan: it was once refused after replacing the earlier --out.
    "upload_connect_unknown": (
        ["--upload", "--connect", "foo://bad"],
        ["--connect 'foo://bad'", "unknown kind of link", "udpin://"],
    ),
    "upload_connect_port_out_of_range": (
        ["--upload", "--connect", "udpin://0.0.0.0:99999"],
        ["--connect 'udpin://0.0.0.0:99999'", "port from 1 to 65535"],
    ),
    "duplicate_names": (
        ["--targets", str(BAD / "duplicate_names.kml")],
        ["duplicate_names.kml", "two targets named 'Roof'", "placemark 3 and placemark 5"],
    ),
    "geojson_null_geometry": (
        ["--targets", str(BAD / "geojson_null_geometry.geojson")],
        ["geojson_null_geometry.geojson", "feature 3 'Roof'", "no geometry", "Point"],
    ),
    "home_off_dem": (
        ["--home", "47.70,9.43"],
        ["home (--home)", "outside DEM", "move it onto the DEM"],
    ),
    "fleet_vehicles_zero": (["--vehicles", "0"], ["--vehicles 0", "below 1"]),
    # The vehicle's own altitude is named where it was set, not as --altitude.
    "fleet_altitude_under_terrain": (
        ["--fleet", str(BAD / "fleet_altitude_under_terrain.toml")],
        ["[[vehicle]] 1 altitude_m (--fleet", "fleet_altitude_under_terrain.toml", "420 m"],
    ),
    # Refused before a vehicle is built: this count once took 2.26 GB and 31 s.
    "fleet_vehicles_thirty_million": (
        ["--vehicles", "30000000"],
        ["--vehicles", "30000000 vehicles", "over the 16"],
    ),
    # This one once ended in "out of memory: plan fewer targets", naming the wrong input.
    "fleet_vehicles_hundred_million": (
        ["--vehicles", "100000000"],
        ["--vehicles", "100000000 vehicles", "over the 16"],
    ),
    "fleet_fifo": (["--fleet", "%fleet_fifo.toml"], ["fleet_fifo.toml", "FIFO", "--fleet"]),
    "fleet_link_to_dev_zero": (
        ["--fleet", "%fleet_link_to_dev_zero.toml"],
        ["fleet_link_to_dev_zero.toml", "character device", "--fleet"],
    ),
    "fleet_too_large": (
        ["--fleet", "%fleet_too_large.toml"],
        ["fleet_too_large.toml", "over the 4.0 MiB limit"],
    ),
    "fleet_layers_over_max_agl": (
        ["--vehicles", "8"],
        ["layer 7 (vehicle 7)", "over --max-agl 120 m", "--layer-spacing"],
    ),
    "fleet_layer_spacing_zero": (
        ["--vehicles", "2", "--layer-spacing", "0"],
        ["--layer-spacing 0.0", "positive"],
    ),
    "fleet_separation_unknown": (
        ["--vehicles", "2", "--separation", "sideways"],
        ["--separation 'sideways'", "altitude or time"],
    ),
    "fleet_upload": (["--vehicles", "2", "--upload"], ["--upload", "upload --fleet"]),
    "fleet_time_too_close": (
        ["--vehicles", "2", "--separation", "time", "--min-separation", "1000"],
        ["vehicles 1 and 2 come within", "1000 m required", "--separation altitude"],
    ),
}


def _sparse(path: Path, size: int) -> None:
    with path.open("wb") as fh:
        fh.truncate(size)


def _many_targets(path: Path) -> None:
    grid = ((47.0 + 1e-5 * (i // 1000), 8.0 + 1e-5 * (i % 1000)) for i in range(100_000))
    rows = (f"P{i},{lat:.5f},{lon:.5f}\n" for i, (lat, lon) in enumerate(grid))
    path.write_text("name,lat,lon\n" + "".join(rows))


# Samples made at run time, by the name an argument "%name" gives.
RUNTIME: dict[str, Callable[[Path], None]] = {
    "targets_fifo.kml": os.mkfifo,
    "dem_fifo.tif": os.mkfifo,
    "targets_link_to_dev_zero.kml": lambda p: p.symlink_to("/dev/zero"),
    "upload_link_to_dev_urandom.plan": lambda p: p.symlink_to("/dev/urandom"),
    "targets_too_large.kml": lambda p: _sparse(p, TARGETS_MAX_BYTES + 2**20),
    "fleet_fifo.toml": os.mkfifo,
    "fleet_link_to_dev_zero.toml": lambda p: p.symlink_to("/dev/zero"),
    "fleet_too_large.toml": lambda p: _sparse(p, SETTINGS_FILE_MAX_BYTES + 1),
    "targets_100000.csv": _many_targets,
}
# What a child process running a case may spend.
_CHILD_TIMEOUT_S = 120.0
_CHILD_MEMORY_BYTES = 8 * 2**30


def _expand(args: list[str], tmp: Path) -> list[str]:
    out: list[str] = []
    for arg in args:
        if arg.startswith("@"):
            out += (BAD / arg[1:]).read_text().split()
        elif arg.startswith("%"):
            made = tmp / "runtime" / arg[1:]
            made.parent.mkdir(exist_ok=True)
            RUNTIME[arg[1:]](made)
            out.append(str(made))
        else:
            out.append(arg.replace("{tmp}", str(tmp)))
    return out


def _limit_child() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (_CHILD_MEMORY_BYTES, _CHILD_MEMORY_BYTES))


def run_cli(args: list[str], in_child: bool) -> tuple[int, str]:
    """Exit status and stderr of ``urpt-gcs ARGS``, in process or in a limited child."""
    if not in_child:
        result = CliRunner().invoke(main, args)
        return result.exit_code, result.stderr
    try:
        child = subprocess.run(
            [sys.executable, "-c", "from urpt_gcs.cli import main; main()", *args],
            capture_output=True,
            text=True,
            timeout=_CHILD_TIMEOUT_S,
            preexec_fn=_limit_child,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"urpt-gcs {' '.join(args)} still ran after {_CHILD_TIMEOUT_S:g} s")
    return child.returncode, child.stderr


def run_case(args: list[str], out: Path, in_child: bool = False) -> tuple[int, str]:
    """Run `urpt-gcs plan` with the demo site's inputs overridden by ``args`` (expanded)."""
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
        *args,
    ]
    return run_cli(full, in_child)


Snapshot = dict[str, tuple[bytes, int] | str]


def snapshot(root: Path) -> Snapshot:
    """Every entry under ``root``: a file's bytes and mtime, a link's target, or ``<dir>``
    (the samples made at run time, under ``runtime/``, left out)."""
    found: Snapshot = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        if key == "runtime" or key.startswith("runtime/"):
            continue
        if path.is_symlink():
            found[key] = f"-> {os.readlink(path)}"
        elif path.is_dir():
            found[key] = "<dir>"
        else:
            found[key] = (path.read_bytes(), path.stat().st_mtime_ns)
    return found


@pytest.fixture(scope="session")
def previous_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An --out holding a plan of the demo site, with its map, and a file of the operator's."""
    out = tmp_path_factory.mktemp("previous") / "out"
    result = CliRunner().invoke(
        main,
        ["plan", "--dem", SITE, "--targets", TARGETS, "--out", str(out), "--time-limit", "0.5"],
    )
    assert result.exit_code == 0, result.output
    (out / "notes.txt").write_text("the operator's own file\n")
    assert {"mission.plan", "map.png", "summary.json"} <= {p.name for p in out.iterdir()}
    return out


@pytest.mark.parametrize("prior", ["no_out", "previous_out"])
@pytest.mark.parametrize("case", sorted(PLAN_CASES))
def test_bad_input(case: str, prior: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    args, words = PLAN_CASES[case]
    out = tmp_path / "out"
    if prior == "previous_out":
        shutil.copytree(request.getfixturevalue("previous_out"), out, symlinks=True)
    expanded = _expand(args, tmp_path)
    files_before = snapshot(tmp_path)
    before = sorted(p.name for p in BAD.iterdir())
    code, stderr = run_case(expanded, out, in_child=any(a.startswith("%") for a in args))
    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], lines[0]
    if prior == "no_out":
        assert not out.exists()
    assert snapshot(tmp_path) == files_before, "an earlier --out or its folder was changed"
    assert sorted(p.name for p in BAD.iterdir()) == before, "a sample folder was written to"


@pytest.mark.parametrize(
    "dem", ["dem_without_crs.tif", "dem_not_georeferenced.tif", "dem_without_geotransform.tif"]
)
def test_no_library_warning_reaches_the_operator(dem: str, tmp_path: Path) -> None:
    # In a child with every warning shown: in process, pytest would capture them unseen.
    args = ["plan", "--dem", str(BAD / dem), "--targets", TARGETS, "--out", str(tmp_path)]
    child = subprocess.run(
        [sys.executable, "-W", "always", "-m", "urpt_gcs", *args],
        capture_output=True,
        text=True,
        timeout=_CHILD_TIMEOUT_S,
    )
    assert child.returncode == 1
    assert child.stderr.count("\n") == 1, child.stderr
    assert child.stderr.startswith(f"urpt-gcs: error: DEM '{BAD / dem}'")


# name: (the file given to `urpt-gcs upload`, words the message must contain). The file is
# checked before any connection is tried.
UPLOAD_CASES: dict[str, tuple[str, list[str]]] = {
    "upload_not_a_plan": ("upload_not_a_plan.plan", ["upload_not_a_plan.plan", "JSON"]),
    "upload_unsupported_item": (
        "upload_unsupported_item.plan",
        ["upload_unsupported_item.plan", "ComplexItem", "flatten it"],
    ),
    "upload_link_to_dev_urandom": (
        "%upload_link_to_dev_urandom.plan",
        ["upload_link_to_dev_urandom.plan", "a link to '/dev/urandom', a character device"],
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
    from urpt_gcs.vehicle import mavsdk_link

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
def test_bad_upload_file(case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    name, words = UPLOAD_CASES[case]
    if name.startswith("%"):
        # Made at run time and read in a limited child, where a connection cannot be
        # intercepted: nothing listens at NOBODY, so a refusal that came after trying to
        # connect would name the connection, not the file.
        path = _expand([name], tmp_path)[0]
        code, stderr = run_cli(["upload", path, "--connect", NOBODY], in_child=True)
        assert_one_line(code, stderr, words)
        return
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
