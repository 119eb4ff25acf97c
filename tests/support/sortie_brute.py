"""Brute force over sorties: every order of every subset of a handful of points is a sortie,
every partition of the points a plan; each sortie timed from the flight model's primitives
(take-off, each leg from rest to rest, a stop at every point, the leg home at the return
speed, landing), independently of the planner's own timing code."""

from __future__ import annotations

import itertools
import math

import numpy as np

from urpt_gcs.problem.flight_time import FlightModel

__all__ = [
    "VARIED_MODELS",
    "best_partition",
    "partitions_by_count",
    "parts",
    "sortie_time",
    "subsets",
]


def sortie_time(
    model: FlightModel, seq_xy: np.ndarray, home: tuple[float, float], alt_m: float
) -> float:
    """Flight time of one sortie from ``home`` through ``seq_xy`` in order and back."""
    path = [home, *[(float(x), float(y)) for x, y in seq_xy], home]
    legs = [math.dist(a, b) for a, b in itertools.pairwise(path)]
    t = model.takeoff_s(alt_m)
    for leg in legs[:-1]:
        t += float(model.leg_s(leg))
    t += len(seq_xy) * model.stop_s
    t += float(model.return_s(legs[-1]))
    return t + model.landing_s(alt_m)


def subsets(
    points: np.ndarray,
    model: FlightModel,
    endurance_s: float,
    home: tuple[float, float],
    alt_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per subset of the points (a bitmask): the shortest and the quickest sortie through
    exactly them within the endurance (inf when none fits), and the quickest at all."""
    n = len(points)
    to_home = np.hypot(*(points - np.asarray(home)).T)
    gap = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
    out_s = model.leg_s(to_home)
    back_s = model.return_s(to_home)
    hop_s = model.leg_s(gap)
    ends = model.takeoff_s(alt_m) + model.landing_s(alt_m)
    short = np.full(1 << n, np.inf)
    quick = np.full(1 << n, np.inf)
    fastest = np.full(1 << n, np.inf)
    short[0] = quick[0] = fastest[0] = 0.0
    for k in range(1, n + 1):
        for seq in itertools.permutations(range(n), k):
            mask = sum(1 << i for i in seq)
            length = float(to_home[seq[0]] + to_home[seq[-1]])
            time_s = float(ends + out_s[seq[0]] + back_s[seq[-1]] + k * model.stop_s)
            for a, b in itertools.pairwise(seq):
                length += float(gap[a, b])
                time_s += float(hop_s[a, b])
            fastest[mask] = min(fastest[mask], time_s)
            if time_s <= endurance_s:
                short[mask] = min(short[mask], length)
                quick[mask] = min(quick[mask], time_s)
    return short, quick, fastest


def parts(mask: int) -> list[int]:
    """Every submask of ``mask`` that holds its lowest point (one part of a partition)."""
    low = mask & -mask
    rest = mask ^ low
    out = []
    sub = rest
    while True:
        out.append(sub | low)
        if sub == 0:
            return out
        sub = (sub - 1) & rest


def best_partition(cost: np.ndarray, n: int) -> float:
    """The least total cost of a partition of all ``n`` points into parts."""
    best = np.full(1 << n, np.inf)
    best[0] = 0.0
    for mask in range(1, 1 << n):
        best[mask] = min(cost[p] + best[mask ^ p] for p in parts(mask))
    return float(best[-1])


def partitions_by_count(cost: np.ndarray, n: int) -> list[float]:
    """Per count k (index k), the least total cost of a partition of all ``n`` points into
    exactly k parts (inf where there is none)."""
    full = (1 << n) - 1
    best = [np.full(1 << n, np.inf) for _ in range(n + 1)]
    best[0][0] = 0.0
    for k in range(1, n + 1):
        for mask in range(1, 1 << n):
            best[k][mask] = min(
                (cost[p] + best[k - 1][mask ^ p] for p in parts(mask)), default=math.inf
            )
    return [float(best[k][full]) for k in range(n + 1)]


# Flight models of different speeds, limits and firmwares, for tests of their properties.
VARIED_MODELS = [
    FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0),
    FlightModel.arducopter(cruise_m_s=12.0, hold_s=0.0, accel_m_s2=1.0),
    FlightModel.px4(cruise_m_s=8.0, hold_s=2.0),
]
