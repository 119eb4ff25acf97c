"""Sharing the targets out among vehicles that cannot all help: a vehicle too slow to shorten
the fleet's flight, or too short of endurance to reach any target, is left idle; vehicles
that each reach only part of the site share it; and only a target no vehicle reaches makes
the fleet refused, in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.instance import Geometry, Instance
from urpt_gcs.solvers import solve
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.fleet import FleetTours, Vehicle, naive_split, solve_fleet
from urpt_gcs.solvers.fleet_split import reach_split

ALTITUDE_M = 40.0


def _line(
    homes: list[tuple[float, float]], speeds: list[float], endurance_s: list[float | None]
) -> tuple[list[Vehicle], Instance]:
    """Six targets on a line 100 m apart (x = 100 .. 600), two viewpoints each within 5 m,
    one vehicle per home."""
    targets = np.column_stack([np.arange(1, 7) * 100.0, np.zeros(6)])
    points = np.repeat(targets, 2, axis=0) + np.tile([[0.0, 5.0], [0.0, -5.0]], (6, 1))
    vp = np.arange(12)
    tg = vp // 2
    geometry = Geometry(targets, np.zeros(6), ALTITUDE_M, 30.0, 0.0)
    vehicles = [
        Vehicle(
            Instance.from_cover_pairs(vp, tg, points, 6, depot_xy=home, geometry=geometry),
            FlightModel.arducopter(cruise_m_s=speed, hold_s=2.0),
            ALTITUDE_M,
            endurance,
        )
        for home, speed, endurance in zip(homes, speeds, endurance_s, strict=True)
    ]
    return vehicles, vehicles[0].instance


def _fleet(vehicles: list[Vehicle], reference: Instance) -> tuple[FleetTours, float]:
    """The fleet's tours, and the first vehicle flying the single tour alone."""
    single = solve(reference, "exact", SolveSettings(time_limit_s=0.5))
    tours = solve_fleet(vehicles, single.order, reference, "exact", SolveSettings(1.0))
    assert reference.points_xy is not None
    alone = vehicles[0].time_s(reference.points_xy[list(single.order)])
    return tours, alone


def _covered(vehicles: list[Vehicle], tours: FleetTours) -> None:
    """Every target seen by some vehicle's stops and counted for exactly one, and each
    flight's time as measured again here."""
    seen = np.zeros(vehicles[0].instance.n_targets, dtype=bool)
    for vehicle, order, time_s in zip(vehicles, tours.orders, tours.times_s, strict=True):
        seen |= vehicle.instance.covers.seen(list(order))
        assert vehicle.instance.points_xy is not None
        assert vehicle.time_s(vehicle.instance.points_xy[list(order)]) == pytest.approx(time_s)
        assert math.isfinite(time_s)
    assert seen.all()
    counted = sorted(t for share in tours.targets for t in share)
    assert counted == list(range(vehicles[0].instance.n_targets))


@pytest.mark.parametrize("endurance_s", [None, 1200.0])
def test_a_vehicle_too_slow_to_help_is_left_idle(endurance_s: float | None) -> None:
    """At 0.1 m/s its quickest flight to one target is longer than the other's whole tour:
    it flies nothing, and the fleet lands no later than the fast vehicle alone."""
    vehicles, reference = _line([(0.0, 0.0)] * 2, [5.0, 0.1], [endurance_s] * 2)
    tours, alone = _fleet(vehicles, reference)
    _covered(vehicles, tours)
    assert tours.idle == (1,)
    assert tours.orders[1] == () and tours.targets[1] == () and tours.times_s[1] == 0.0
    assert tours.makespan_s <= alone + 1e-9


def test_a_vehicle_that_reaches_no_target_is_left_idle() -> None:
    """Its home is so far that no target is within its endurance: it flies nothing."""
    vehicles, reference = _line([(0.0, 0.0), (5000.0, 5000.0)], [5.0, 5.0], [None, 300.0])
    assert not vehicles[1].flyable().any()
    tours, alone = _fleet(vehicles, reference)
    _covered(vehicles, tours)
    assert tours.idle == (1,)
    assert tours.makespan_s <= alone + 1e-9


def test_vehicles_that_each_reach_part_of_the_site_share_it() -> None:
    """From either end of the line neither vehicle reaches the far end within its endurance,
    so neither can fly the single tour; between them they reach every target."""
    homes = [(-400.0, 0.0), (1100.0, 0.0)]
    vehicles, reference = _line(homes, [5.0, 5.0], [300.0, 300.0])
    reach = [v.instance.covers.seen(np.flatnonzero(v.flyable()).tolist()) for v in vehicles]
    assert not reach[0].all() and not reach[1].all() and (reach[0] | reach[1]).all()
    tours, _ = _fleet(vehicles, reference)
    _covered(vehicles, tours)
    assert tours.idle == ()
    # Where no cut of the tour fits, each target goes to a vehicle that reaches it.
    orders = reach_split(vehicles, list(range(6)), [0.0, 0.0])
    seen = np.zeros(6, dtype=bool)
    for vehicle, order in zip(vehicles, orders, strict=True):
        seen |= vehicle.instance.covers.seen(order)
        assert vehicle.instance.points_xy is not None
        assert math.isfinite(vehicle.time_s(vehicle.instance.points_xy[order]))
    assert seen.all()


def test_a_target_no_vehicle_reaches_is_refused_in_one_line() -> None:
    vehicles, reference = _line([(-600.0, 0.0), (-700.0, 0.0)], [5.0, 5.0], [300.0, 300.0])
    with pytest.raises(SettingsError) as caught:
        _fleet(vehicles, reference)
    message = str(caught.value)
    assert "\n" not in message
    assert "vehicles 1, 2" in message and "endurance" in message


def test_vehicles_alike_all_get_a_piece_of_the_naive_split() -> None:
    """Idle is for a vehicle that cannot help: vehicles alike share the tour among them."""
    vehicles, reference = _line([(0.0, 0.0)] * 3, [5.0] * 3, [None] * 3)
    single = solve(reference, "exact", SolveSettings(time_limit_s=0.5))
    pieces, times, cut = naive_split(vehicles, single.order, reference)
    assert all(pieces) and all(cut) and all(t > 0.0 for t in times)
