"""The instance as a GTSP whose clusters partition the nodes (the paper's reduction).

A viewpoint that sees several targets becomes one node per target it sees, all at the same
place (zero distance apart); each target's cluster holds the nodes of the viewpoints that see
it; the depot, if any, is a cluster of its own. Visiting exactly one node per cluster is then
the same problem as seeing every target, and GTSP solvers and GTSPLIB files speak this form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from urpt_gcs.gtsp import Instance, IntArray
from urpt_gcs.inputs import require_memory
from urpt_gcs.terrain import FloatArray


@dataclass(frozen=True, slots=True)
class Clustered:
    """Nodes with a distance matrix and a cluster each.

    ``viewpoint[i]`` is the instance viewpoint node ``i`` copies, ``-1`` for the depot node.
    """

    distance: FloatArray
    cluster: IntArray
    n_clusters: int
    viewpoint: IntArray
    depot_node: int | None

    @property
    def n_nodes(self) -> int:
        return int(self.cluster.shape[0])

    def members(self) -> list[IntArray]:
        """The nodes of each cluster."""
        order = np.argsort(self.cluster, kind="stable")
        bounds = np.searchsorted(self.cluster[order], np.arange(self.n_clusters + 1))
        return [order[bounds[k] : bounds[k + 1]] for k in range(self.n_clusters)]

    def cycle_length(self, nodes: list[int] | IntArray) -> float:
        idx = np.asarray(nodes, dtype=np.int64)
        return float(self.distance[idx, np.roll(idx, -1)].sum())


def partition_nodes(instance: Instance) -> int:
    """How many nodes the partition form of ``instance`` has: one per (viewpoint, target it
    sees) pair, and the depot."""
    return int(np.count_nonzero(instance.covers)) + (1 if instance.has_depot else 0)


def require_partition_memory(instance: Instance, solver: str, bytes_per_pair: float) -> None:
    """Refuse, before building it, a partition form too big for the memory budget.

    ``bytes_per_pair`` is what ``solver`` keeps, at its peak, per pair of nodes: 8 per dense
    float64 node-by-node matrix, more for other copies.

    Raises
    ------
    MemoryBudgetError
        Naming the estimate and what to change.
    """
    n = partition_nodes(instance)
    require_memory(
        bytes_per_pair * float(n) * float(n),
        f"the {solver} solver's distance matrices over {n} nodes (each of "
        f"{instance.n_viewpoints} viewpoints once per target it sees, {instance.n_targets} "
        "targets)",
        "use fewer --samples, or fewer targets per plan",
    )


def cluster_instance(instance: Instance) -> Clustered:
    """Expand ``instance`` into the partition form (copies per target, depot cluster last)."""
    vp, tg = np.nonzero(instance.covers)
    dist = instance.distance[np.ix_(vp, vp)]
    if instance.depot_distance is None:
        return Clustered(dist, tg.astype(np.int64), instance.n_targets, vp.astype(np.int64), None)
    n = len(vp)
    full = np.zeros((n + 1, n + 1), dtype=np.float64)
    full[1:, 1:] = dist
    full[0, 1:] = instance.depot_distance[0, vp]
    full[1:, 0] = instance.depot_distance[1, vp]
    cluster = np.concatenate([[instance.n_targets], tg]).astype(np.int64)
    viewpoint = np.concatenate([[-1], vp]).astype(np.int64)
    return Clustered(full, cluster, instance.n_targets + 1, viewpoint, 0)


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
