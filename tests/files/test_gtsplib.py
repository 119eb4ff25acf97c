"""GTSPLIB files: every best-known tour has its published length; bad files fail on one line.

The shared instances are read in place from ``../shared/bench/gtsplib``. Distance kinds and
matrix formats the folder lacks are checked on tiny hand-written files whose distances are
worked out by hand in the test.
"""

from __future__ import annotations

import csv
import itertools
import math
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import GTSPLIB, needs_shared
from hypothesis import given, settings
from hypothesis import strategies as st

from urpt_gcs.errors import OutputError, SettingsError
from urpt_gcs.files.formats.gtsplib import export_gtsplib, read_gtsplib, read_tour, write_gtsplib
from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix

TOURS = sorted((GTSPLIB / "tours").glob("*.tour"))
needs_gtsplib = needs_shared(GTSPLIB)


def _header(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        match = re.match(r"\s*(TYPE|EDGE_WEIGHT_TYPE|EDGE_WEIGHT_FORMAT)\b\s*:?\s*(\S+)", line)
        if match:
            out[match.group(1)] = match.group(2)
    return out


def _best_known() -> dict[str, int]:
    with (GTSPLIB / "best_known.csv").open() as fh:
        return {row["instance"]: int(row["best_known"]) for row in csv.DictReader(fh)}


@needs_gtsplib
def test_the_folder_holds_every_kind_the_tours_exercise() -> None:
    kinds = set()
    for tour in TOURS:
        head = _header(GTSPLIB / f"{tour.name.split('.')[0]}.gtsp")
        kinds.add(head["EDGE_WEIGHT_TYPE"])
        kinds.add(head["TYPE"])
        kinds.add(head.get("EDGE_WEIGHT_FORMAT", ""))
    assert len(TOURS) == len(list(GTSPLIB.glob("*.gtsp"))) == 30
    expected = {"EUC_2D", "CEIL_2D", "ATT", "GEO", "EXPLICIT", "AGTSP", "GTSP"}
    assert expected | {"FULL_MATRIX", "UPPER_ROW", "UPPER_DIAG_ROW"} <= kinds


@needs_gtsplib
@pytest.mark.parametrize("tour_path", TOURS, ids=lambda p: p.name.split(".")[0])
def test_best_known_tour_has_exactly_its_published_length(tour_path: Path) -> None:
    name, length = tour_path.name.split(".")[:2]
    instance = read_gtsplib(GTSPLIB / f"{name}.gtsp")
    tour = read_tour(tour_path)
    assert instance.name.lower() == name.lower()  # 40kroa200 says NAME: 40kroA200
    assert (instance.covers.dense(tour).sum(axis=0) == 1).all(), "one node per set"
    assert instance.tour_length(tour) == int(length) == _best_known()[name]
    assert instance.distance.dtype == np.float64
    assert (instance.distance == np.round(instance.distance)).all()


def _tsplib(kind: str, a: tuple[float, float], b: tuple[float, float]) -> int:
    """One distance by the TSPLIB text, in scalar C-like arithmetic."""
    if kind == "GEO":

        def radians(v: float) -> float:
            deg = int(v)
            return 3.141592 * (deg + 5.0 * (v - deg) / 3.0) / 180.0

        q1 = math.cos(radians(a[1]) - radians(b[1]))
        q2 = math.cos(radians(a[0]) - radians(b[0]))
        q3 = math.cos(radians(a[0]) + radians(b[0]))
        return int(6378.388 * math.acos(0.5 * ((1.0 + q1) * q2 - (1.0 - q1) * q3)) + 1.0)
    xd, yd = a[0] - b[0], a[1] - b[1]
    if kind == "ATT":
        r = math.sqrt((xd * xd + yd * yd) / 10.0)
        t = int(r + 0.5)
        return t + 1 if t < r else t
    if kind == "CEIL_2D":
        return math.ceil(math.sqrt(xd * xd + yd * yd))
    return int(math.sqrt(xd * xd + yd * yd) + 0.5)


@needs_gtsplib
@pytest.mark.parametrize("name", ["41gr202", "107att532", "200dsj1000", "212u1060"])
def test_vectorised_distances_equal_the_scalar_rules(name: str) -> None:
    instance = read_gtsplib(GTSPLIB / f"{name}.gtsp")
    assert instance.points_xy is not None
    kind = _header(GTSPLIB / f"{name}.gtsp")["EDGE_WEIGHT_TYPE"]
    pts = instance.points_xy.tolist()
    rng = np.random.default_rng(1)
    for i, j in rng.integers(0, instance.n_viewpoints, size=(400, 2)).tolist():
        if i != j:
            assert instance.distance[i, j] == _tsplib(kind, pts[i], pts[j]), (i, j)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _coordinate_file(kind: str, coords: list[tuple[float, float]]) -> str:
    nodes = "\n".join(f"{k} {x} {y}" for k, (x, y) in enumerate(coords, start=1))
    sets = "\n".join(f"{k} {k} -1" for k in range(1, len(coords) + 1))
    return (
        f"NAME: tiny\nTYPE: GTSP\nDIMENSION: {len(coords)}\nGTSP_SETS: {len(coords)}\n"
        f"EDGE_WEIGHT_TYPE:{kind}\nNODE_COORD_SECTION\n{nodes}\nGTSP_SET_SECTION\n{sets}\nEOF\n"
    )


@pytest.mark.parametrize(
    ("kind", "coords", "expected"),
    [
        # |01| = 5, |02| = sqrt 2 = 1.41, |12| = sqrt 13 = 3.61
        ("EUC_2D", [(0, 0), (3, 4), (1, 1)], [5, 1, 4]),
        ("CEIL_2D", [(0, 0), (3, 4), (1, 1)], [5, 2, 4]),
        # sqrt(100/10) = 3.16 -> 3 < 3.16 -> 4; sqrt(900/10) = 9.49 -> 10; sqrt(1000/10) = 10
        ("ATT", [(0, 0), (10, 0), (0, 30)], [4, 10, 10]),
        # on the equator: 1 deg = 6378.388 * 3.141592/180 = 111.32 -> 112; 1.50 is 1 deg 50 min
        # = 1.8333 deg -> 204.08 -> 205 (nint-ing the degrees would give 2 - 0.8333 deg, 130)
        ("GEO", [(0, 0), (0, 1.0), (0, 1.50)], [112, 205, 93]),
    ],
)
def test_hand_computed_coordinate_distances(
    tmp_path: Path, kind: str, coords: list[tuple[float, float]], expected: list[int]
) -> None:
    instance = read_gtsplib(_write(tmp_path, "tiny.gtsp", _coordinate_file(kind, coords)))
    d = instance.distance
    assert [d[0, 1], d[0, 2], d[1, 2]] == expected
    assert (d == d.T).all() and (np.diag(d) == 0).all()


MATRIX = [[9, 3, 5, 7], [3, 9, 4, 6], [5, 4, 9, 8], [7, 6, 8, 9]]
EXPLICIT = {
    "UPPER_ROW": "3 5 7\n 4 6\n8",
    "LOWER_ROW": "3\n5 4\n7 6 8",
    "UPPER_DIAG_ROW": "9 3 5 7 9 4 6 9 8 9",
    "LOWER_DIAG_ROW": "9\n3 9\n5 4 9\n7 6 8 9",
    "UPPER_COL": "3 5 4\n7 6 8",
    "LOWER_COL": "3 5 7 4 6 8",
    "UPPER_DIAG_COL": "9 3 9 5 4 9 7 6 8 9",
    "LOWER_DIAG_COL": "9 3 5 7\n9 4 6\n9 8\n9",
}


@pytest.mark.parametrize("fmt", sorted(EXPLICIT))
def test_triangular_formats_fill_the_matrix(tmp_path: Path, fmt: str) -> None:
    text = (
        "NAME : tri\nTYPE : GTSP\nDIMENSION : 4\nGTSP_SETS : 2\nEDGE_WEIGHT_TYPE : EXPLICIT\n"
        f"EDGE_WEIGHT_FORMAT : {fmt}\nEDGE_WEIGHT_SECTION\n{EXPLICIT[fmt]}\n"
        "GTSP_SET_SECTION\n1 1 2 -1\n2 3\n 4 -1\nEOF\n"
    )
    instance = read_gtsplib(_write(tmp_path, "tri.gtsp", text))
    expected = np.array(MATRIX, dtype=float)
    if "DIAG" not in fmt:
        np.fill_diagonal(expected, 0.0)
    assert (instance.distance == expected).all()
    assert instance.points_xy is None
    dense = instance.covers.dense().tolist()
    assert dense == [[True, False], [True, False], [False, True], [False, True]]


def test_asymmetric_full_matrix_and_a_node_in_two_sets(tmp_path: Path) -> None:
    text = (
        "NAME:asym\nTYPE  AGTSP\nDIMENSION:3\nGTSP_SETS:2\nEDGE_WEIGHT_TYPE:EXPLICIT\n"
        "EDGE_WEIGHT_FORMAT:FULL_MATRIX\nEDGE_WEIGHT_SECTION\n0 1 2\n3 0 4 5 6\n0\n"
        "GTSP_SET_SECTION\n1 1 2 -1 2 2 3 -1\nEOF\n"
    )
    instance = read_gtsplib(_write(tmp_path, "asym.gtsp", text))
    assert instance.distance.tolist() == [[0, 1, 2], [3, 0, 4], [5, 6, 0]]
    assert instance.covers.dense()[1].all() and instance.n_targets == 2
    assert instance.tour_length([0, 2]) == 2 + 5


GOOD = _coordinate_file("EUC_2D", [(0, 0), (3, 4), (1, 1)])
BAD = {
    "no_dimension": (GOOD.replace("DIMENSION: 3\n", ""), 13, "DIMENSION"),
    "tsp_type": (GOOD.replace("TYPE: GTSP", "TYPE: TSP"), 2, "TYPE"),
    "euc_3d": (GOOD.replace("EDGE_WEIGHT_TYPE:EUC_2D", "EDGE_WEIGHT_TYPE: EUC_3D"), 5, "EUC_3D"),
    "short_coords": (GOOD.replace("3 1 1\n", "3 1\n"), 6, "NODE_COORD_SECTION"),
    "word_in_coords": (GOOD.replace("2 3 4", "2 3 four"), 8, "'four'"),
    "node_out_of_range": (GOOD.replace("3 3 -1", "3 7 -1"), 13, "node 7"),
    "set_unterminated": (GOOD.replace("3 3 -1", "3 3"), 14, "-1"),
    "set_missing": (GOOD.replace("3 3 -1\n", ""), 10, "set(s) [3]"),
    "set_empty": (GOOD.replace("3 3 -1", "3 -1"), 13, "no nodes"),
    "set_twice": (GOOD.replace("3 3 -1", "2 3 -1"), 13, "twice"),
    "numbers_outside": ("1 2 3\n" + GOOD, 1, "outside any section"),
    "dimension_word": (GOOD.replace("DIMENSION: 3", "DIMENSION: three"), 3, "DIMENSION"),
    "upper_row_short": (
        "TYPE: GTSP\nDIMENSION: 3\nGTSP_SETS: 1\nEDGE_WEIGHT_TYPE: EXPLICIT\n"
        "EDGE_WEIGHT_FORMAT: UPPER_ROW\nEDGE_WEIGHT_SECTION\n1 2\nGTSP_SET_SECTION\n1 1 2 3 -1\n",
        6,
        "UPPER_ROW",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_file_fails_on_one_line_naming_file_and_line(tmp_path: Path, case: str) -> None:
    text, line, word = BAD[case]
    path = _write(tmp_path, f"{case}.gtsp", text)
    with pytest.raises(SettingsError) as info:
        read_gtsplib(path)
    message = str(info.value)
    assert "\n" not in message
    assert f"'{path}'" in message and f"line {line}:" in message and word in message, message


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match=r"'.*absent.gtsp' does not exist"):
        read_gtsplib(tmp_path / "absent.gtsp")
    (tmp_path / "zero.gtsp").symlink_to("/dev/zero")
    with pytest.raises(SettingsError, match=r"a character device, not a regular file"):
        read_gtsplib(tmp_path / "zero.gtsp")
    (tmp_path / "bin.gtsp").write_bytes(b"\xff\xfe\x00NAME")
    with pytest.raises(SettingsError, match=r"cannot be read as text \(not UTF-8\)"):
        read_gtsplib(tmp_path / "bin.gtsp")


def test_read_tour(tmp_path: Path) -> None:
    path = _write(
        tmp_path, "t.tour", "NAME : t\nTYPE : TOUR\nDIMENSION : 3\nTOUR_SECTION\n3 1\n2\n-1\n"
    )
    assert read_tour(path) == [2, 0, 1]
    _write(tmp_path, "open.tour", "TOUR_SECTION\n3 1\n2\n")
    with pytest.raises(SettingsError, match=r"line 3: TOUR_SECTION is not terminated"):
        read_tour(tmp_path / "open.tour")
    _write(tmp_path, "dim.tour", "DIMENSION: 4\nTOUR_SECTION\n3 1\n2 -1\n")
    with pytest.raises(SettingsError, match="line 1: DIMENSION 4 but the tour lists 3"):
        read_tour(tmp_path / "dim.tour")
    _write(tmp_path, "zero.tour", "TOUR_SECTION\n0 -1\n")
    with pytest.raises(SettingsError, match="node 0 is outside"):
        read_tour(tmp_path / "zero.tour")


def _random_instance(seed: int, depot: bool) -> Instance:
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 6)), int(rng.integers(1, 4))
    points = rng.uniform(-50.0, 250.0, size=(n, 2))
    covers = rng.random((n, m)) < 0.45
    covers[rng.integers(0, n, size=m), np.arange(m)] = True
    if not depot:
        return Instance(
            covers=Covers.from_dense(covers), distance=euclidean_matrix(points), points_xy=points
        )
    home = rng.uniform(-50.0, 250.0, size=2)
    to_home = np.hypot(*(points - home).T)
    return Instance(
        covers=Covers.from_dense(covers),
        distance=euclidean_matrix(points),
        depot_distance=np.vstack([to_home, to_home]),
        points_xy=points,
        depot_xy=(float(home[0]), float(home[1])),
    )


def _cover_optimum(instance: Instance) -> float:
    """Shortest tour over any viewpoints that see every target, by enumeration."""
    best = math.inf
    for k in range(1, instance.n_viewpoints + 1):
        for subset in itertools.combinations(range(instance.n_viewpoints), k):
            if instance.uncovered(list(subset)):
                continue
            for order in itertools.permutations(subset):
                if instance.has_depot or order[0] == subset[0]:
                    best = min(best, instance.tour_length(list(order)))
    return best


def _set_optimum(instance: Instance) -> float:
    """Shortest cycle through one node of each set, by enumeration (the partition form)."""
    d = instance.distance.tolist()
    sets = [instance.covers.viewpoints_of(t).tolist() for t in range(instance.n_targets)]
    best = math.inf
    for rest in itertools.permutations(sets[1:]):
        for nodes in itertools.product(sets[0], *rest):
            cycle = [*nodes, nodes[0]]
            best = min(best, sum(d[a][b] for a, b in itertools.pairwise(cycle)))
    return best


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), depot=st.booleans())
def test_export_round_trip_keeps_the_optimum_to_the_centimetre(
    tmp_path_factory: pytest.TempPathFactory, seed: int, depot: bool
) -> None:
    instance = _random_instance(seed, depot)
    path = tmp_path_factory.mktemp("rt") / "rt.gtsp"
    path.write_text(write_gtsplib(instance, "rt", comment="round\ntrip"))
    back = read_gtsplib(path)
    vp, tg = instance.covers.pairs()
    places = np.vstack([instance.points_xy[vp], [instance.depot_xy] if depot else np.empty((0, 2))])
    nodes = len(vp) + int(depot)
    assert back.n_viewpoints == nodes and back.n_targets == instance.n_targets + int(depot)
    assert back.name == "rt" and back.points_xy is not None
    assert (back.points_xy >= 0).all() and (back.points_xy == np.round(back.points_xy)).all()
    assert back.covers.dense()[np.arange(len(vp)), tg].all(), (
        "node k is the k-th (viewpoint, target)"
    )
    cm = np.rint(100.0 * places)
    assert (back.points_xy == cm - cm.min(axis=0)).all()
    # Every edge is within 2 cm of 100 x the original (rounding of both ends and of nint).
    assert np.abs(back.distance - 100.0 * euclidean_matrix(places)).max() <= 2.0
    slack_cm = 2.0 * back.n_targets
    assert abs(_set_optimum(back) - 100.0 * _cover_optimum(instance)) <= slack_cm


def test_writer_refuses_what_euc_2d_cannot_say(tmp_path: Path) -> None:
    covers = Covers.from_dense(np.ones((2, 1), dtype=bool))
    with pytest.raises(SettingsError, match="positions"):
        write_gtsplib(Instance(covers=covers, distance=np.zeros((2, 2))), "x")
    skewed = Instance(covers=covers, distance=np.ones((2, 2)), points_xy=np.zeros((2, 2)))
    with pytest.raises(SettingsError, match="not the Euclidean distances"):
        write_gtsplib(skewed, "x")
    good = _random_instance(3, depot=True)
    blocker = _write(tmp_path, "file", "not a folder")
    with pytest.raises(OutputError, match="--export-gtsp") as info:
        export_gtsplib(good, blocker / "x.gtsp")
    assert "\n" not in str(info.value)
    written = export_gtsplib(good, tmp_path / "sub" / "ok.gtsp")
    assert written.read_text().startswith("NAME : ok\n")
    assert sorted(p.name for p in written.parent.iterdir()) == ["ok.gtsp"]
