"""OR-Tools routing as a GTSP solver: one mandatory disjunction per cluster.

It works on the partition form (:mod:`urpt_gcs.solvers.clustered`): a viewpoint that sees
several targets is one node per target, so "exactly one node per disjunction" still lets a
tour use one viewpoint for several targets. Routing needs a start node: the depot when there
is one; otherwise each node of the smallest cluster in turn, sharing the time limit. Guided
local search runs until the time limit, which counts from the start of the solve: building
the model (a second for a few thousand nodes) is part of it.
"""

from __future__ import annotations

import time

import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

from urpt_gcs.bound.geometric import geometric_lower_bound
from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour
from urpt_gcs.solvers.clustered import (
    Clustered,
    cluster_instance,
    partition_nodes,
    require_partition_memory,
    viewpoint_order,
)

__all__ = [
    "MAX_NODES",
    "RoutingSolver",
    "route_clustered",
    "solve_clustered",
]

# Routing needs integer arc costs; scale so that centimetres (or GTSPLIB units) survive.
_SCALE = 100.0
# Peak memory per pair of partition-form nodes: the float and integer matrices, the Python
# lists handed to routing and its own copy (63 measured).
_BYTES_PER_NODE_PAIR = 72.0
# Routing's arc costs are a full matrix in C++ (a callback per arc over coordinates would be
# called from Python millions of times), so the baseline stops at this many nodes.
MAX_NODES = 12_000


def route_clustered(
    clustered: Clustered, start: int, time_limit_s: float, deadline: float | None = None
) -> list[int] | None:
    """Best node cycle found from ``start`` within the time limit (None if none found).

    The limit counts from this call, model building included, or ends at ``deadline`` (a
    ``time.perf_counter()`` value) when one is given.
    """
    if deadline is None:
        deadline = time.perf_counter() + time_limit_s
    n = clustered.n_nodes
    cost = np.rint(clustered.matrix() * _SCALE).astype(np.int64)
    manager = pywrapcp.RoutingIndexManager(n, 1, start)
    routing = pywrapcp.RoutingModel(manager)
    # A matrix callback stays in C++; a Python callback would be called millions of times.
    # Rows one by one, so that other threads (the progress display) run in between.
    callback = routing.RegisterTransitMatrix([row.tolist() for row in cost])
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
    params.time_limit.FromMilliseconds(max(int((deadline - time.perf_counter()) * 1000), 1))

    # The search holds the GIL; a limit that calls back into Python lets other threads (the
    # progress display) run meanwhile, and ends the search on our clock.
    def out_of_time() -> bool:
        return time.perf_counter() >= deadline

    limit = routing.solver().CustomLimit(out_of_time)
    routing.AddSearchMonitor(limit)
    solution = routing.SolveWithParameters(params)
    if solution is None:
        return None
    cycle: list[int] = []
    index = routing.Start(0)
    while not routing.IsEnd(index):
        cycle.append(manager.IndexToNode(index))
        index = solution.Value(routing.NextVar(index))
    return cycle


def solve_clustered(
    clustered: Clustered, time_limit_s: float, deadline: float | None = None
) -> list[int]:
    """Best node cycle over the possible starts, within ``time_limit_s`` in all (counted from
    this call) or by ``deadline`` (a ``time.perf_counter()`` value) when one is given."""
    if deadline is None:
        deadline = time.perf_counter() + time_limit_s
    if clustered.depot_node is not None:
        starts = [clustered.depot_node]
    else:
        starts = min(clustered.members(), key=len).tolist()
    best: list[int] | None = None
    for k, start in enumerate(starts):
        # What is left is shared among the starts still to try.
        share = (deadline - time.perf_counter()) / (len(starts) - k)
        cycle = route_clustered(clustered, int(start), share, time.perf_counter() + share)
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
        n = partition_nodes(instance)
        if n > MAX_NODES:
            raise SettingsError.about(
                "the OR-Tools baseline handles at most {most} (viewpoint, target) nodes, "
                "not {n}: use {solver} heuristic, or fewer {samples}",
                most=MAX_NODES,
                n=n,
            )
        require_partition_memory(instance, self.name, _BYTES_PER_NODE_PAIR)
        started = time.perf_counter()
        clustered = cluster_instance(instance)
        cycle = solve_clustered(clustered, settings.time_limit_s, started + settings.time_limit_s)
        return finish_tour(
            instance,
            viewpoint_order(clustered, cycle),
            lower_bound=geometric_lower_bound(instance),
            solver=self.name,
            solve_s=time.perf_counter() - started,
        )
