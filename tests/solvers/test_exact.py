"""The exact solver against brute-force enumeration on small random instances."""

from __future__ import annotations

import itertools
import math

import pytest
from support.instances import random_instance

from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers import SolveSettings, choose, prepare, solve
from urpt_gcs.solvers.exact import ExactSolver, exact_work, greedy_order, search_exact


@pytest.fixture(scope="module", autouse=True)
def _compiled() -> None:
    """Compile the kernels before any time limit runs: on a cold cache the first solve would
    spend its limit compiling and end unproven."""
    prepare("exact")


def _brute_force(inst: Instance) -> float:
    """Shortest closed tour over every ordered subset of viewpoints that sees every target."""
    n = inst.n_viewpoints
    best = math.inf
    for k in range(1, n + 1):
        for subset in itertools.combinations(range(n), k):
            if inst.uncovered(subset):
                continue
            for perm in itertools.permutations(subset):
                if not inst.has_depot and perm[0] != subset[0]:
                    continue  # a cycle: fix its first element
                best = min(best, inst.tour_length(perm))
    return best


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("depot", [True, False])
def test_exact_equals_brute_force(seed: int, depot: bool) -> None:
    inst = random_instance(seed, n=7, m=4, depot=depot, overlap=0.25)
    tour = solve(inst, "exact")
    assert tour.proven_optimal
    assert inst.uncovered(list(tour.order)) == []
    assert tour.length == pytest.approx(_brute_force(inst), rel=1e-9)
    assert tour.length == pytest.approx(inst.tour_length(list(tour.order)), rel=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_exact_equals_brute_force_asymmetric(seed: int) -> None:
    inst = random_instance(100 + seed, n=7, m=3, depot=seed % 2 == 0, asymmetric=True, overlap=0.0)
    tour = solve(inst, "exact")
    assert tour.length == pytest.approx(_brute_force(inst), rel=1e-9)


def test_auto_picks_exact_when_it_fits() -> None:
    small = random_instance(1, n=60, m=8, depot=True)
    assert exact_work(small).fits_budget
    assert choose(small) == "exact"
    tour = solve(small, "auto", SolveSettings(time_limit_s=1.0))
    other = solve(small, "ortools", SolveSettings(time_limit_s=1.0))
    assert tour.proven_optimal and tour.length <= other.length + 1e-9


@pytest.mark.parametrize("depot", [True, False])
def test_stopped_early_it_keeps_a_covering_tour_and_a_valid_bound(depot: bool) -> None:
    inst = random_instance(3, n=40, m=10, depot=depot, overlap=0.1)
    seed = greedy_order(inst)
    whole = search_exact(inst, seed)
    assert whole.proven and whole.work > 1000
    for work_limit in (1, whole.work // 100, whole.work // 3):
        tour = ExactSolver(work_limit=work_limit).solve(inst, SolveSettings(time_limit_s=600.0))
        assert not tour.proven_optimal, work_limit
        assert inst.uncovered(list(tour.order)) == []
        assert tour.length == pytest.approx(inst.tour_length(list(tour.order)), rel=1e-12)
        assert 0.0 <= tour.lower_bound <= whole.length + 1e-9 <= tour.length + 1e-9
        assert any("stopped at the time limit" in note for note in tour.notes)
        # The work count, not the clock, decides where it stops.
        stopped = search_exact(inst, seed, work_limit=work_limit)
        again = search_exact(inst, seed, work_limit=work_limit)
        assert stopped == again and not stopped.proven and stopped.work >= work_limit
        assert stopped.lower_bound <= whole.length + 1e-9


def test_a_deadline_already_past_still_answers_with_a_tour() -> None:
    inst = random_instance(4, n=30, m=8, depot=False)
    found = search_exact(inst, deadline=0.0)
    assert not found.proven and found.work == 0
    assert inst.uncovered(list(found.order)) == []
    assert found.lower_bound <= solve(inst, "exact").length + 1e-9
