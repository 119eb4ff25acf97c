"""The bound's warm-up compiles every kernel a plan's bound runs, so that its clock is spent
bounding (compiled inside it, a cold cache left the demo's bound 22 % below the flight where
a warm one certifies 0.2 %).

Each check runs in a fresh interpreter, where no kernel has been compiled or loaded yet: in
this one, earlier tests would already have done so and the check could not fail.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

_COUNT = """
import importlib, pkgutil
import numba.core.registry as registry
import urpt_gcs.bound, urpt_gcs.visibility

def kernels():
    found = {}
    for package in (urpt_gcs.bound, urpt_gcs.visibility):
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + "."):
            module = importlib.import_module(info.name)
            for name, value in vars(module).items():
                if isinstance(value, registry.CPUDispatcher):
                    found[f"{info.name}.{name}"] = len(value.signatures)
    return found
"""


def _run(body: str) -> None:
    script = _COUNT + textwrap.dedent(body)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]


def test_after_the_warm_up_no_bound_compiles_a_kernel() -> None:
    _run(
        """
        import numpy as np
        from shapely.geometry import Point
        from urpt_gcs.bound.lower_bound import warm_up, lower_bound
        from urpt_gcs.problem.regions import RegionSet

        warm_up()
        before = kernels()
        rng = np.random.default_rng(5)
        for n in (3, 30, 220):
            xy = rng.random((n, 2)) * 40.0 * n**0.5
            discs = np.column_stack([xy, rng.uniform(1.0, 6.0, n)])
            lower_bound(RegionSet(discs=discs, depot_xy=(-5.0, -5.0)), 1e6, 0.3)
        polygons = tuple(Point(x, y).buffer(3.0) for x, y in rng.random((12, 2)) * 200.0)
        lower_bound(RegionSet(polygons=polygons, depot_xy=(0.0, 0.0)), 1e6, 0.3)
        lower_bound(RegionSet(polygons=polygons), 1e6, 0.3)
        after = kernels()
        grown = {k: (before.get(k, 0), v) for k, v in after.items() if v > before.get(k, 0)}
        assert not grown, f"compiled after the warm-up: {grown}"
        assert any(after.values())
        """
    )


def test_after_the_warm_up_no_star_walk_compiles_a_kernel() -> None:
    _run(
        """
        import numpy as np, pyproj
        from rasterio.transform import Affine
        from urpt_gcs.site.terrain import Terrain
        from urpt_gcs.visibility.outer import warm_up
        from urpt_gcs.visibility.regions import Camera
        from urpt_gcs.visibility.stars import finer_wedges, star_reach

        rows, cols = np.indices((120, 120)) * 0.5
        z = 50.0 + 8.0 * np.exp(-((cols - 30.0) ** 2 + (rows - 25.0) ** 2) / 40.0)
        terrain = Terrain(
            elevation_m=z, transform=Affine.translation(500000.0, 5200000.0)
            @ Affine.scale(0.5, -0.5), crs=pyproj.CRS.from_epsg(32632), source="hill",
            read_window_px=(0, 0, 120, 120), source_shape_px=(120, 120),
        )
        camera = Camera(80.0, 30.0)
        warm_up(terrain, np.array([500010.0, 5199990.0]), 50.0, camera)
        before = kernels()
        targets = np.array([[500020.0, 5199980.0], [500040.0, 5199970.0]])
        ground = np.array([50.0, 51.0])
        star_reach(terrain, targets, ground, camera, 720, 2)
        finer_wedges(terrain, targets, ground, camera, 720, [3, 700], 2)
        after = kernels()
        grown = {k: (before.get(k, 0), v) for k, v in after.items() if v > before.get(k, 0)}
        assert not grown, f"compiled after the warm-up: {grown}"
        assert any(after.values())
        """
    )
