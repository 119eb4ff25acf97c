"""The stage chain: from a DEM and targets to a checked plan, for one vehicle or a fleet."""
