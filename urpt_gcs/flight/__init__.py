"""From a tour to a flight: position margins, refinement, sorties, safety checks, mission items,
geofence."""

__all__: list[str] = []
