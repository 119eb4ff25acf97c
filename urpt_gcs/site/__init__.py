"""Site inputs: input files, targets, the terrain (DEM) and the camera."""
