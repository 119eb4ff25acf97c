"""OR-Tools routing as a GTSP solver: one mandatory disjunction per target.

A viewpoint that sees several targets appears once per target it sees (the paper's copies),
each copy in its target's disjunction, so "exactly one node per disjunction" still lets a
tour use one viewpoint for several targets. Guided local search runs until the time limit.
"""

from __future__ import annotations

import time

import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

from urpt_gcs.errors import PlanError
from urpt_gcs.gtsp import Instance
from urpt_gcs.solvers.base import SolveSettings, Tour, finish_tour, geometric_lower_bound

# Routing needs integer arc costs: centimetres.
_SCALE = 100.0


class RoutingSolver:
    """OR-Tools routing with guided local search."""

    name = "ortools"

    def solve(self, instance: Instance, settings: SolveSettings) -> Tour:
        started = time.perf_counter()
        vp, tg = np.nonzero(instance.covers)  # one node per (viewpoint, target) copy
        nodes = np.concatenate([[-1], vp])  # node 0 is the depot
        cost = np.rint(instance.distance_m[nodes + 1][:, nodes + 1] * _SCALE).astype(np.int64)
        manager = pywrapcp.RoutingIndexManager(len(nodes), 1, 0)
        routing = pywrapcp.RoutingModel(manager)
        # A matrix callback stays in C++; a Python callback would be called millions of times.
        callback = routing.RegisterTransitMatrix(cost.tolist())
        routing.SetArcCostEvaluatorOfAllVehicles(callback)
        for t in range(instance.n_targets):
            members = (np.flatnonzero(tg == t) + 1).tolist()
            routing.AddDisjunction([manager.NodeToIndex(n) for n in members])
        params = pywrapcp.DefaultRoutingSearchParameters()
        params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
        params.local_search_metaheuristic = (
            routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
        )
        params.time_limit.FromMilliseconds(max(int(settings.time_limit_s * 1000), 1))
        solution = routing.SolveWithParameters(params)
        if solution is None:
            raise PlanError("OR-Tools found no tour within the time limit: raise --time-limit")
        order: list[int] = []
        index = routing.Start(0)
        while not routing.IsEnd(index):
            node = manager.IndexToNode(index)
            if node != 0:
                order.append(int(nodes[node]))
            index = solution.Value(routing.NextVar(index))
        return finish_tour(
            instance,
            order,
            lower_bound_m=geometric_lower_bound(instance),
            solver=self.name,
            solve_s=time.perf_counter() - started,
        )
