"""The GTSPLIB benchmark: time limits, recomputed costs, results.csv, table and the CLI."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner, Result
from conftest import DEMO, GTSPLIB, needs_shared

import urpt_gcs.bench.gtsplib as bench
from urpt_gcs.bench.gtsplib import Row, bench_solvers, format_table, run_gtsplib, tour_cost
from urpt_gcs.cli import main
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.files.formats.gtsplib import read_gtsplib
from urpt_gcs.solvers import SOLVERS
from urpt_gcs.solvers.routing import RoutingSolver

REQUIRED = {"instance", "solver", "run", "cost", "gap_pct", "time_s", "best_known"}

# Corners of a 30 x 40 rectangle, one per set; the centre, also in set 1, makes it 120 not 140.
SQUARE = """NAME : 4square
TYPE : GTSP
DIMENSION : 5
GTSP_SETS : 4
EDGE_WEIGHT_TYPE : EUC_2D
NODE_COORD_SECTION
1 0 0
2 30 0
3 30 40
4 0 40
5 15 20
GTSP_SET_SECTION
1 1 5 -1
2 2 -1
3 3 -1
4 4 -1
EOF
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "4square.gtsp").write_text(SQUARE)
    (tmp_path / "4other.gtsp").write_text(SQUARE.replace("4square", "4other"))
    (tmp_path / "best_known.csv").write_text("instance,best_known\n4square,100\n4other,100\n")
    (tmp_path / "glns_default.csv").write_text(
        "instance,best_known,glns_default_mean_cost,glns_default_mean_gap_pct,"
        "glns_default_mean_time_s\n4square,100,100.0,0.0,0.05\n"
    )
    return tmp_path


def test_solvers_default_to_the_heuristic_and_always_add_the_baseline(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert bench_solvers(["ortools"]) == ["ortools"]
    assert bench_solvers(["auto", "ortools", "auto"]) == ["auto", "ortools"]
    monkeypatch.delitem(SOLVERS, "heuristic", raising=False)
    assert bench_solvers([]) == ["ortools"]
    monkeypatch.setitem(SOLVERS, "heuristic", RoutingSolver)
    assert bench_solvers([]) == ["heuristic", "ortools"]
    with pytest.raises(SettingsError, match=r"^solver 'nope' is not known"):
        bench_solvers(["nope"])


def test_limits_from_glns_times_costs_gaps_and_results_csv(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(bench, "DEFAULT_TIME_LIMIT_S", 0.2)
    said: list[str] = []
    out = folder / "out"
    rows = run_gtsplib(folder, ["ortools"], None, runs=2, out_dir=out, progress=said.append)
    assert [(r.instance, r.run) for r in rows] == [
        ("4other", 0),
        ("4other", 1),
        ("4square", 0),
        ("4square", 1),
    ]
    assert len(said) == 4
    by_name = {r.instance: r for r in rows}
    assert by_name["4square"].time_limit_s == pytest.approx(3 * 0.05)
    assert by_name["4other"].time_limit_s == 0.2, "no GLNS time: the default"
    assert by_name["4square"].glns_time_s == 0.05 and by_name["4other"].glns_cost is None
    for row in rows:
        assert row.cost == 120.0 and row.gap_pct == pytest.approx(20.0)
        assert (row.clusters, row.nodes) == (4, 5)
    with (out / "results.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert set(table[0]) >= REQUIRED and len(table) == 4
    assert float(table[0]["cost"]) == 120.0 and table[0]["glns_cost"] == ""


def test_bad_arguments_are_settings_errors(folder: Path) -> None:
    with pytest.raises(SettingsError, match="--only nope"):
        run_gtsplib(folder, ["ortools"], 0.1, 1, only=["nope"])
    with pytest.raises(SettingsError, match="--runs 0"):
        run_gtsplib(folder, ["ortools"], 0.1, 0)
    with pytest.raises(SettingsError, match="time_limit_s"):
        run_gtsplib(folder, ["ortools"], -1.0, 1)
    (folder / "empty").mkdir()
    with pytest.raises(SettingsError, match=r"no \.gtsp file"):
        run_gtsplib(folder / "empty", ["ortools"], 0.1, 1)
    with pytest.raises(SettingsError, match="does not exist"):
        run_gtsplib(folder / "absent", ["ortools"], 0.1, 1)
    (folder / "glns_default.csv").write_text("instance,glns_default_mean_cost\n4square,1\n")
    with pytest.raises(SettingsError, match="line 1: the header lacks column"):
        run_gtsplib(folder, ["ortools"], 0.1, 1)


def test_cost_is_recomputed_and_checked(folder: Path) -> None:
    instance = read_gtsplib(folder / "4square.gtsp")
    assert tour_cost(instance, [4, 1, 2, 3], "x") == 25 + 25 + 40 + 30
    with pytest.raises(PlanError, match="misses sets \\[4\\]"):
        tour_cost(instance, [0, 1, 2], "x")
    with pytest.raises(PlanError, match="outside"):
        tour_cost(instance, [0, 1, 2, -1], "x")


def _row(instance: str, clusters: int, solver: str, cost: float) -> Row:
    return Row(
        instance, clusters, 10, solver, 0, 1.0, cost, 0.5, 100.0, cost - 100.0, None, None, None
    )


def test_table_compares_each_solver_with_the_baseline_from_40_clusters() -> None:
    rows = [
        _row("11small", 11, "heuristic", 101.0),
        _row("11small", 11, "ortools", 100.0),
        _row("40a", 40, "heuristic", 100.0),
        _row("40a", 40, "ortools", 103.0),
        _row("41b", 41, "heuristic", 102.0),
        _row("41b", 41, "ortools", 102.0),
    ]
    text = format_table(rows)
    assert "ahead of ortools on 1 of 2 (tied 1, behind 0); ahead on every one: no" in text
    assert "heuristic 1.0000 %, ortools 1.6667 %" in text
    lines = text.splitlines()
    assert lines[1].split()[:5] == ["instance", "sets", "nodes", "best_known", "limit_s"]
    assert any(line.startswith("40a") and "103.0" in line for line in lines)


def _cli(args: list[str]) -> Result:
    return CliRunner().invoke(main, args)


@needs_shared(GTSPLIB)
def test_cli_bench_on_the_shared_folder_writes_results(tmp_path: Path) -> None:
    out = tmp_path / "tmp"
    args = ["bench", "gtsplib", str(GTSPLIB), "--only", "11eil51", "--solver", "ortools"]
    result = _cli([*args, "--time-limit", "0.5", "--out", str(out)])
    assert result.exit_code == 0, result.output
    with (out / "results.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert set(rows[0]) >= REQUIRED and len(rows) == 1
    assert rows[0]["instance"] == "11eil51" and rows[0]["solver"] == "ortools"
    assert float(rows[0]["cost"]) >= 174 and float(rows[0]["best_known"]) == 174
    assert "11eil51" in result.stdout and "mean gap" in result.stdout


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--only", "11eil51,nosuch"], "--only nosuch"),
        (["--runs", "0"], "--runs 0"),
        (["--solver", "nope"], "--solver 'nope'"),
    ],
)
@needs_shared(GTSPLIB)
def test_cli_bench_errors_are_one_line(extra: list[str], word: str) -> None:
    result = _cli(["bench", "gtsplib", str(GTSPLIB), "--time-limit", "0.1", *extra])
    assert result.exit_code == 1
    assert result.stderr.count("\n") == 1 and word in result.stderr, result.stderr


def test_plan_export_is_read_back_by_bench(tmp_path: Path) -> None:
    exported = tmp_path / "gtsp" / "demo.gtsp"
    plan = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    failed = _cli(
        [*plan, "--out", str(tmp_path / "bad"), "--fov", "95", "--export-gtsp", str(exported)]
    )
    assert failed.exit_code == 1 and not exported.parent.exists()
    # Tolerance 0: the bound is then for every flight that sees the targets, the exported
    # candidates' tours among them (with a tolerance it is for stops that hold it).
    export = ["--export-gtsp", str(exported), "--position-tolerance", "0"]
    result = _cli([*plan, "--out", str(tmp_path / "out"), "--time-limit", "1", "--json", *export])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in exported.parent.iterdir()) == ["demo.gtsp"]
    instance = read_gtsplib(exported)
    assert instance.n_targets == 16 + 1, "one set per target and the home last"
    last = instance.covers.viewpoints_of(instance.n_targets - 1).tolist()
    assert last == [instance.n_viewpoints - 1]
    out = tmp_path / "bench"
    args = ["bench", "gtsplib", str(exported.parent), "--solver", "ortools", "--time-limit", "1"]
    ran = _cli([*args, "--out", str(out)])
    assert ran.exit_code == 0, ran.output
    with (out / "results.csv").open() as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["instance"] == "demo" and row["best_known"] == "" and row["gap_pct"] == ""
    summary = json.loads(result.stdout)
    # Centimetres: no tour beats the plan's lower bound; a solve of equal effort is close.
    rounding_cm = 2.0 * instance.n_targets
    lower_cm, plan_cm = 100 * summary["lower_bound_m"], 100 * summary["tour_length_m"]
    assert lower_cm - rounding_cm <= float(row["cost"]) <= 3 * plan_cm
