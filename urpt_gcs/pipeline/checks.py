"""Checks on the inputs before any planning: points off the DEM or with lat and lon swapped,
ground without elevation, a DEM window over the memory budget, and a flight plane whose camera
cone is too narrow or too high for ``--gsd``.

Each raises a :class:`~urpt_gcs.errors.UrptError` that names the point or flag and the fix.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyproj

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.errors import SettingsError, TargetsError
from urpt_gcs.memory import require_memory
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.site.dem import WGS84, DemInfo, check_elevations
from urpt_gcs.site.targets import SWAP_FIX, TargetSet
from urpt_gcs.visibility.regions import Camera

# The narrowest camera cone a plan accepts, as a radius on the flight plane: ten times the
# 1e-7 degree grid waypoints are stored on, so a rounded waypoint stays well inside it.
MIN_CONE_RADIUS_M = 0.1


def check_swapped(
    info: DemInfo, site: TargetSet, home: tuple[float, float], home_source: str
) -> None:
    """Refuse, with a hint, a point off the DEM that swapped lat and lon would put on it.

    Checked before anything else uses the points: a point far off the site otherwise fails
    later and less clearly (no DEM window, a UTM zone edge, a distorted projection).

    Parameters
    ----------
    info
        The DEM's description.
    site
        The targets as read.
    home
        Home (lat, lon), degrees.
    home_source
        Where home came from; ``"--home"`` blames the flag, anything else the target file.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        ``--home`` is off the DEM and would be on it swapped.
    urpt_gcs.errors.TargetsError
        A target (or home from the file) is off the DEM and would be on it swapped.
    """
    points = [(f"target '{t.name}'", t.lat_deg, t.lon_deg) for t in site.targets]
    points.append((f"home ({home_source})", *home))
    lat = np.array([p[1] for p in points])
    lon = np.array([p[2] for p in points])
    off = ~_on_dem(info, lat, lon)
    swapped = off & _on_dem(info, lon, lat)
    if not swapped.any():
        return
    i = int(np.flatnonzero(swapped)[0])
    where, a, b = points[i]
    problem = (
        f"lies outside DEM '{info.path}', and ({b:.7f}, {a:.7f}) would lie on it: "
        "did you swap lat and lon?"
    )
    if i == len(points) - 1 and home_source == "--home":
        raise SettingsError.about(
            "{home} {a},{b} {problem} Give {home} LAT,LON: {home} {b},{a}",
            a=a,
            b=b,
            problem=problem,
        )
    fix = SWAP_FIX.get(Path(site.source).suffix.lower(), "swap the two numbers")
    raise TargetsError(
        f"{where} ({a:.7f}, {b:.7f}) in targets file '{site.source}' {problem} "
        f"{fix[0].upper()}{fix[1:]}"
    )


def _on_dem(info: DemInfo, lat: FloatArray, lon: FloatArray) -> BoolArray:
    """Which WGS84 points fall inside the DEM's extent (any point off the globe does not)."""
    ok = (np.abs(lat) <= 90.0) & (np.abs(lon) <= 180.0)
    to_src = pyproj.Transformer.from_crs(WGS84, info.horizontal_crs, always_xy=True)
    sx, sy = to_src.transform(np.where(ok, lon, 0.0), np.where(ok, lat, 0.0), errcheck=False)
    col, row = ~info.transform @ (np.asarray(sx), np.asarray(sy))
    with np.errstate(invalid="ignore"):
        inside = (col >= 0) & (col <= info.width_px) & (row >= 0) & (row <= info.height_px)
    return np.asarray(ok & np.isfinite(col) & np.isfinite(row) & inside, dtype=np.bool_)


def check_ground(
    info: DemInfo,
    ground: FloatArray,
    names: list[str],
    lat_lon: list[tuple[float, float]],
) -> FloatArray:
    """The ground elevation at each point, or an error naming the first point without one.

    Parameters
    ----------
    info
        The DEM's description.
    ground
        The elevation sampled at each point; NaN where there is none.
    names
        Each point as a message names it (``target 'T1'``, ``home (...)``).
    lat_lon
        Each point's (lat, lon), degrees.

    Returns
    -------
    FloatArray
        ``ground``, when every point has an elevation.

    Raises
    ------
    urpt_gcs.errors.TargetsError
        The first point off the DEM or on a nodata cell.
    """
    bad = np.flatnonzero(~np.isfinite(ground))
    if bad.size == 0:
        return ground
    check_elevations(info)
    i = int(bad[0])
    lat, lon = lat_lon[i]
    to_src = pyproj.Transformer.from_crs(WGS84, info.horizontal_crs, always_xy=True)
    sx, sy = to_src.transform(lon, lat)
    col, row = ~info.transform @ (sx, sy)
    where = f"{names[i]} ({lat:.7f}, {lon:.7f})"
    if not (0 <= col <= info.width_px and 0 <= row <= info.height_px):
        fix = (
            "move it onto the DEM"
            if names[i].startswith("home")
            else "remove it from the target file"
        )
        raise TargetsError(
            f"{where} lies outside DEM '{info.path}': {fix} or use a DEM that covers it"
        )
    raise TargetsError(
        f"{where} is on a nodata cell of DEM '{info.path}': move it onto surveyed ground"
    )


def require_window(
    info: DemInfo,
    cell_m: float,
    need: tuple[float, float, float, float],
    altitude_m: float,
    settings: PlanSettings,
) -> None:
    """Refuse a camera cone whose DEM window would not fit the memory budget.

    The window is counted in full even where it runs past the DEM: every ray of the
    visibility sweep and every line of sight is sampled that far, cell by cell.

    Parameters
    ----------
    info
        The DEM's description.
    cell_m
        The DEM's cell size in the planning CRS, metres.
    need
        The window (xmin, ymin, xmax, ymax) in the planning CRS.
    altitude_m
        The flight plane the cones are drawn from.
    settings
        The plan's settings, which the message names.

    Raises
    ------
    urpt_gcs.errors.UrptError
        The window would not fit the memory budget.
    """
    width = math.ceil((need[2] - need[0]) / cell_m)
    height = math.ceil((need[3] - need[1]) / cell_m)
    # The grid spanning the cones holds float64 elevations at most.
    per_cell = 8
    if settings.altitude_m is not None:
        cause = f"--altitude {altitude_m:g} m"
    else:
        cause = f"--clearance {settings.clearance_m:g} m (camera at {altitude_m:.0f} m)"
    require_memory(
        float(width) * float(height) * per_cell,
        f"{cause} with --fov {settings.fov_deg:g}: the camera cone needs a DEM window of "
        f"{width} x {height} cells, which",
        "lower --altitude/--clearance or narrow the camera (--fov)",
    )


def check_gsd(camera: Camera, ground_m: FloatArray, names: list[str]) -> None:
    """Refuse a plane too high for ``--gsd`` over some target: no photo from it resolves it.

    Parameters
    ----------
    camera
        The camera on the flight plane.
    ground_m
        The ground elevation under each target.
    names
        Each target's name.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        The plane is at or beyond the GSD distance over some target.
    """
    far = camera.max_distance_m
    height = camera.altitude_m - ground_m
    i = int(np.argmax(height))
    if height[i] < far:
        return
    assert camera.gsd_cm is not None
    raise SettingsError.about(
        "{gsd_cm} {gsd:g} cm needs the camera within {far:.1f} m of target '{name}', but the "
        "plane is {height:.1f} m above it: lower {altitude_m} or {clearance_m}, or ask for a "
        "coarser {gsd_cm}",
        gsd=camera.gsd_cm,
        far=far,
        name=names[i],
        height=height[i],
    )


def check_cone_width(
    camera: Camera, ground_m: FloatArray, names: list[str], tolerance_m: float
) -> None:
    """Refuse a camera cone too narrow for a waypoint to be placed inside it, or for the
    vehicle to photograph from within ``tolerance_m`` of it.

    Parameters
    ----------
    camera
        The camera on the flight plane.
    ground_m
        The ground elevation under each target.
    names
        Each target's name.
    tolerance_m
        How far the vehicle may stop off its waypoint (``--position-tolerance``).

    Raises
    ------
    urpt_gcs.errors.SettingsError
        Some target's cone is narrower than :data:`MIN_CONE_RADIUS_M` or twice
        ``tolerance_m``.
    """
    cone = camera.least_half_width_m(ground_m)
    i = int(np.argmin(cone))
    least = max(MIN_CONE_RADIUS_M, 2.0 * tolerance_m)
    if cone[i] >= least:
        return
    if camera.frame is not None:
        raise SettingsError.about(
            "the frame camera sees only {seen} around target '{name}' (its short side, "
            "within any {gsd_cm} distance), under the {least:g} m a stop needs (twice "
            "{position_tolerance_m}): raise {altitude_m} or {clearance_m}, ask for a coarser "
            "{gsd_cm}, or lower {position_tolerance_m}",
            seen=_length(float(cone[i])),
            name=names[i],
            least=least,
        )
    height = camera.altitude_m - float(ground_m[i])
    need = math.ceil(math.degrees(math.atan(least / height)) * 1000) / 1000
    seen = "{fov_deg} {fov:g} sees only {seen} around target '{name}'"
    at = {"fov": camera.fov_deg, "seen": _length(float(cone[i])), "name": names[i], "need": need}
    if least > MIN_CONE_RADIUS_M:
        raise SettingsError.about(
            seen + ", under twice the {tolerance:g} m the vehicle may stop off its waypoint "
            "({position_tolerance_m}): use {fov_deg} {need:g} or more, or lower "
            "{position_tolerance_m}",
            tolerance=tolerance_m,
            **at,
        )
    raise SettingsError.about(
        seen + ", finer than a waypoint can be placed (1e-7 degree, about 1 cm): "
        "use {fov_deg} {need:g} or more",
        **at,
    )


__all__ = [
    "MIN_CONE_RADIUS_M",
    "check_cone_width",
    "check_ground",
    "check_gsd",
    "check_swapped",
    "require_window",
]


def _length(metres: float) -> str:
    """A short length for a message: centimetres below a metre, else metres."""
    return f"{metres * 100:.1f} cm" if metres < 1.0 else f"{metres:.2f} m"
