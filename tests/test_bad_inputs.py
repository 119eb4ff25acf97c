"""The bad-input catalogue: every sample in tests/data/bad/ named after the failure it causes.

Each case: exit status 1, exactly one line on stderr naming the input and what to do, no
traceback, and nothing written to the output folder.

Samples that cannot be committed (FIFOs, links to devices, a file over a size cap) are made in
the test's folder at run time: an argument ``%name`` stands for the path ``RUNTIME[name]``
makes. Those cases run the CLI in a child process with a time and memory limit, so that a
regression fails instead of hanging or eating the machine.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main
from urpt_gcs.inputs import TARGETS_MAX_BYTES

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
    "demo_300_targets": (
        ["--targets", str(BAD / "demo_300_targets.csv")],
        ["300 targets", "GiB", "fewer targets per plan"],
    ),
    "targets_100000": (
        ["--targets", "%targets_100000.csv"],
        ["100000 targets in", "targets_100000.csv", "GiB", "plan fewer targets at a time"],
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
    "targets_100000.csv": _many_targets,
}
# What a child process running a case may spend.
_CHILD_TIMEOUT_S = 120.0
_CHILD_MEMORY_BYTES = 8 * 2**30


def _expand(args: list[str], tmp_path: Path) -> list[str]:
    out: list[str] = []
    for arg in args:
        if arg.startswith("@"):
            out += (BAD / arg[1:]).read_text().split()
        elif arg.startswith("%"):
            made = tmp_path / arg[1:]
            RUNTIME[arg[1:]](made)
            out.append(str(made))
        else:
            out.append(arg)
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


def run_case(args: list[str], out: Path, tmp_path: Path) -> tuple[int, str]:
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
        *_expand(args, tmp_path),
    ]
    return run_cli(full, in_child=any(a.startswith("%") for a in args))


@pytest.mark.parametrize("case", sorted(PLAN_CASES))
def test_bad_input(case: str, tmp_path: Path) -> None:
    args, words = PLAN_CASES[case]
    out = tmp_path / "out"
    before = sorted(p.name for p in BAD.iterdir())
    code, stderr = run_case(args, out, tmp_path)
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
    "upload_link_to_dev_urandom": (
        "%upload_link_to_dev_urandom.plan",
        ["upload_link_to_dev_urandom.plan", "a link to '/dev/urandom', a character device"],
    ),
}


@pytest.mark.parametrize("case", sorted(UPLOAD_CASES))
def test_bad_upload_file(case: str, tmp_path: Path) -> None:
    name, words = UPLOAD_CASES[case]
    path = _expand([name], tmp_path)[0] if name.startswith("%") else str(BAD / name)
    code, stderr = run_cli(
        ["upload", path, "--connect", "udpin://127.0.0.1:14999"], in_child=name.startswith("%")
    )
    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("urpt-gcs: error: "), stderr
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], lines[0]


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
