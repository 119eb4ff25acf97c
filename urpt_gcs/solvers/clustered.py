"""The instance as a GTSP whose clusters partition the nodes (the paper's reduction).

A viewpoint that sees several targets becomes one node per target it sees, all at the same
place (zero distance apart); each target's cluster holds the nodes of the viewpoints that see
it; the depot, if any, is a cluster of its own. Visiting exactly one node per cluster is then
the same problem as seeing every target, and GTSP solvers and GTSPLIB files speak this form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.memory import require_memory
from urpt_gcs.problem.instance import Instance, euclidean_matrix

__all__ = [
    "Clustered",
    "cluster_instance",
    "partition_nodes",
    "require_partition_memory",
    "viewpoint_order",
]


@dataclass(frozen=True, slots=True)
class Clustered:
    """Nodes with a cluster each, and their distances: an explicit node-by-node matrix
    ``distance``, or node positions ``xy`` with Euclidean distances (exactly one is set).

    ``viewpoint[i]`` is the instance viewpoint node ``i`` copies, ``-1`` for the depot node.
    """

    distance: FloatArray | None
    cluster: IntArray
    n_clusters: int
    viewpoint: IntArray
    depot_node: int | None
    xy: FloatArray | None = None

    def __post_init__(self) -> None:
        if (self.distance is None) == (self.xy is None):
            raise ValueError("Clustered needs exactly one of distance and xy")

    @property
    def n_nodes(self) -> int:
        return int(self.cluster.shape[0])

    def members(self) -> list[IntArray]:
        """The nodes of each cluster."""
        order = np.argsort(self.cluster, kind="stable")
        bounds = np.searchsorted(self.cluster[order], np.arange(self.n_clusters + 1))
        return [order[bounds[k] : bounds[k + 1]] for k in range(self.n_clusters)]

    def legs(self, u: IntArray, v: IntArray) -> FloatArray:
        """The costs of ``u[k] -> v[k]``."""
        if self.distance is not None:
            out: FloatArray = self.distance[u, v]
            return out
        assert self.xy is not None
        p, q = self.xy[u], self.xy[v]
        legs: FloatArray = np.hypot(p[:, 0] - q[:, 0], p[:, 1] - q[:, 1])
        return legs

    def matrix(self) -> FloatArray:
        """The node-by-node matrix (built from ``xy`` on the plane; small forms only)."""
        if self.distance is not None:
            return self.distance
        assert self.xy is not None
        return euclidean_matrix(self.xy)

    def cycle_length(self, nodes: list[int] | IntArray) -> float:
        idx = np.asarray(nodes, dtype=np.int64)
        return float(self.legs(idx, np.roll(idx, -1)).sum())


def partition_nodes(instance: Instance) -> int:
    """How many nodes the partition form of ``instance`` has: one per (viewpoint, target it
    sees) pair, and the depot."""
    return instance.covers.n_pairs + (1 if instance.has_depot else 0)


def require_partition_memory(
    instance: Instance, solver: str, bytes_per_pair: float, bytes_per_node: float = 0.0
) -> None:
    """Refuse, before building it, a partition form too big for the memory budget.

    ``bytes_per_pair`` is what ``solver`` keeps, at its peak, per pair of nodes (8 per dense
    float64 node-by-node matrix, more for other copies), ``bytes_per_node`` what it keeps per
    node (its sparse structures).

    Raises
    ------
    MemoryBudgetError
        Naming the estimate and what to change.
    """
    n = float(partition_nodes(instance))
    kind = "distance matrices" if bytes_per_pair > 0.0 else "node arrays"
    require_memory(
        bytes_per_pair * n * n + bytes_per_node * n,
        f"the {solver} solver's {kind} over {int(n)} nodes (each of "
        f"{instance.n_viewpoints} viewpoints once per target it sees, {instance.n_targets} "
        "targets)",
        "use fewer --samples, or fewer targets per plan",
    )


def cluster_instance(instance: Instance) -> Clustered:
    """Expand ``instance`` into the partition form (copies per target, depot node first).

    An explicit instance gives an explicit node matrix; one on the plane gives node positions
    only, so that the form stays linear in the nodes.
    """
    vp, tg = instance.covers.pairs()
    depot = instance.depot_distance is not None
    cluster = np.concatenate([[instance.n_targets], tg]) if depot else tg
    viewpoint = np.concatenate([[-1], vp]) if depot else vp
    m = instance.n_targets + (1 if depot else 0)
    node = (cluster.astype(np.int64), m, viewpoint.astype(np.int64), 0 if depot else None)
    if instance.distance is None:
        assert instance.points_xy is not None
        xy = instance.points_xy[vp]
        if depot:
            assert instance.depot_xy is not None
            xy = np.vstack([np.asarray(instance.depot_xy, dtype=np.float64)[None, :], xy])
        return Clustered(None, *node, xy=np.ascontiguousarray(xy, dtype=np.float64))
    dist = instance.distance[np.ix_(vp, vp)]
    if instance.depot_distance is None:
        return Clustered(dist, *node)
    n = len(vp)
    full = np.zeros((n + 1, n + 1), dtype=np.float64)
    full[1:, 1:] = dist
    full[0, 1:] = instance.depot_distance[0, vp]
    full[1:, 0] = instance.depot_distance[1, vp]
    return Clustered(full, *node)


def viewpoint_order(clustered: Clustered, cycle: list[int] | IntArray) -> list[int]:
    """Instance viewpoints along a node cycle, starting after the depot if there is one."""
    nodes = [int(n) for n in cycle]
    if clustered.depot_node is not None:
        k = nodes.index(clustered.depot_node)
        nodes = nodes[k + 1 :] + nodes[:k]
    out: list[int] = []
    for n in nodes:
        v = int(clustered.viewpoint[n])
        if not out or out[-1] != v:
            out.append(v)
    return out
