"""The flight band against dense sampling of the bilinear surface (Terrain.sample)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pyproj
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from urpt_gcs.errors import PlanError, SettingsError
from urpt_gcs.flight.band import (
    FlightBand,
    band_profile,
    inside_band,
    negated_terrain,
)
from urpt_gcs.flight.follow import follow_terrain, path_in_band
from urpt_gcs.site.terrain import Terrain

CRS = pyproj.CRS.from_epsg(32632)
X0, Y0 = 500_000.0, 5_200_000.0
BAND = FlightBand(30.0, 120.0)


def _terrain(z: np.ndarray, cell: float = 10.0) -> Terrain:
    return Terrain(
        elevation_m=z.astype(np.float64),
        transform=Affine(cell, 0.0, X0, 0.0, -cell, Y0),
        crs=CRS,
        source="test",
        read_window_px=(0, 0, z.shape[1], z.shape[0]),
        source_shape_px=z.shape,
    )


def _heights(terrain: Terrain, a: np.ndarray, b: np.ndarray, count: int) -> np.ndarray:
    """Height above the surface at ``count`` evenly spaced points of each segment (n, count)."""
    t = np.linspace(0.0, 1.0, count)
    p = a[:, None, :] + (b - a)[:, None, :] * t[None, :, None]
    return p[..., 2] - terrain.sample(p[..., 0], p[..., 1])


def _dense_inside(terrain: Terrain, poly: np.ndarray, band: FlightBand, step_m: float) -> bool:
    """Every ``step_m`` along the polyline (and at its vertices), inside the band."""
    for p, q in itertools.pairwise(poly):
        count = max(math.ceil(np.hypot(*(q[:2] - p[:2])) / step_m), 1) + 1
        h = _heights(terrain, p[None], q[None], count)[0]
        if not (np.all(h >= band.floor_m - 1e-6) and np.all(h <= band.ceiling_m + 1e-6)):
            return False
    return True


def _ridge(height: float, cell: float = 10.0) -> Terrain:
    """A north-south Gaussian ridge (or valley, for a negative height) across 2.6 km."""
    x = (np.arange(260) + 0.5) * cell
    profile = 100.0 + height * np.exp(-(((x - 1300.0) / 250.0) ** 2))
    return _terrain(np.tile(profile, (40, 1)), cell)


def _leg(terrain: Terrain, x_a: float, x_b: float, agl: float) -> tuple[np.ndarray, np.ndarray]:
    y = Y0 - 200.0
    a = np.array([X0 + x_a, y, 0.0])
    b = np.array([X0 + x_b, y, 0.0])
    a[2] = float(terrain.sample(a[0], a[1])) + agl
    b[2] = float(terrain.sample(b[0], b[1])) + agl
    return a, b


def test_band_profile_matches_dense_sampling_on_rough_terrain() -> None:
    rng = np.random.default_rng(7)
    terrain = _terrain(200.0 + rng.normal(0.0, 25.0, (30, 30)))
    n, dense = 300, 20_000
    # Ends within the raster (300 m square), heights 150 to 350 m.
    a = np.column_stack([X0 + rng.uniform(0, 300, n), Y0 - rng.uniform(0, 300, n)])
    b = np.column_stack([X0 + rng.uniform(0, 300, n), Y0 - rng.uniform(0, 300, n)])
    a = np.column_stack([a, rng.uniform(150, 350, n)])
    b = np.column_stack([b, rng.uniform(150, 350, n)])
    p = band_profile(terrain, a, b)
    h = np.concatenate(
        [_heights(terrain, a[i : i + 50], b[i : i + 50], dense) for i in range(0, n, 50)]
    )
    assert np.all(p.unknown_fraction == 0.0)
    # Between two dense samples the height changes by at most the steepest slope times the
    # spacing: the surface's (4 sigma over one cell, twice over a diagonal) plus the segment's.
    length = np.hypot(*(b[:, :2] - a[:, :2]).T)
    slope = 2.0 * float(np.ptp(terrain.elevation_m)) / terrain.cell_m
    slack = (slope * length + np.abs(b[:, 2] - a[:, 2])) / (dense - 1) + 1e-6
    assert np.all(h.min(axis=1) >= p.lowest_m - 1e-6)
    assert np.all(h.max(axis=1) <= p.highest_m + 1e-6)
    assert np.all(h.min(axis=1) - p.lowest_m <= slack)
    assert np.all(p.highest_m - h.max(axis=1) <= slack)
    # And the extremes are where the profile says they are.
    for value, at in ((p.lowest_m, p.lowest_at), (p.highest_m, p.highest_at)):
        q = a + (b - a) * at[:, None]
        np.testing.assert_allclose(q[:, 2] - terrain.sample(q[:, 0], q[:, 1]), value, atol=1e-6)
    # A whole negated raster answers as the cropped one made per call.
    whole = band_profile(terrain, a, b, negated=negated_terrain(terrain))
    np.testing.assert_allclose(whole.highest_m, p.highest_m, atol=1e-9)


def test_a_one_cell_spike_or_pit_between_samples_is_caught() -> None:
    z = np.full((20, 60), 100.0)
    z[10, 31] += 80.0  # a spike: its bilinear hump spans x 305 .. 325 m
    z[5, 31] -= 80.0  # a pit, five rows north
    terrain = _terrain(z)
    y_spike, y_pit = Y0 - 105.0, Y0 - 55.0
    a = np.array(
        [[X0 + 5.0, y_spike, 150.0], [X0 + 5.0, y_pit, 195.0], [X0 + 5.0, Y0 - 155.0, 150]]
    )
    b = a + np.array([575.0, 0.0, 0.0])
    # Samples 25 m apart, at x = 5, 30, ..., 580: 305 and 330 straddle the spike's peak.
    coarse = _heights(terrain, a, b, 24)
    assert np.all((coarse >= 30.0) & (coarse <= 120.0))
    assert inside_band(terrain, a, b, BAND).tolist() == [False, False, True]
    p = band_profile(terrain, a, b)
    assert p.lowest_m[0] == pytest.approx(150.0 - 180.0)
    assert p.highest_m[1] == pytest.approx(195.0 - 20.0)


@pytest.mark.parametrize("height", [300.0, -300.0], ids=["ridge", "valley"])
def test_follow_terrain_over_a_ridge_and_a_valley(height: float) -> None:
    terrain = _ridge(height)
    a, b = _leg(terrain, 300.0, 2300.0, BAND.mid_m)
    assert not inside_band(terrain, a, b, BAND)[0]
    w = follow_terrain(terrain, a, b, BAND)
    poly = np.vstack([a, w, b])
    assert inside_band(terrain, poly[:-1], poly[1:], BAND).all()
    assert _dense_inside(terrain, poly, BAND, 0.25)
    # On the horizontal line from a to b, in order.
    np.testing.assert_allclose(w[:, 1], a[1])
    assert np.all(np.diff(poly[:, 0]) > 0.0)
    # The profile's curvature is at most 2 * 300 / 250^2 m per m^2, so a chord of 173 m strays
    # at most 36 m (the band's half width less its 10 % insets) from the curve: twelve
    # mid-band pieces cover the 2 km leg, hence at most 11 waypoints; it takes 3.
    assert 1 <= len(w) <= 11


@pytest.mark.parametrize(
    ("relief", "floor", "ceiling"), [(40.0, 10.0, 60.0), (100.0, 30.0, 120.0), (40.0, 10.0, 30.0)]
)
def test_follow_terrain_across_saddles_between_samples(
    relief: float, floor: float, ceiling: float
) -> None:
    # A checkerboard: along a diagonal each cell's surface is a parabola, which a chord between
    # two samples a quarter cell apart misses by up to relief / 16, more than the 10 % insets;
    # only the exact check of each piece keeps these legs inside, and the narrowest band only
    # at a finer spacing.
    band = FlightBand(floor, ceiling)
    terrain = _terrain(500.0 + relief * (np.indices((40, 40)).sum(axis=0) % 2 * 2 - 1))
    a = np.array([X0 + 52.0, Y0 - 53.0, 0.0])
    b = np.array([X0 + 352.0, Y0 - 347.0, 0.0])
    a[2] = float(terrain.sample(a[0], a[1])) + band.floor_m
    b[2] = float(terrain.sample(b[0], b[1])) + band.ceiling_m
    poly = np.vstack([a, follow_terrain(terrain, a, b, band), b])
    assert inside_band(terrain, poly[:-1], poly[1:], band).all()
    assert _dense_inside(terrain, poly, band, 0.05)


def test_flat_or_sloping_terrain_needs_no_waypoint() -> None:
    x = (np.arange(260) + 0.5) * 10.0
    for profile in (np.full(260, 100.0), 100.0 + 0.3 * x):
        terrain = _terrain(np.tile(profile, (40, 1)))
        a, b = _leg(terrain, 300.0, 2300.0, 40.0)
        assert follow_terrain(terrain, a, b, BAND).shape == (0, 3)


def test_waypoints_go_to_the_height_asked_where_they_can() -> None:
    terrain = _ridge(300.0)
    a, b = _leg(terrain, 300.0, 2300.0, 100.0)
    w = follow_terrain(terrain, a, b, BAND, aim_m=100.0)
    poly = np.vstack([a, w, b])
    assert inside_band(terrain, poly[:-1], poly[1:], BAND).all()
    agl = w[:, 2] - terrain.sample(w[:, 0], w[:, 1])
    assert np.all((agl >= BAND.floor_m) & (agl <= BAND.ceiling_m))


def test_path_in_band_inserts_waypoints_only_where_needed() -> None:
    terrain = _ridge(300.0)
    a, b = _leg(terrain, 300.0, 2300.0, 60.0)
    c = b + np.array([0.0, -150.0, 10.0])  # a short leg along the flat
    path, original = path_in_band(terrain, np.vstack([a, b, c]), BAND)
    assert original[0] == 0 and original[-2:].tolist() == [1, 2]
    assert np.all(original[1:-2] == -1) and len(path) > 3
    np.testing.assert_array_equal(path[original >= 0], np.vstack([a, b, c]))
    assert inside_band(terrain, path[:-1], path[1:], BAND).all()


def test_unknown_ground_or_an_end_outside_the_band_is_refused() -> None:
    terrain = _ridge(300.0)
    z = terrain.elevation_m.copy()
    z[20, 130] = np.nan
    holed = _terrain(z)
    a, b = _leg(holed, 300.0, 2300.0, 60.0)
    a[1] = b[1] = Y0 - 205.0  # through the nodata cell's row
    with pytest.raises(PlanError, match=r"leg 1 .*unknown ground"):
        path_in_band(holed, np.vstack([a, b]), BAND)
    a, b = _leg(terrain, 300.0, 2300.0, 60.0)
    with pytest.raises(ValueError, match="inside the flight band"):
        follow_terrain(terrain, a + np.array([0.0, 0.0, 100.0]), b, BAND)


@st.composite
def _terrain_case(
    draw: st.DrawFn, spikes: bool = False
) -> tuple[Terrain, np.ndarray, np.ndarray, FlightBand]:
    """A smooth terrain (with one-cell spikes and pits, if asked), a band, and a long leg whose
    ends are inside the band, often at its very floor or ceiling."""
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    rows, cols, cell = 40, 120, draw(st.sampled_from([2.0, 5.0, 10.0]))
    yy, xx = np.mgrid[0:rows, 0:cols] * cell
    z = np.full((rows, cols), 500.0)
    for _ in range(draw(st.integers(2, 8))):  # Gaussian hills and hollows
        cx, cy = rng.uniform(0, cols * cell), rng.uniform(0, rows * cell)
        r = rng.uniform(5.0, 40.0) * cell
        # Slopes up to 0.8 * sqrt(2 / e), 35 degrees.
        height = rng.uniform(-0.8, 0.8) * r
        z += height * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / r**2)
    for _ in range(draw(st.integers(0, 40)) if spikes else 0):
        z[rng.integers(rows), rng.integers(cols)] += rng.choice([-1.0, 1.0]) * rng.uniform(2, 20)
    terrain = _terrain(z, cell)
    floor = draw(st.floats(5.0, 60.0))
    band = FlightBand(floor, floor + draw(st.floats(15.0, 100.0)))
    ends = []
    # Long legs: from the raster's western third to its eastern, or back.
    for side in rng.permutation([0.0, 0.7]):
        x = X0 + rng.uniform(side, side + 0.3) * cols * cell
        y = Y0 - rng.uniform(0.0, rows * cell)
        agl = band.floor_m + draw(st.sampled_from([0.0, 1.0, rng.uniform()])) * band.width_m
        ends.append(np.array([x, y, float(terrain.sample(x, y)) + agl]))
    return terrain, ends[0], ends[1], band


@settings(max_examples=60, deadline=None)
@given(st.booleans().flatmap(_terrain_case))
def test_follow_terrain_always_stays_inside_the_band(
    case: tuple[Terrain, np.ndarray, np.ndarray, FlightBand],
) -> None:
    terrain, a, b, band = case
    w = follow_terrain(terrain, a, b, band)
    poly = np.vstack([a, w, b])
    assert inside_band(terrain, poly[:-1], poly[1:], band).all()
    assert _dense_inside(terrain, poly, band, terrain.cell_m / 8.0)
    # On the line from a to b, in order.
    t = (w[:, :2] - a[:2]) @ (b[:2] - a[:2]) / max(float(np.sum((b[:2] - a[:2]) ** 2)), 1e-12)
    np.testing.assert_allclose(a[:2] + t[:, None] * (b[:2] - a[:2]), w[:, :2], atol=1e-6)
    assert np.all(np.diff(np.concatenate([[0.0], t, [1.0]])) > 0.0)


@pytest.mark.parametrize(
    ("floor", "ceiling", "says"),
    [
        (120.0, 30.0, "120:30: the floor must be below the ceiling; give e.g. 30:120"),
        (30.0, 30.0, "the floor must be below the ceiling"),
        (0.0, 120.0, "the floor must be above the surface"),
        (-5.0, 120.0, "the floor must be above the surface"),
        (math.nan, 120.0, "give finite heights"),
        (30.0, math.inf, "give finite heights"),
        (30.0, 20_000.0, "the ceiling is over 10000 m"),
    ],
)
def test_flight_band_settings_are_checked(floor: float, ceiling: float, says: str) -> None:
    with pytest.raises(SettingsError, match="agl_band_m") as caught:
        FlightBand(floor, ceiling)
    assert says in str(caught.value)
    assert caught.value.naming({"agl_band_m": "--agl-band"}).startswith("--agl-band ")


def test_flight_band_middle() -> None:
    assert FlightBand(30.0, 120.0).mid_m == 75.0
    assert FlightBand(30.0, 10_000.0).ceiling_m == 10_000.0
