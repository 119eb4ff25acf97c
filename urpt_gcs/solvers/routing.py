"""OR-Tools routing as a GTSP solver: one mandatory disjunction per cluster.

It works on the partition form (:mod:`urpt_gcs.solvers.clustered`): a viewpoint that sees
several targets is one node per target, so "exactly one node per disjunction" still lets a
tour use one viewpoint for several targets. Routing needs a start node: the depot when there
is one; otherwise each node of the smallest cluster in turn, sharing the time limit. Guided
local search runs until the time limit.
"""

from __future__ import annotations

import time

import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

from urpt_gcs.errors import PlanError
from urpt_gcs.gtsp import Instance
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour, geometric_lower_bound
from urpt_gcs.solvers.clustered import (
    Clustered,
    cluster_instance,
    require_partition_memory,
    viewpoint_order,
)

# Routing needs integer arc costs; scale so that centimetres (or GTSPLIB units) survive.
_SCALE = 100.0
# Peak memory per pair of partition-form nodes: the float and integer matrices, the Python
# lists handed to routing and its own copy (63 measured).
_BYTES_PER_NODE_PAIR = 72.0


def route_clustered(clustered: Clustered, start: int, time_limit_s: float) -> list[int] | None:
    """Best node cycle found from ``start`` within the time limit (None if none found)."""
    n = clustered.n_nodes
    cost = np.rint(clustered.distance * _SCALE).astype(np.int64)
    manager = pywrapcp.RoutingIndexManager(n, 1, start)
    routing = pywrapcp.RoutingModel(manager)
    # A matrix callback stays in C++; a Python callback would be called millions of times.
    callback = routing.RegisterTransitMatrix(cost.tolist())
    routing.SetArcCostEvaluatorOfAllVehicles(callback)
    start_cluster = clustered.cluster[start]
    for k, members in enumerate(clustered.members()):
        if k == start_cluster:
            # The start's own cluster is visited by the start; its other nodes are not needed.
            for node in members.tolist():
                if node != start:
                    routing.AddDisjunction([manager.NodeToIndex(node)], 0)
            continue
        routing.AddDisjunction([manager.NodeToIndex(int(node)) for node in members])
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = (
        routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    )
    params.time_limit.FromMilliseconds(max(int(time_limit_s * 1000), 1))
    solution = routing.SolveWithParameters(params)
    if solution is None:
        return None
    cycle: list[int] = []
    index = routing.Start(0)
    while not routing.IsEnd(index):
        cycle.append(manager.IndexToNode(index))
        index = solution.Value(routing.NextVar(index))
    return cycle


def solve_clustered(clustered: Clustered, time_limit_s: float) -> list[int]:
    """Best node cycle over the possible starts, within ``time_limit_s`` in all."""
    if clustered.depot_node is not None:
        starts = [clustered.depot_node]
    else:
        starts = min(clustered.members(), key=len).tolist()
    best: list[int] | None = None
    for start in starts:
        cycle = route_clustered(clustered, int(start), time_limit_s / len(starts))
        if cycle is not None and (
            best is None or clustered.cycle_length(cycle) < clustered.cycle_length(best)
        ):
            best = cycle
    if best is None:
        raise PlanError("OR-Tools found no tour within the time limit: raise --time-limit")
    return best


class RoutingSolver:
    """OR-Tools routing with guided local search."""

    name = "ortools"

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        require_partition_memory(instance, self.name, _BYTES_PER_NODE_PAIR)
        started = time.perf_counter()
        clustered = cluster_instance(instance)
        cycle = solve_clustered(clustered, settings.time_limit_s)
        return finish_tour(
            instance,
            viewpoint_order(clustered, cycle),
            lower_bound=geometric_lower_bound(instance),
            solver=self.name,
            solve_s=time.perf_counter() - started,
        )
