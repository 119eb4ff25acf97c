"""Brute-force tours through a few sets of points: every order, every point of each set
(a grid inside each region), so the shortest found is a real tour through the regions and
at least their continuous optimum."""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["brute_force_tour", "disc_grid", "small_discs"]


def disc_grid(x: float, y: float, r: float, k: int) -> np.ndarray:
    """Points of a fine grid inside a disc, and on its rim."""
    g = np.linspace(-r, r, k)
    gx, gy = np.meshgrid(g, g)
    inside = gx**2 + gy**2 <= r * r
    a = np.linspace(0.0, 2.0 * np.pi, 4 * k, endpoint=False)
    rim = np.column_stack([x + r * np.cos(a), y + r * np.sin(a)])
    return np.vstack([np.column_stack([x + gx[inside], y + gy[inside]]), rim])


def brute_force_tour(sets: list[np.ndarray], depot: tuple[float, float] | None) -> float:
    """The shortest closed tour through one point of each set, over every order (a real
    tour, so it is at least the continuous optimum)."""
    best = np.inf
    n = len(sets)
    first = [np.asarray(depot)[None, :]] if depot is not None else []
    orders = (
        itertools.permutations(range(n))
        if depot
        else ((0, *p) for p in itertools.permutations(range(1, n)))
    )
    for perm in orders:
        seq = first + [sets[i] for i in perm]
        for start in range(len(seq[0])):
            cur = np.zeros(1)
            prev = seq[0][start : start + 1]
            for nxt in seq[1:]:
                d = np.hypot(prev[:, None, 0] - nxt[None, :, 0], prev[:, None, 1] - nxt[None, :, 1])
                cur = (cur[:, None] + d).min(axis=0)
                prev = nxt
            close = np.hypot(*(prev - seq[0][start]).T)
            best = min(best, float((cur + close).min()))
            if depot is not None:
                break
    return best


def small_discs(
    seed: int, side: float, widest: float, coarse: int
) -> tuple[np.ndarray, tuple[float, float] | None, float]:
    """Five seeded discs in a ``side`` square (radii 0.5 to ``widest``), home at its centre
    for even seeds and none for odd ones, and the brute-force tour through them (grids of 15
    points a side, or ``coarse`` without home, where every point of the first disc is a
    start)."""
    rng = np.random.default_rng(seed)
    n = 5
    discs = np.column_stack(
        [rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(0.5, widest, n)]
    )
    depot = (side / 2, side / 2) if seed % 2 == 0 else None
    brute = brute_force_tour([disc_grid(*d, 15 if depot else coarse) for d in discs], depot)
    return discs, depot, brute
