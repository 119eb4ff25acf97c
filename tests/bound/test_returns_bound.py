"""The order search with the depot's copies: a bound of flights of at least K sorties from
home. On points it is the shortest plan of exactly K non-empty sorties, found by brute force
over every partition and order (and every plan of more sorties is no shorter, merged); on
the planner's path it raises the sortie bound above the single tour."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.sortie_brute import partitions_by_count, subsets

from urpt_gcs.bound.lower_bound import returns_bound, sorties_through
from urpt_gcs.bound.order_bound import order_bound
from urpt_gcs.bound.sorties import SortieBudget, sortie_bound
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.regions import OuterStar, RegionSet

HOME = (0.0, 0.0)
MODEL = FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0)


def _plans(points: np.ndarray, endurance_s: float = math.inf) -> list[float]:
    """Per count k (index k), the shortest plan of exactly k non-empty sorties from home
    through the points, each sortie the shortest through its part within the endurance."""
    short, _, _ = subsets(points, MODEL, endurance_s, HOME, 30.0)
    return partitions_by_count(short, len(points))


def _points(seed: int, far: bool) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if far:  # a cluster away from home: every sortie flies out and back
        return rng.uniform(0.0, 80.0, (6, 2)) + np.array([300.0, 200.0])
    return rng.uniform(-150.0, 150.0, (6, 2))


def _stars(points: np.ndarray, reach: float = 0.0) -> list[OuterStar | None]:
    return [*(OuterStar((float(x), float(y)), np.full(8, reach)) for x, y in points), None]


@pytest.mark.parametrize("far", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_on_points_it_is_the_shortest_plan_of_k_sorties(seed: int, far: bool) -> None:
    points = _points(seed, far)
    plans = _plans(points)
    for k in (1, 2, 3):
        found = order_bound(_stars(points), HOME, math.inf, 30.0, returns=k - 1)
        assert found.finished
        assert found.value <= min(plans[k:]) * (1.0 + 1e-6)
        assert found.value >= plans[k] * (1.0 - 1e-6)
    # Each return home costs something here: a test that the copies are really inserted.
    assert plans[3] > plans[2] > plans[1]


def test_on_discs_it_stays_under_every_plan_through_points_of_the_discs() -> None:
    """Discs of radius 12: any plan through one point of each disc is a plan for the discs,
    so the bound stays under the brute-force plans through the centres and rises with K."""
    points = _points(1, far=True)
    plans = _plans(points)
    values = [
        order_bound(_stars(points, 12.0), HOME, math.inf, 30.0, returns=k - 1).value
        for k in (1, 2, 3)
    ]
    for k, value in zip((1, 2, 3), values, strict=True):
        assert value <= min(plans[k:]) * (1.0 + 1e-9)
    assert values[0] < values[1] < values[2]


def test_the_returns_need_the_depot_last() -> None:
    points = _points(0, far=False)
    with pytest.raises(ValueError, match="depot"):
        order_bound(_stars(points)[:-1], None, math.inf, 1.0, returns=1)
    regions = RegionSet(discs=np.column_stack([points, np.full(len(points), 1.0)]))
    with pytest.raises(ValueError, match="depot"):
        returns_bound(regions, math.inf, 1.0, 1)
    assert sorties_through(regions, math.inf) is None


@pytest.mark.parametrize("seed", range(3))
def test_the_sortie_bound_takes_it_where_two_sorties_are_needed(seed: int) -> None:
    """Discs of radius 15 around home under an endurance of 80 % of the quickest single
    sortie through their centres: two sorties or more are proven, the sortie bound takes
    the order search over that many (above what it proves without it), and stays under the
    brute-force plans through the centres of that many sorties or more within the
    endurance (plans for the discs too)."""
    points = _points(seed, far=False)
    reach = np.full(len(points), 15.0)
    regions = RegionSet(discs=np.column_stack([points, reach]), depot_xy=HOME)
    distance = np.maximum(np.hypot(*points.T) - reach, 0.0)
    single = order_bound(_stars(points, 15.0), HOME, math.inf, 30.0).value
    _, quick, _ = subsets(points, MODEL, math.inf, HOME, 30.0)
    endurance = 0.8 * float(quick[-1])
    budget = SortieBudget.of(MODEL, 30.0, endurance)
    through = sorties_through(regions, math.inf)
    assert through is not None
    alone = sortie_bound(points, reach, distance, single, budget, math.inf, 2.0)
    found = sortie_bound(points, reach, distance, single, budget, math.inf, 2.0, through)
    assert found.sorties >= 2
    again = returns_bound(regions, math.inf, 10.0, found.sorties - 1)
    assert found.length_m >= again.value * (1.0 - 1e-6)
    assert found.length_m > alone.length_m * 1.01
    assert found.length_m <= min(_plans(points, endurance)[found.sorties :]) * (1.0 + 1e-9)
