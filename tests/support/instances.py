"""Random viewpoint instances for solver tests: overlapping cover sets, with or without a
depot, symmetric or not."""

from __future__ import annotations

import numpy as np

from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix


def random_instance(
    seed: int, n: int, m: int, depot: bool, asymmetric: bool = False, overlap: float = 0.3
) -> Instance:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 100, (n, 2))
    covers = np.zeros((n, m), dtype=bool)
    covers[np.arange(n), rng.integers(0, m, n)] = True
    covers[np.arange(m) % n, np.arange(m)] = True  # every target seen
    covers |= rng.random((n, m)) < overlap  # overlapping cover sets
    dist = euclidean_matrix(pts)
    if asymmetric:
        dist = dist + rng.uniform(0, 20, (n, n))
        np.fill_diagonal(dist, 0.0)
    depot_distance = None
    if depot:
        home = rng.uniform(0, 100, 2)
        d = np.hypot(pts[:, 0] - home[0], pts[:, 1] - home[1])
        depot_distance = np.vstack([d, d + (rng.uniform(0, 5, n) if asymmetric else 0)])
    return Instance(
        covers=Covers.from_dense(covers),
        distance=dist,
        depot_distance=depot_distance,
        points_xy=pts,
    )
