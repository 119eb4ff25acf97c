"""The continuous problem from regions alone: refinement, the solve path and ``bench cetsp``."""

from __future__ import annotations

import csv

import numpy as np
from click.testing import CliRunner

from urpt_gcs.bench.cetsp import COLUMNS
from urpt_gcs.cli import main
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.continuous import solve_regions
from urpt_gcs.solvers.refine import best_on_disc, closed_length, refine_touches
from urpt_gcs.solvers.regions import RegionSet


def test_best_point_on_a_disc_matches_a_dense_search() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, b = rng.uniform(-10, 10, 2), rng.uniform(-10, 10, 2)
        c, r = rng.uniform(-10, 10, 2), rng.uniform(0.5, 4.0)
        p = np.asarray(best_on_disc(*a, *b, *c, r))
        rr = np.sqrt(rng.uniform(0, 1, 200_000)) * r
        t = rng.uniform(0, 2 * np.pi, 200_000)
        q = c + np.column_stack([rr * np.cos(t), rr * np.sin(t)])
        dense = np.min(np.hypot(*(q - a).T) + np.hypot(*(q - b).T))
        got = np.hypot(*(p - a)) + np.hypot(*(p - b))
        assert np.hypot(*(p - c)) <= r * (1 + 1e-9)
        assert got <= dense + 1e-6


def test_refinement_never_lengthens_and_stays_inside() -> None:
    rng = np.random.default_rng(1)
    n = 12
    discs = np.column_stack([rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(2, 9, n)])
    regions = RegionSet(discs=discs, depot_xy=(50.0, 50.0))
    seq = np.arange(n)
    start = discs[:, :2].copy()  # the centres: a tour through the discs, far from the best
    refined = refine_touches(regions, seq, start)
    assert regions.contains(refined, seq).all()
    before, after = closed_length(start, regions.depot_xy), closed_length(refined, regions.depot_xy)
    # Each disc lets its leg pair shorten by up to twice its radius: a real gain, bounded.
    assert before - 2 * discs[:, 2].sum() - 1e-9 <= after < before


def test_solve_regions_enters_every_disc_and_brackets_the_optimum() -> None:
    # Discs on a circle of radius 20 around the depot: the tour is about the circle through
    # their inner rims, 2 pi (20 - r), give or take the chords.
    k, r = 10, 2.0
    a = 2 * np.pi * np.arange(k) / k
    discs = np.column_stack([20 * np.cos(a), 20 * np.sin(a), np.full(k, r)])
    regions = RegionSet(discs=discs, depot_xy=(18.0, 0.0))
    tour = solve_regions(regions, SolveSettings(time_limit_s=2.0))
    seen = regions.contains(tour.touch_xy, tour.touch_region)
    assert seen.all() and sorted(tour.touch_region.tolist()) == list(range(k))
    polygon = k * 2 * (20 - r) * np.sin(np.pi / k)  # the inscribed polygon through inner rims
    assert tour.length <= polygon * 1.001
    assert tour.length <= tour.discrete_length + 1e-9
    assert 0.0 < tour.lower_bound <= tour.length


def test_bench_cetsp_writes_the_columns(tmp_path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "instances").mkdir()
    (tmp_path / "instances" / "square.txt").write_text(
        "# square source=here depot=0,0\n10 0 1\n10 10 1\n0 10 1\n"
    )
    (tmp_path / "best_known.csv").write_text(
        "name,n_discs,depot,best_known_length,best_known_source,proven_optimal,lower_bound,notes\n"
        "square,3,yes,34.0,here,no,,\n"
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["bench", "cetsp", str(tmp_path), "--time-limit", "1", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS
    length, bound = float(rows[0]["length"]), float(rows[0]["lower_bound"])
    # Brute force: one rim point per disc (the best touch is on the rim), every order.
    t = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    rims = [
        np.column_stack([x + np.cos(t), y + np.sin(t)]) for x, y in ((10, 0), (10, 10), (0, 10))
    ]
    brute = np.inf
    for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2)):
        p, q, w = (rims[i] for i in order)
        pq = np.hypot(p[:, None, 0] - q[None, :, 0], p[:, None, 1] - q[None, :, 1])
        qw = np.hypot(q[:, None, 0] - w[None, :, 0], q[:, None, 1] - w[None, :, 1])
        total = np.hypot(*p.T)[:, None, None] + pq[:, :, None] + qw[None] + np.hypot(*w.T)
        brute = min(brute, float(total.min()))
    assert bound <= length <= brute + 1e-9
    assert length >= brute - 0.01  # the grid is fine: 4 degrees of rim
    assert float(rows[0]["best_known"]) == 34.0


def test_bench_cetsp_refuses_a_folder_without_instances(tmp_path) -> None:  # type: ignore[no-untyped-def]
    result = CliRunner().invoke(main, ["bench", "cetsp", str(tmp_path)])
    assert result.exit_code == 1
    assert "instances/" in result.output and "Traceback" not in result.output
