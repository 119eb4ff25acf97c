"""The tube bound against independent figures: the union's area against shapely's polygons
inside and outside every disc, the sweep's inequality against shapely's buffers of random
flights, and the bound against brute-force tours and proven CETSP optima."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from conftest import CETSP, needs_shared
from support.brute_tours import small_discs
from support.cetsp import proven_optima

from urpt_gcs.bench.cetsp import read_instance
from urpt_gcs.bound.lower_bound import lower_bound
from urpt_gcs.bound.tube import tube_bound, union_area
from urpt_gcs.problem.regions import RegionSet

_SEGS = 64


def _shapely_union(xy: np.ndarray, r: np.ndarray, outside: bool) -> float:
    """The union's area with each disc an inscribed polygon (vertices on the circle) or,
    ``outside``, one whose edges touch the circle from outside."""
    keep = r > 0
    grow = 1.0 / math.cos(math.pi / (4 * _SEGS)) if outside else 1.0
    polys = shapely.buffer(shapely.points(xy[keep]), r[keep] * grow, quad_segs=_SEGS)
    return float(shapely.union_all(polys).area) if polys.size else 0.0


@pytest.mark.parametrize("seed", range(8))
def test_union_area_lies_between_polygons_inside_and_outside_the_discs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    # Far from the origin, as a projected CRS puts a site.
    xy = rng.uniform(0, 300, (n, 2)) + np.array([500_000.0, 5_200_000.0])
    r = rng.uniform(-5.0, 30.0, n)
    if seed % 2:
        # Identical discs, one inside another, and tangent pairs.
        xy[1::7] = xy[0::7][: len(xy[1::7])]
        r[1::7] = r[0::7][: len(r[1::7])]
        r[2::9] = 1.0
        if n > 3:
            xy[3] = xy[2] + (r[2] + 7.0, 0.0)
            r[3] = 7.0
    got = union_area(xy, r)
    inside = _shapely_union(xy, r, outside=False)
    outside = _shapely_union(xy, r, outside=True)
    assert inside <= got <= outside
    assert got >= inside - 1e-9  # below the truth, but by no more than the polygons are


def test_union_area_of_one_disc_and_of_disjoint_ones() -> None:
    assert union_area(np.array([[3.0, 4.0]]), np.array([10.0])) == pytest.approx(
        math.pi * 100.0, rel=1e-6
    )
    xy = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    assert union_area(xy, np.array([1.0, 2.0, 3.0])) == pytest.approx(14.0 * math.pi, rel=1e-6)
    assert union_area(xy, np.array([-1.0, 0.0, 0.0])) == 0.0


@pytest.mark.parametrize("seed", range(10))
def test_a_flights_tube_covers_at_most_pi_s2_plus_2_s_l(seed: int) -> None:
    """The sweep's inequality, on shapely's buffer of random closed flights (some crossing
    themselves, several from one home)."""
    rng = np.random.default_rng(seed)
    s = float(rng.uniform(1.0, 40.0))
    home = np.zeros((1, 2))
    lines, total = [], 0.0
    for _ in range(int(rng.integers(1, 4))):
        pts = np.vstack([home, rng.uniform(-60, 60, (int(rng.integers(1, 12)), 2)), home])
        total += float(np.hypot(*np.diff(pts, axis=0).T).sum())
        lines.append(shapely.LineString(pts))
    # Inscribed polygons: below the tube's true area by a hair.
    tube = shapely.union_all([ln.buffer(s, quad_segs=_SEGS) for ln in lines]).area
    assert tube <= math.pi * s * s + 2.0 * s * total


@pytest.mark.parametrize("seed", range(6))
def test_tube_bound_never_above_a_brute_force_tour(seed: int) -> None:
    # Crowded discs, where the tube is positive.
    discs, depot, brute = small_discs(40 + seed, 12.0, 2.0, 7)
    got, s = tube_bound(discs[:, :2], discs[:, 2], depot)
    assert got <= brute * (1.0 + 1e-9)
    assert got == 0.0 or s > 0.0


@needs_shared("bench/cetsp")
@pytest.mark.parametrize(("name", "optimum"), proven_optima(CETSP, 1000))
def test_tube_bound_never_above_a_proven_cetsp_optimum(name: str, optimum: float) -> None:
    regions = read_instance(CETSP / "instances" / f"{name}.txt")
    assert regions.discs is not None
    got, _ = tube_bound(regions.discs[:, :2], regions.discs[:, 2], regions.depot_xy)
    assert got <= optimum * (1.0 + 1e-9)


def test_on_crowded_regions_the_bound_counts_them_all() -> None:
    """1000 overlapping discs: the order search over 150 far apart sees few gaps between
    them, the tube counts every disc. The automatic bound takes the tube's, and stays below
    a real tour (a boustrophedon over the rows of a grid every disc meets)."""
    rng = np.random.default_rng(3)
    n, side = 1000, 3000.0
    discs = np.column_stack([rng.uniform(0, side, (n, 2)), rng.uniform(20.0, 80.0, n)])
    regions = RegionSet(discs=discs, depot_xy=(side / 2, side / 2))
    # A tour: rows 2 * 20 m apart, each disc's centre within 20 m of a row (its radius is at
    # least 20), joined end to end and back home.
    rows = np.arange(20.0, side, 40.0)
    xs = [(0.0, side) if k % 2 == 0 else (side, 0.0) for k in range(len(rows))]
    pts = [(side / 2, side / 2)] + [(x, y) for y, ends in zip(rows, xs, strict=True) for x in ends]
    pts.append((side / 2, side / 2))
    tour = float(np.hypot(*np.diff(np.asarray(pts), axis=0).T).sum())
    bound = lower_bound(regions, upper=tour, time_limit_s=1.0)
    tube, _ = tube_bound(discs[:, :2], discs[:, 2], regions.depot_xy)
    assert bound.method.startswith("tube")
    assert bound.value == pytest.approx(tube)
    assert tube <= tour


def test_radii_with_too_many_overlapping_pairs_are_not_tried(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Above the pairs' cap a radius is skipped (its arrays are never made), and the bound
    keeps the best of the radii below it: never more than with every radius tried."""
    import urpt_gcs.bound.tube as tube

    rng = np.random.default_rng(9)
    xy = rng.uniform(0, 1000.0, (600, 2))
    reach = rng.uniform(10.0, 30.0, 600)
    full, _ = tube_bound(xy, reach, (500.0, 500.0))
    monkeypatch.setattr(tube, "TUBE_MAX_PAIRS", 400)
    assert math.isnan(union_area(xy, np.full(600, 60.0)))
    capped, s = tube_bound(xy, reach, (500.0, 500.0))
    assert 0.0 <= capped <= full
    assert capped == 0.0 or s > 0.0
