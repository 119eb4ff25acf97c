"""No output may replace an input: every spelling of the same file is refused before planning.

Each refused case: exit 1, one line on stderr naming the output, the input and the fix, and
every file under the case's folder left byte for byte.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main

FAST = ["--time-limit", "0.5", "--no-map"]


def _files(root: Path) -> dict[str, bytes | str]:
    found: dict[str, bytes | str] = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        if path.is_symlink():
            found[key] = f"-> {os.readlink(path)}"
        elif path.is_file():
            found[key] = path.read_bytes()
    return found


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder holding copies of the demo's DEM and targets, made the current one."""
    shutil.copy(DEMO / "site.tif", tmp_path / "site.tif")
    shutil.copy(DEMO / "targets.kml", tmp_path / "targets.kml")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _refused(root: Path, args: list[str], *words: str) -> None:
    before = _files(root)
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert _files(root) == before, "a file was written, moved or removed"


def test_export_gtsp_that_is_the_dem_by_another_spelling_is_refused(site: Path) -> None:
    (site / "sub").mkdir()
    args = ["plan", "--dem", "site.tif", "--targets", "targets.kml", "--out", "out", *FAST]
    _refused(site, [*args, "--export-gtsp", "sub/../site.tif"], "--export-gtsp", "--dem")


def test_export_gtsp_that_is_the_targets_file_is_refused(site: Path) -> None:
    args = ["plan", "--dem", "site.tif", "--targets", "targets.kml", "--out", "out", *FAST]
    _refused(site, [*args, "--export-gtsp", str(site / "targets.kml")], "--targets")


def test_targets_inside_out_under_an_output_name_are_refused(site: Path) -> None:
    (site / "field").mkdir()
    shutil.move(site / "targets.kml", site / "field" / "plan.kml")
    args = ["plan", "--dem", "site.tif", "--targets", "field/plan.kml", "--out", "field", *FAST]
    _refused(site, args, "--out 'field'", "--targets", "plan.kml", "choose another --out")


def test_targets_reached_through_a_link_to_out_are_refused(site: Path) -> None:
    (site / "field").mkdir()
    shutil.move(site / "targets.kml", site / "field" / "plan.kml")
    (site / "via").symlink_to("field")
    args = ["plan", "--dem", "site.tif", "--targets", "via/plan.kml", "--out", "field", *FAST]
    _refused(site, args, "--targets", "plan.kml")


def test_dem_hard_linked_as_an_output_is_refused(site: Path) -> None:
    (site / "out").mkdir()
    os.link(site / "site.tif", site / "out" / "map.png")
    args = ["plan", "--dem", "site.tif", "--targets", "targets.kml", "--out", "out", *FAST]
    _refused(site, args, "--dem", "map.png")


def test_fleet_file_inside_a_fleet_out_is_refused(site: Path) -> None:
    (site / "out").mkdir()
    (site / "out" / "summary.json").write_text("[[vehicle]]\n\n[[vehicle]]\n")
    args = ["plan", "--dem", "site.tif", "--targets", "targets.kml", "--out", "out", *FAST]
    _refused(site, [*args, "--fleet", "out/summary.json"], "--fleet", "summary.json")


def test_a_link_among_the_outputs_to_an_input_is_replaced_and_the_input_kept(site: Path) -> None:
    (site / "out").mkdir()
    (site / "out" / "plan.kml").symlink_to("../targets.kml")
    kept = (site / "targets.kml").read_bytes()
    args = ["plan", "--dem", "site.tif", "--targets", "targets.kml", "--out", "out", *FAST]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert (site / "targets.kml").read_bytes() == kept
    assert not (site / "out" / "plan.kml").is_symlink()


def test_batch_writing_into_the_jobs_folder_over_a_sites_targets_is_refused(site: Path) -> None:
    (site / "quarry").mkdir()
    shutil.move(site / "targets.kml", site / "quarry" / "plan.kml")
    jobs = site / "jobs.toml"
    jobs.write_text('[[site]]\nname = "quarry"\ndem = "site.tif"\ntargets = "quarry/plan.kml"\n')
    _refused(site, ["batch", str(jobs), "--out", str(site)], "[[site]] 'quarry'", "plan.kml")
