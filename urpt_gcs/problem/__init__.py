"""The problem without terrain: the GTSP instance, regions on the plane, the flight-time model."""

__all__: list[str] = []
