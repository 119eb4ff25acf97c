"""Shared fixtures: synthetic GeoTIFFs and paths to the real rasters beside the checkout."""

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
DEMO = REPO / "missions" / "demo"
# What `plan` prints on stderr as each stage ends when stderr is no terminal.
STAGE_LINE = re.compile(r"\.\.\. .+: \d+\.\d\d s")

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
