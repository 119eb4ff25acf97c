"""``bench cetsp --peer``: a second solver beside ours, its tour read, recomputed and checked."""

from __future__ import annotations

import csv
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from conftest import CETSP, needs_shared

from urpt_gcs.bench.cetsp_peer import PeerRow, format_peer_table, run_cetsp_peer
from urpt_gcs.bench.peer_tour import PeerCommand, closed_length, first_missed, read_peer_output
from urpt_gcs.cli import main
from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.regions import RegionSet

TIME_S = 1.0
GRACE_S = 1.0
# Six discs around a 40 x 30 rectangle; the depot at a corner's centre.
DISCS = [(0, 0, 1), (20, 0, 1), (40, 0, 1), (40, 30, 1), (20, 30, 1), (0, 30, 1)]
DEPOT = (0.0, 0.0)

# One peer, whose behaviour is the instance's name. It records the CPUs it may run on.
PEER = r"""
import os, subprocess, sys, time
from pathlib import Path

path, name = Path(sys.argv[1]), sys.argv[2]
here = Path(sys.argv[3])
(here / f"cpus_{name}.txt").write_text(" ".join(map(str, sorted(os.sched_getaffinity(0)))))
lines = [l for l in path.read_text().splitlines()[1:] if l.strip()]
centres = [l.split()[:2] for l in lines]
if name == "misses":
    del centres[2]
if name == "sleeps":
    child = subprocess.Popen(["sleep", "60"])
    (here / "grandchild.pid").write_text(str(child.pid))
    time.sleep(60)
if name == "crashes":
    print("TOUR 0 0 1 1")
    sys.exit("peer: boom")
if name == "says_nothing":
    print("hello")
    sys.exit(0)
if name == "lies":
    print("LENGTH 1.0")
print("TOUR " + " ".join(f"{x} {y}" for x, y in centres))
"""
NAMES = ("valid", "misses", "lies", "sleeps", "crashes", "says_nothing")


def _write_folder(folder: Path) -> None:
    (folder / "instances").mkdir(parents=True)
    body = "".join(f"{x} {y} {r}\n" for x, y, r in DISCS)
    for name in NAMES:
        depot = f"{DEPOT[0]:g},{DEPOT[1]:g}" if name == "valid" else "none"
        (folder / "instances" / f"{name}.txt").write_text(f"# {name} depot={depot}\n{body}")
    (folder / "best_known.csv").write_text(
        "name,n_discs,depot,best_known_length,best_known_source,proven_optimal,lower_bound,"
        "notes\n" + "".join(f"{name},6,no,136,test,unknown,,\n" for name in NAMES)
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, PeerRow]]:
    """Every instance once, with the peer beside ours (the runs are the slow part)."""
    folder = tmp_path_factory.mktemp("cetsp")
    _write_folder(folder)
    (folder / "peer.py").write_text(PEER)
    command = f"{sys.executable} {folder / 'peer.py'} {{instance}} {{name}} {folder}"
    rows = run_cetsp_peer(
        folder, command, time_limit_s=TIME_S, out_dir=folder / "out", grace_s=GRACE_S
    )
    return folder, {row.ours.instance: row for row in rows}


def _perimeter(points: list[tuple[float, float]]) -> float:
    return sum(math.dist(points[i - 1], points[i]) for i in range(len(points)))


def test_a_valid_tour_is_tabulated_with_its_recomputed_length(
    run: tuple[Path, dict[str, PeerRow]],
) -> None:
    row = run[1]["valid"]
    assert row.peer.status == "ok", row.peer.note
    assert row.peer.length == pytest.approx(_perimeter([(x, y) for x, y, _ in DISCS]), rel=1e-12)
    assert row.peer_above_best_pct == pytest.approx(100.0 * (140.0 / 136.0 - 1.0))
    assert row.lead is not None and row.lead[0] == "ours"
    assert row.ours.length <= 140.0 and row.ours.lower_bound <= row.ours.length


def test_a_tour_missing_a_disc_is_invalid_and_names_it(
    run: tuple[Path, dict[str, PeerRow]],
) -> None:
    row = run[1]["misses"]
    assert row.peer.status == "invalid"
    assert row.peer.length is None
    assert "disc 3 of 6" in row.peer.note and "40" in row.peer.note
    assert row.peer_above_best_pct is None and row.lead is None


def test_a_claimed_length_is_shown_but_never_used(run: tuple[Path, dict[str, PeerRow]]) -> None:
    row = run[1]["lies"]
    assert row.peer.claimed_length == 1.0
    assert row.peer.length == pytest.approx(140.0, rel=1e-12)


def test_a_peer_past_its_time_is_killed_with_what_it_started(
    run: tuple[Path, dict[str, PeerRow]],
) -> None:
    folder, rows = run
    row = rows["sleeps"]
    assert row.peer.status == "timed out"
    assert row.peer.length is None
    assert TIME_S + GRACE_S <= row.peer.time_s < TIME_S + GRACE_S + 2.0
    pid = int((folder / "grandchild.pid").read_text())
    status = Path(f"/proc/{pid}/status")
    # Gone, or a zombie waiting for its reaper: not running either way.
    assert not status.exists() or "State:\tZ" in status.read_text()


def test_a_crash_or_no_tour_is_a_row_saying_so(run: tuple[Path, dict[str, PeerRow]]) -> None:
    crashed = run[1]["crashes"].peer
    assert crashed.status == "crashed" and crashed.length is None
    assert "exit code 1" in crashed.note and "boom" in crashed.note
    silent = run[1]["says_nothing"].peer
    assert silent.status == "no tour" and "no TOUR line" in silent.note


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs")
def test_ours_and_the_peer_ran_on_different_cpus(run: tuple[Path, dict[str, PeerRow]]) -> None:
    folder, rows = run
    for name, row in rows.items():
        seen = tuple(int(c) for c in (folder / f"cpus_{name}.txt").read_text().split())
        assert seen == row.peer_cpus and len(seen) == 1
        assert len(row.ours_cpus) == 1 and row.ours_cpus != seen


def test_the_table_and_results_csv(run: tuple[Path, dict[str, PeerRow]]) -> None:
    folder, rows = run
    table = format_peer_table(list(rows.values()))
    assert "peer on misses: the tour misses disc 3 of 6" in table
    assert "over 2 valid tours of 6" in table
    with (folder / "out" / "results.csv").open(newline="") as f:
        written = {r["instance"]: r for r in csv.DictReader(f)}
    assert set(written) == set(NAMES)
    assert written["misses"]["peer_status"] == "invalid"
    assert written["misses"]["peer_length"] == ""
    assert written["lies"]["peer_claimed_length"] == "1.000000"
    assert float(written["lies"]["peer_length"]) == pytest.approx(140.0)


def test_a_leg_crossing_a_disc_touches_it_and_the_depot_must_be_on_the_tour() -> None:
    regions = RegionSet(discs=np.array([[5.0, 0.5, 0.5], [10.0, 0.0, 1.0]]), depot_xy=(0.0, 0.0))
    through = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert first_missed(through, regions) is None
    assert closed_length(through) == 20.0
    away = np.array([[0.0, 1.0], [10.0, 0.0]])
    assert "depot" in (first_missed(away, regions) or "")
    short = np.array([[0.0, 0.0], [8.9, 0.0]])
    assert "disc 2 of 2" in (first_missed(short, regions) or "")


@pytest.mark.parametrize(
    ("stdout", "why"),
    [
        ("", "no TOUR line"),
        ("TOUR 1 2 3", "not x y pairs"),
        ("TOUR 1 two", "not a number"),
        ("TOUR 1 nan", "not finite"),
    ],
)
def test_unusable_output_says_why(stdout: str, why: str) -> None:
    result = read_peer_output(stdout)
    assert isinstance(result, str) and why in result


def test_the_last_tour_printed_counts() -> None:
    result = read_peer_output("TOUR 0 0 1 1\nLENGTH 3\nTOUR 2 2 3 3\n")
    assert not isinstance(result, str)
    assert result.points.tolist() == [[2.0, 2.0], [3.0, 3.0]]
    assert result.claimed_length == 3.0


@pytest.mark.parametrize(
    ("command", "said"),
    [
        ("python3 peer.py {time_s}", "no {instance}"),
        ("python3 peer.py {instance} {budget}", "unknown placeholder {budget}"),
        ("no-such-solver-here {instance}", "cannot start 'no-such-solver-here'"),
        ("python3 'peer.py {instance}", "check the quotes"),
        ("", "--peer is empty"),
    ],
)
def test_a_bad_peer_command_is_refused(command: str, said: str) -> None:
    with pytest.raises(SettingsError, match=None) as caught:
        PeerCommand.parse(command)
    assert said in str(caught.value)


def _cli(args: list[str]) -> Result:
    return CliRunner().invoke(main, ["bench", "cetsp", *args])


def test_the_cli_refuses_a_bad_peer_in_one_line_before_solving(tmp_path: Path) -> None:
    _write_folder(tmp_path)
    result = _cli([str(tmp_path), "--peer", "no-such-solver-here {instance}"])
    assert result.exit_code == 1
    assert result.output.strip().count("\n") == 0
    assert "cannot start 'no-such-solver-here'" in result.output
    result = _cli([str(tmp_path), "--peer", "python3 x.py {instance}", "--threads", "2"])
    assert result.exit_code == 2 and "one core" in result.output
    result = _cli([str(tmp_path), "--peer-grace", "3"])
    assert result.exit_code == 2 and "with --peer" in result.output


@needs_shared(CETSP / "instances" / "concentricCircles1.txt")
def test_the_cli_beside_a_nearest_neighbour_peer_on_a_real_instance(tmp_path: Path) -> None:
    peer = tmp_path / "nn.py"
    peer.write_text(
        "import math, re, sys\n"
        "head, *lines = open(sys.argv[1]).read().splitlines()\n"
        "pts = [tuple(map(float, l.split()[:2])) for l in lines if l.strip()]\n"
        "depot = re.search(r'depot=(\\S+)', head).group(1)\n"
        "if depot != 'none':\n"
        "    pts.insert(0, tuple(map(float, depot.split(','))))\n"
        "tour = [pts.pop(0)]\n"
        "while pts:\n"
        "    i = min(range(len(pts)), key=lambda k: math.dist(pts[k], tour[-1]))\n"
        "    tour.append(pts.pop(i))\n"
        "print('TOUR ' + ' '.join(f'{x!r} {y!r}' for x, y in tour))\n"
    )
    out = tmp_path / "out"
    result = _cli(
        [
            str(CETSP),
            "--only",
            "concentricCircles1",
            "--time-limit",
            "1",
            "--peer",
            f"{sys.executable} {peer} {{instance}}",
            "--out",
            str(out),
        ]
    )
    assert result.exit_code == 0, result.output
    assert "concentricCircles1" in result.output and " valid " in result.output
    with (out / "results.csv").open(newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert row["peer_status"] == "ok"
    assert float(row["peer_length"]) > float(row["length"]) >= float(row["lower_bound"])
