"""Shared fixtures: synthetic GeoTIFFs and paths to the real data beside the checkout.

Data too large or too foreign to commit (the real rasters, the GTSPLIB and CETSP benches, the
SITL builds) lives in ``../shared`` beside the checkout, which CI lays out but a fresh clone
does not have. A test that reads from it says so with :func:`needs_shared`, and is skipped
with a one-line reason where the folder is absent, rather than failing::

    from conftest import needs_shared

    @needs_shared("dem/odm_dsm_utm51n.tif")
    def test_something_on_a_real_raster(): ...

    pytestmark = needs_shared("bench/gtsplib")  # every test of a module
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REAL_DEMS = SHARED / "dem"
GTSPLIB = SHARED / "bench" / "gtsplib"
CETSP = SHARED / "bench" / "cetsp"
DEMO = REPO / "missions" / "demo"
# A plan of the demo the tests fly and read, kept apart from missions/demo/out, which
# `make demo` rewrites.
DEMO_OUT = Path(__file__).resolve().parent / "data" / "demo_plan"
# What `plan` prints on stderr as each stage ends when stderr is no terminal.
STAGE_LINE = re.compile(r"\.\.\. .+: \d+\.\d\d s")


def needs_shared(path: str | Path) -> pytest.MarkDecorator:
    """Skip unless ``path`` (relative to ``../shared``, or a path inside it) exists.

    Use it as a decorator on a test or a parametrize case (``pytest.param(...,
    marks=needs_shared(...))``), or as a module's ``pytestmark``. The reason reads
    "needs ../shared/dem (not present on this machine)".
    """
    full = SHARED / path
    shown = "../" + full.relative_to(SHARED.parent).as_posix()
    return pytest.mark.skipif(
        not full.exists(), reason=f"needs {shown} (not present on this machine)"
    )


WriteDem = Callable[..., Path]


@pytest.fixture
def write_dem(tmp_path: Path) -> WriteDem:
    """Write a north-up GeoTIFF from an array; row 0 is the north edge."""

    def write(
        z: np.ndarray,
        name: str = "dem.tif",
        crs: str | None = "EPSG:32632",
        res: float = 0.5,
        origin: tuple[float, float] = (500_000.0, 5_200_000.0),
        nodata: float | None = -10000.0,
        dtype: str = "float32",
    ) -> Path:
        path = tmp_path / name
        profile = {
            "driver": "GTiff",
            "height": z.shape[0],
            "width": z.shape[1],
            "count": 1,
            "dtype": dtype,
            "transform": from_origin(origin[0], origin[1], res, res),
            "nodata": nodata,
        }
        if crs is not None:
            profile["crs"] = crs
        with rasterio.open(path, "w", **profile) as dst:
            dst.write(z.astype(dtype), 1)
        return path

    return write


def grid_xy(
    shape: tuple[int, int], res: float = 0.5, origin: tuple[float, float] = (500_000.0, 5_200_000.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of pixel centres for a grid written by ``write_dem``."""
    rows, cols = np.indices(shape)
    return origin[0] + (cols + 0.5) * res, origin[1] - (rows + 0.5) * res
