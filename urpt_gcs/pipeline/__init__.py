"""The stage chain: from a DEM and targets to a checked plan, for one vehicle or a fleet.

In the order a plan runs through them:

- ``settings`` -- every setting of a plan and of a fleet (:class:`PlanSettings`, ...);
- ``stages`` -- how the chain announces each stage and times it;
- ``checks`` -- checks on the inputs and the flight plane before any planning;
- ``area`` -- the site placed on the DEM (``read_site``) and the DEM window and flight plane
  planned on (``read_area``);
- ``missions`` -- the tour cut into sorties, written as missions and checked as written;
- ``improve`` -- stops moved within what they see, and the flight's certified lower bound;
- ``result`` -- :class:`Plan`, everything a plan produced;
- ``planner`` -- ``plan()``, the chain itself, and ``finish_plan()``;
- ``altitude`` -- ``--altitude auto``: the same plan over a range of altitudes;
- ``fleet`` -- ``plan_fleet()``: several vehicles, each on its own layer;
- ``separation`` -- the fleet's planned tracks and the start delays that keep them apart.
"""

__all__: list[str] = []
