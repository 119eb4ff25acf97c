"""The K-tree bound of sorties: never above the shortest plan of at least K sorties, found by
brute force over every partition of a handful of points (every order of every part), and
above the single tour where the returns home are what the plan pays for."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.sortie_brute import partitions_by_count, sortie_time, subsets

from urpt_gcs.bound.k_tree import k_tree_bound
from urpt_gcs.bound.sorties import SortieBudget, sortie_bound
from urpt_gcs.problem.flight_time import FlightModel

HOME = (0.0, 0.0)


def _shortest_plans(points: np.ndarray) -> list[float]:
    """Per count k of sorties (index k), the shortest plan of exactly k non-empty sorties
    from home through the points (each sortie the shortest through its part)."""
    short, _, _ = subsets(points, FlightModel.arducopter(5.0, 2.0), math.inf, HOME, 30.0)
    return partitions_by_count(short, len(points))


def _layout(seed: int, far: bool) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if far:  # a cluster far from home: every sortie flies out and back
        return rng.uniform(0.0, 60.0, (7, 2)) + np.array([400.0, 300.0])
    return rng.uniform(-200.0, 200.0, (7, 2))


@pytest.mark.parametrize("far", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_never_above_the_shortest_plan_of_at_least_k_sorties(seed: int, far: bool) -> None:
    points = _layout(seed, far)
    plans = _shortest_plans(points)
    distance = np.hypot(*(points - np.asarray(HOME)).T)
    for at_least in (1, 2, 3, 5):
        bound, _ = k_tree_bound(points, np.zeros(len(points)), distance, at_least, math.inf, 0.5)
        assert 0.0 < bound <= min(plans[at_least:]) * (1.0 + 1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_a_count_raised_by_the_bound_goes_on_over_that_many(seed: int) -> None:
    """Started over one sortie, told by its recount that its length proves three: it goes on
    over three, the count it returns, and stays under the shortest plan of three or more."""
    points = _layout(seed, far=True)
    plans = _shortest_plans(points)
    distance = np.hypot(*(points - np.asarray(HOME)).T)
    asked: list[float] = []

    def recount(length_m: float) -> int:
        asked.append(length_m)
        return 3

    bound, count = k_tree_bound(points, np.zeros(7), distance, 1, math.inf, 0.5, recount)
    assert asked and count == 3
    assert bound <= min(plans[3:]) * (1.0 + 1e-9)
    alone, _ = k_tree_bound(points, np.zeros(7), distance, 1, math.inf, 0.5)
    assert bound > alone


@pytest.mark.parametrize("seed", range(4))
def test_counts_the_returns_home_of_far_sorties(seed: int) -> None:
    """Three sorties to a cluster far away fly out and back three times: the bound sees most
    of that, where the single tour's optimum (one out and back) cannot."""
    points = _layout(seed, far=True)
    plans = _shortest_plans(points)
    distance = np.hypot(*(points - np.asarray(HOME)).T)
    bound, _ = k_tree_bound(points, np.zeros(len(points)), distance, 3, math.inf, 0.5)
    assert bound >= plans[1] + 0.9 * 2.0 * 2.0 * float(distance.min())
    assert bound >= 0.95 * min(plans[3:])


def test_discs_and_the_sortie_bound_take_it_where_two_sorties_are_needed() -> None:
    """Discs far from home under an endurance that lets a sortie fly to any one of them but
    not to all: the sortie bound is at least the K-tree's over the discs, and both stay
    under the plan of a sortie per disc, to its nearest point and back."""
    rng = np.random.default_rng(3)
    centres = rng.uniform(0.0, 80.0, (8, 2)) + np.array([600.0, 0.0])
    reach = np.full(8, 5.0)
    distance = np.hypot(*centres.T) - reach
    nearest = centres * (distance / (distance + reach))[:, None]
    model = FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0)
    alone = [sortie_time(model, p[None, :], HOME, 30.0) for p in nearest]
    budget = SortieBudget.of(model, 30.0, 1.05 * max(alone))
    single, _ = k_tree_bound(centres, reach, distance, 1, math.inf, 0.5)
    found = sortie_bound(centres, reach, distance, single, budget, math.inf, 0.5)
    assert 2 <= found.sorties <= len(centres)
    tree, _ = k_tree_bound(centres, reach, distance, found.sorties, math.inf, 0.5)
    assert found.length_m >= tree * (1.0 - 1e-9)
    assert found.length_m <= float(2.0 * distance.sum()) * (1.0 + 1e-9)
