"""The stop packing: never more stops than the fewest points that meet every circle (found
by brute force over every cell of the circles' arrangement), and not vacuous."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from support.sortie_brute import VARIED_MODELS

from urpt_gcs.bound.geometric import stop_packing
from urpt_gcs.bound.sorties import least_extra_s
from urpt_gcs.problem.flight_time import FlightModel


def _options(xy: np.ndarray, r: np.ndarray) -> list[frozenset[int]]:
    """The sets of circles one point can meet: at every crossing of two circles (as complex
    numbers), every centre, and a dense grid over their bounding box."""
    c = xy[:, 0] + 1j * xy[:, 1]
    points = list(c)
    for i, j in itertools.combinations(range(len(c)), 2):
        d = abs(c[j] - c[i])
        if d == 0.0 or d > r[i] + r[j] or d < abs(r[i] - r[j]):
            continue
        along = (r[i] ** 2 - r[j] ** 2 + d * d) / (2.0 * d)
        up = math.sqrt(max(r[i] ** 2 - along**2, 0.0))
        unit = (c[j] - c[i]) / d
        points += [c[i] + unit * (along + 1j * up), c[i] + unit * (along - 1j * up)]
    lo, hi = (xy - r[:, None]).min(axis=0), (xy + r[:, None]).max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 120), np.linspace(lo[1], hi[1], 120))
    points += list((gx + 1j * gy).ravel())
    p = np.asarray(points)
    inside = np.abs(p[:, None] - c[None, :]) <= r[None, :] * (1.0 + 1e-9) + 1e-7
    return list({frozenset(np.flatnonzero(row).tolist()) for row in inside if row.any()})


def _fewest(n: int, options: list[frozenset[int]]) -> int:
    """The fewest options that hold every circle between them."""
    everything = frozenset(range(n))
    maximal = [o for o in options if not any(o < other for other in options)]
    for k in range(1, n + 1):
        for pick in itertools.combinations(maximal, k):
            if frozenset().union(*pick) == everything:
                return k
    raise AssertionError("no cover")


@pytest.mark.parametrize("seed", range(12))
def test_packing_never_counts_more_stops_than_the_fewest(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5 + seed % 4
    xy = rng.uniform(0.0, 100.0 if seed % 2 else 60.0, (n, 2))
    r = rng.uniform(8.0, 30.0, n)
    y = stop_packing(xy, r)
    assert (y >= 0.0).all()
    fewest = _fewest(n, _options(xy, r))
    assert y.sum() <= fewest + 1e-9
    # Every subset's weight is at most the fewest points meeting that subset.
    sub = np.arange(n)[: n // 2 + 1]
    sub_fewest = _fewest(len(sub), _options(xy[sub], r[sub]))
    assert y[sub].sum() <= sub_fewest + 1e-9


def test_circles_through_one_point_weigh_one() -> None:
    p = np.array([40.0, -25.0])
    a = np.linspace(0.0, 2.0 * math.pi, 7, endpoint=False)
    r = np.linspace(5.0, 30.0, 7)
    xy = p + r[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    assert stop_packing(xy, r).sum() <= 1.0 + 1e-9


def test_nested_and_touching_circles() -> None:
    """A circle inside another, and two that touch: one point meets each pair."""
    xy = np.array([[0.0, 0.0], [3.0, 0.0], [100.0, 0.0], [120.0, 0.0]])
    r = np.array([10.0, 2.0, 10.0, 10.0])
    y = stop_packing(xy, r)
    assert y[:2].sum() <= 1.0 + 1e-9
    assert y[2:].sum() <= 1.0 + 1e-9


def test_packing_is_not_vacuous() -> None:
    """Disjoint circles each need a stop; a chain of circles each crossing the next needs
    every other one."""
    xy = np.column_stack([np.arange(6) * 50.0, np.zeros(6)])
    assert stop_packing(xy, np.full(6, 10.0)).sum() == pytest.approx(6.0, abs=1e-6)
    chain = np.column_stack([np.arange(7) * 15.0, np.zeros(7)])
    assert stop_packing(chain, np.full(7, 10.0)).sum() == pytest.approx(4.0, abs=1e-6)


@pytest.mark.parametrize("model", VARIED_MODELS)
def test_least_extra_is_under_every_longer_leg_and_close(model: FlightModel) -> None:
    leg_from, extra = model.cruise_overhead()
    d = np.linspace(0.0, 2.0 * leg_from, 20_001)
    over = np.asarray(model.leg_s(d)) - d / model.cruise_m_s
    for share in (0.01, 0.1, 0.3, 0.5, 0.9, 1.0, 1.5):
        gap = share * leg_from
        least = least_extra_s(model, gap)
        true = float(over[d >= gap].min())
        assert 0.0 <= least <= true + 1e-12
        assert least >= true - 0.01 * extra
