"""Site inputs: input files, targets, the terrain (DEM) and the camera."""

__all__: list[str] = []
