"""The paper's study, quick subset: what CI runs of `urpt-gcs bench paper`."""

from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

from urpt_gcs.cli import main


def test_bench_paper_quick(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        main,
        [
            "bench", "paper", "--quick", "--out", str(tmp_path), "--heuristic-time", "0.3",
            "--bound-time", "0.2",
        ],
    )  # fmt: skip
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
        "refined",
        "certified_bound",
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
        # Refinement never lengthens; the continuous bound is below the refined tour.
        assert float(row["refined"]) <= optimum + 1e-6
        assert 0.0 <= float(row["certified_bound"]) <= float(row["refined"]) + 1e-6
    assert "Continuous gap" in result.stdout and "Refinement:" in result.stdout


def test_tables_survive_an_instance_seen_from_one_point(tmp_path: Path) -> None:
    """Where one viewpoint sees every target the optimum is 0: no ratio, no division."""
    from urpt_gcs.bench.paper import Row, format_tables, read_csv, write_csv

    rows = [
        Row(
            0,
            4,
            30.0,
            20,
            84,
            0.0,
            True,
            0.01,
            0.0,
            0.1,
            "heuristic",
            90.0,
            470.0,
            3,
            540.0,
            0.0,
            180.0,
        ),
        Row(
            1,
            4,
            30.0,
            20,
            84,
            100.0,
            True,
            0.01,
            100.0,
            0.1,
            "heuristic",
            150.0,
            400.0,
            2,
            540.0,
            10.0,
            180.0,
        ),
    ]
    write_csv(rows, tmp_path / "results.csv")
    assert read_csv(tmp_path / "results.csv") == rows
    text = format_tables(rows)
    assert "1 with optimum 0" in text
    assert "on the 1 instances with optimum > 0: True" in text
