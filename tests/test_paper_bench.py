"""The paper's study, quick subset: what CI runs of `urpt-gcs bench paper`."""

from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

from urpt_gcs.cli import main


def test_bench_paper_quick(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        main, ["bench", "paper", "--quick", "--out", str(tmp_path), "--heuristic-time", "0.3"]
    )
    assert result.exit_code == 0, result.output
    assert "Table I" in result.stdout
    rows = list(csv.DictReader((tmp_path / "results.csv").open()))
    assert len(rows) == 6
    for key in (
        "terrain",
        "m",
        "fov_deg",
        "d",
        "optimum",
        "proven",
        "exact_s",
        "heuristic",
        "approx",
        "lower_bound",
        "naive",
    ):
        assert key in rows[0]
    for row in rows:
        optimum = float(row["optimum"])
        assert row["proven"] == "True"
        assert float(row["lower_bound"]) <= optimum + 1e-6
        assert optimum <= float(row["heuristic"]) + 1e-6
        # Flying over every target is one of the candidate tours.
        assert optimum <= float(row["naive"]) + 1e-6
        assert float(row["approx_path"]) <= float(row["theorem_factor"]) * optimum
