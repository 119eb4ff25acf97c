"""PyVRP beside our sortie planning on a tiny instance: both sides see every target once, fit
the endurance, and report the total the flight-time model gives their sorties."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("pyvrp", reason="PyVRP is not installed (the bench extra)")

from urpt_gcs.bench.pyvrp_sorties import (
    TICKS_PER_S,
    SortieRun,
    best_viewpoint_instance,
    check_sorties,
    one_target_instance,
    our_sorties,
    pyvrp_data,
    pyvrp_sorties,
)
from urpt_gcs.pipeline.missions import flight_model
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.instance import Geometry, Instance

ALTITUDE_M = 60.0
ENDURANCE_S = 300.0
MODEL = flight_model(PlanSettings())
HOME = (0.0, 0.0)


def _instance() -> Instance:
    """Ten targets 150-450 m around home, three one-target viewpoints each, and a viewpoint
    seeing two targets (which the restriction drops)."""
    rng = np.random.default_rng(7)
    angle = rng.uniform(0.0, 2.0 * math.pi, 10)
    radius = rng.uniform(150.0, 450.0, 10)
    targets = np.c_[radius * np.cos(angle), radius * np.sin(angle)]
    points = np.vstack([targets + rng.normal(0.0, 20.0, (10, 2)) for _ in range(3)])
    vp = list(range(30))
    tg = [k % 10 for k in range(30)]
    points = np.vstack([points, (targets[0] + targets[1]) / 2.0])
    vp += [30, 30]
    tg += [0, 1]
    return Instance.from_cover_pairs(
        vp,
        tg,
        points,
        10,
        depot_xy=HOME,
        geometry=Geometry(targets, np.zeros(10), ALTITUDE_M, 30.0, 0.0),
    )


def _checked(instance: Instance, run: SortieRun) -> float:
    check = check_sorties(instance, run.routes, ALTITUDE_M, MODEL, ENDURANCE_S)
    assert run.feasible
    assert check.uncovered == ()
    assert check.repeated == ()
    assert check.over_endurance == ()
    assert check.longest_s <= ENDURANCE_S
    # The side's own total is the model's, up to PyVRP's times in whole ticks rounded up.
    stops = sum(len(r) for r in run.routes)
    legs = stops + len(run.routes)
    slack = (legs + stops + 2 * len(run.routes)) / TICKS_PER_S
    assert check.flight_time_s - 1e-6 <= run.reported_s <= check.flight_time_s + slack
    return check.flight_time_s


def test_one_target_instance_drops_the_shared_viewpoint() -> None:
    full = _instance()
    restricted, kept_vp, kept_t = one_target_instance(full)
    assert restricted.n_viewpoints == 30
    assert 30 not in kept_vp.tolist()
    assert kept_t.tolist() == list(range(10))
    best, chosen = best_viewpoint_instance(restricted)
    assert best.n_viewpoints == best.n_targets == 10
    assert restricted.geometry is not None and restricted.points_xy is not None
    off = np.hypot(*(restricted.points_xy[chosen] - restricted.geometry.targets_xy).T)
    for t in range(10):
        near = np.hypot(*(restricted.points_xy[t::10] - restricted.geometry.targets_xy[t]).T)
        assert off[t] == pytest.approx(near.min())


def test_pyvrp_data_times_the_legs_as_the_model() -> None:
    restricted, _, _ = one_target_instance(_instance())
    data = pyvrp_data(restricted, ALTITUDE_M, MODEL, ENDURANCE_S)
    assert restricted.points_xy is not None
    matrix = data.duration_matrix(profile=0)
    d = float(np.hypot(*restricted.points_xy[4]))
    out, back = float(MODEL.leg_s(d)), float(MODEL.return_s(d))
    assert out != back
    assert matrix[0, 5] == math.ceil(out * TICKS_PER_S)
    assert matrix[5, 0] == math.ceil(back * TICKS_PER_S)
    assert data.num_groups == 10
    assert data.vehicle_type(0).shift_duration == ENDURANCE_S * TICKS_PER_S


@pytest.mark.parametrize("form", ["groups", "best"])
def test_both_sides_see_every_target_within_the_endurance(form: str) -> None:
    restricted, _, _ = one_target_instance(_instance())
    instance = restricted if form == "groups" else best_viewpoint_instance(restricted)[0]
    ours = our_sorties(instance, ALTITUDE_M, MODEL, ENDURANCE_S, 1.0, seed=0)
    theirs = pyvrp_sorties(instance, ALTITUDE_M, MODEL, ENDURANCE_S, 1.0, seed=0)
    assert len(ours.routes) >= 2  # the endurance cuts the flight
    ours_s, theirs_s = _checked(instance, ours), _checked(instance, theirs)
    # Ten targets: both sides are within a few per cent of each other.
    assert abs(theirs_s / ours_s - 1.0) < 0.1
