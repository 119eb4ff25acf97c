"""The exact segment test against dense brute force on the bilinear surface."""

from __future__ import annotations

import math

import numpy as np
import pyproj
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.segments import clear_of_terrain, segment_profile

CRS = pyproj.CRS.from_epsg(32632)
DENSE = 40_001


def _terrain(z: np.ndarray, cell: float = 10.0) -> Terrain:
    return Terrain(
        elevation_m=z.astype(np.float64),
        transform=Affine(cell, 0.0, 500_000.0, 0.0, -cell, 5_200_000.0),
        crs=CRS,
        source="test",
        read_window_px=(0, 0, z.shape[1], z.shape[0]),
        source_shape_px=z.shape,
    )


def _padded_px(terrain: Terrain, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(col, row) of points on the padded grid, whose centres are at whole numbers."""
    col = (x - 500_000.0) / terrain.cell_m + 0.5
    row = (5_200_000.0 - y) / terrain.cell_m + 0.5
    return col, row


def _bilinear(terrain: Terrain, col: np.ndarray, row: np.ndarray) -> np.ndarray:
    """The surface written out directly at padded-grid (col, row): edge values repeated half
    a cell past the outermost centres, unknown where a corner that carries weight is nodata or
    outside the raster."""
    rows, cols = terrain.elevation_m.shape
    z = np.pad(terrain.elevation_m, 1, mode="edge")
    inside = (col >= 0.5) & (col <= cols + 0.5) & (row >= 0.5) & (row <= rows + 0.5)
    c0 = np.clip(np.floor(col), 0, cols).astype(int)
    r0 = np.clip(np.floor(row), 0, rows).astype(int)
    fc, fr = col - c0, row - r0
    total = np.zeros_like(col)
    unknown = ~inside
    for dr, dc, w in (
        (0, 0, (1 - fr) * (1 - fc)),
        (0, 1, (1 - fr) * fc),
        (1, 0, fr * (1 - fc)),
        (1, 1, fr * fc),
    ):
        v = z[np.clip(r0 + dr, 0, rows + 1), np.clip(c0 + dc, 0, cols + 1)]
        weighted = w > 0
        unknown |= weighted & np.isnan(v)
        total += np.where(weighted, np.nan_to_num(v) * w, 0.0)
    return np.where(unknown, np.nan, total)


def _brute(terrain: Terrain, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Largest terrain height above the segment, and the share of samples over no data."""
    t = np.linspace(0.0, 1.0, DENSE)
    p = a[None, :] + (b - a)[None, :] * t[:, None]
    # Samples placed in pixel coordinates: in metres, a point a hair off the raster's edge
    # (5.2e6 m north) rounds onto it and would count as known ground.
    (ca, cb), (ra, rb) = _padded_px(terrain, np.array([a[0], b[0]]), np.array([a[1], b[1]]))
    z = _bilinear(terrain, ca + (cb - ca) * t, ra + (rb - ra) * t)
    known = np.isfinite(z)
    excess = float(np.max(z[known] - p[known, 2])) if known.any() else -math.inf
    return excess, float((~known).mean())


def _tolerance(terrain: Terrain, a: np.ndarray, b: np.ndarray) -> float:
    # How much the surface minus the segment can change between two dense samples.
    z = terrain.elevation_m[np.isfinite(terrain.elevation_m)]
    span = float(z.max() - z.min()) if z.size else 0.0
    length = float(np.hypot(*(b[:2] - a[:2])))
    slope = span / terrain.cell_m * 2.0 + abs(float(b[2] - a[2])) / max(length, 1e-9)
    return slope * length / (DENSE - 1) + 1e-7


def _point(terrain: Terrain, draw: st.DrawFn, height: float) -> np.ndarray:
    rows, cols = terrain.elevation_m.shape
    cell = terrain.cell_m
    # On a micro-cell grid: exact pixel edges and centre lines stay reachable, but not points
    # a rounding error away from them, where the two computations may fall either side.
    x = 500_000.0 + round(draw(st.floats(-1.0, cols + 1.0)), 6) * cell
    y = 5_200_000.0 - round(draw(st.floats(-1.0, rows + 1.0)), 6) * cell
    return np.array([x, y, height])


@st.composite
def _case(draw: st.DrawFn) -> tuple[Terrain, np.ndarray, np.ndarray]:
    rows = draw(st.integers(1, 9))
    cols = draw(st.integers(1, 9))
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    z = np.full((rows, cols), 100.0) + rng.normal(0.0, 2.0, (rows, cols))
    for _ in range(draw(st.integers(0, 3))):  # single-cell spikes at random cells
        z[rng.integers(rows), rng.integers(cols)] += rng.uniform(20.0, 80.0)
    if draw(st.booleans()):
        z[rng.integers(rows), rng.integers(cols)] = np.nan
    terrain = _terrain(z)
    a = _point(terrain, draw, draw(st.floats(90.0, 190.0)))
    b = _point(terrain, draw, draw(st.floats(90.0, 190.0)))
    return terrain, a, b


@settings(max_examples=300, deadline=None)
@given(_case())
def test_exact_maximum_matches_dense_sampling(case: tuple[Terrain, np.ndarray, np.ndarray]) -> None:
    terrain, a, b = case
    profile = segment_profile(terrain, a[None], b[None])
    brute, unknown = _brute(terrain, a, b)
    exact = float(profile.excess_m[0])
    if unknown > 1.0 - 2.0 / DENSE:
        # Over no data but at an isolated point (an end on a pixel centre beside nodata).
        assert profile.unknown_fraction[0] > 1.0 - 2.0 / DENSE
        return
    tol = _tolerance(terrain, a, b)
    # Never below what any sample shows (it is a maximum), and no more than sampling can miss.
    assert exact >= brute - 1e-7
    assert exact <= brute + tol
    assert abs(float(profile.unknown_fraction[0]) - unknown) <= 3.0 / DENSE + 1e-9


def test_a_one_pixel_wall_between_half_cell_samples_is_found() -> None:
    z = np.full((21, 21), 100.0)
    z[:, 10] = 165.0  # a wall one pixel wide, 65 m high
    terrain = _terrain(z)
    # A level leg at 160 m crossing the wall obliquely, away from any half-cell sample.
    a = np.array([500_000.0 + 3.3 * 10, 5_200_000.0 - 2.7 * 10, 160.0])
    b = np.array([500_000.0 + 17.9 * 10, 5_200_000.0 - 15.1 * 10, 160.0])
    profile = segment_profile(terrain, a[None], b[None])
    assert math.isclose(float(profile.excess_m[0]), 5.0, abs_tol=1e-9)
    assert not clear_of_terrain(terrain, a[None], b[None])[0]


def test_sight_line_grazing_a_spike_top() -> None:
    z = np.full((11, 11), 0.0)
    z[5, 5] = 50.0
    terrain = _terrain(z)
    cx, cy = 500_000.0 + 5.5 * 10, 5_200_000.0 - 5.5 * 10  # the spike's pixel centre
    target = np.array([cx - 40.0, cy, 0.0])
    # A line from the target passing exactly over the spike's top at 50 m, then 1 cm below.
    over = np.array([cx + 40.0, cy, 100.0 + 0.02])
    under = np.array([cx + 40.0, cy, 100.0 - 0.02])
    clear = clear_of_terrain(terrain, np.vstack([over, under]), np.vstack([target, target]))
    assert clear.tolist() == [True, False]


def test_nodata_and_outside_are_unknown() -> None:
    z = np.full((5, 5), 10.0)
    z[2, 2] = np.nan
    terrain = _terrain(z)
    y = 5_200_000.0 - 2.5 * 10
    a = np.array([[500_000.0 - 30.0, y, 50.0], [500_000.0 + 5.0, y - 17.0, 50.0]])
    b = np.array([[500_000.0 + 80.0, y, 50.0], [500_000.0 + 6.0, y - 16.0, 50.0]])
    profile = segment_profile(terrain, a, b)
    # Along the row of centres through the nodata one: 30 m past each edge of the raster and
    # the 20 m between the nodata centre's neighbours: 80 of 110 m.
    assert math.isclose(float(profile.unknown_fraction[0]), 80.0 / 110.0, abs_tol=1e-9)
    assert float(profile.unknown_fraction[1]) == 0.0
    assert math.isclose(float(profile.excess_m[1]), -40.0, abs_tol=1e-9)
    assert clear_of_terrain(terrain, a, b).tolist() == [False, True]


def test_vertical_segment_and_non_finite_ends() -> None:
    terrain = _terrain(np.full((4, 4), 5.0))
    p = np.array([500_000.0 + 15.0, 5_200_000.0 - 15.0])
    a = np.array([[*p, 5.0], [np.nan, p[1], 50.0]])
    b = np.array([[*p, 50.0], [*p, 50.0]])
    profile = segment_profile(terrain, a, b)
    assert math.isclose(float(profile.excess_m[0]), 0.0, abs_tol=1e-12)
    assert float(profile.unknown_fraction[1]) == 1.0
    assert clear_of_terrain(terrain, a, b).tolist() == [True, False]


def test_a_known_point_beside_nodata_counts() -> None:
    """The segment ends on a line of pixel centres next to a nodata row: the cell it ends in
    touches nodata, but the surface at the end uses only the known centres of that line."""
    z = np.array([[np.nan, 99.5, 98.5, 99.1, 102.0], [100.06, 208.9, 154.8, 97.0, 100.8]])
    terrain = _terrain(z)
    a = np.array([500_020.0, 5_200_000.0, 90.0])
    b = np.array([500_000.0, 5_199_985.0, 90.0])
    profile = segment_profile(terrain, a[None], b[None])
    assert math.isclose(float(profile.excess_m[0]), 10.06, abs_tol=1e-9)
    assert math.isclose(float(profile.at[0]), 1.0)
    assert math.isclose(float(profile.unknown_fraction[0]), 0.75, abs_tol=1e-9)
