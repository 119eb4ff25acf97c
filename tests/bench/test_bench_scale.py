"""The scale benchmark itself, on a tiny site: the rows it reports exist and the plan ran."""

from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

from urpt_gcs.bench.scale import TERRAIN_STAGES
from urpt_gcs.cli import main


def test_bench_scale_plans_a_tiny_site_and_reports_every_column(tmp_path: Path) -> None:
    got = CliRunner().invoke(
        main, ["bench", "scale", "--targets", "3", "--size", "600", "--out", str(tmp_path)]
    )
    assert got.exit_code == 0, got.output
    with (tmp_path / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1
    row = rows[0]
    assert row["status"] == "ok", row["status"]
    assert (int(row["targets"]), int(row["size_px"])) == (3, 600)
    assert float(row["wall_s"]) > 0.0 and float(row["peak_rss_mb"]) > 0.0
    # Refined, the one stop may sit right above home when home's plane sees every target.
    assert int(row["viewpoints"]) >= 3 and float(row["tour_m"]) >= 0.0
    assert float(row["read_only_s"]) > 0.0
    assert float(row["ratio"]) > 0.0
    for stage in ("terrain", *TERRAIN_STAGES, "solve"):
        assert stage in row["timings_s"], row["timings_s"]
    # The table printed after the progress lines has the header and the run's row.
    lines = got.output.splitlines()
    header = next(k for k, line in enumerate(lines) if line.split()[:2] == ["targets", "px"])
    assert lines[header + 1 :] and lines[-1].split()[:2] == ["3", "600"]
