"""From a tour to a flight: position margins, refinement, sorties, safety checks, mission items,
geofence, the terrain-following flight band."""

__all__: list[str] = []
