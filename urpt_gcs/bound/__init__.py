"""The certified lower bound: relaxations of the continuous problem that no flight beats.

Terrain-free: the regions come from :mod:`urpt_gcs.problem.regions`; the outer stars walked on
the DEM are made by the visibility package.
"""

__all__: list[str] = []
