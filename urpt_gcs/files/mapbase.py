"""What the map picture (:mod:`urpt_gcs.files.mapview`) and the map page
(:mod:`urpt_gcs.files.mappage`) both show, worked out once: the DSM as shaded relief, each
sortie's route as flown, each photo's frame on the ground, the geofence, the view around it
all, and the title.

Everything is in the planning CRS, so distances on either map are metres on the ground.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import matplotlib
import numpy as np
import numpy.typing as npt
import pyproj
from matplotlib.colors import LightSource, Normalize, to_rgb

from urpt_gcs.arrays import FloatArray
from urpt_gcs.files.band_report import eye_heights_m
from urpt_gcs.files.bandview import title_lines
from urpt_gcs.files.report import flight_quality
from urpt_gcs.flight.mission import waypoint_positions
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.site.dem import WGS84
from urpt_gcs.site.terrain import Terrain

__all__ = [
    "BACKGROUND",
    "FENCE_COLOUR",
    "MAX_DISPLAY_PX",
    "NODATA_ALPHA",
    "NODATA_COLOUR",
    "TINT_ALPHA",
    "TINT_CMAP",
    "display_step",
    "frame_footprints",
    "geofence_xy",
    "hillshade",
    "map_title",
    "map_transformer",
    "relief_rgb",
    "sortie_routes",
    "view_bounds",
]

# Longest side of the raster drawn, in pixels; larger windows are decimated for display.
MAX_DISPLAY_PX = 1600
# The elevation tint laid over the grey hillshade, and how much of it shows.
TINT_CMAP = "terrain"
TINT_ALPHA = 0.45
# Cells without data: this light red at this opacity over the background.
NODATA_COLOUR = "#fca082"
NODATA_ALPHA = 0.55
# Behind the DSM, where there is no raster.
BACKGROUND = "#eeeeee"
# The geofence's outline.
FENCE_COLOUR = "#c00000"
# A colour per target and its region, in turn (matplotlib's tab10, Bokeh's Category10).
_TARGET_COLOURS = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


def display_step(terrain: Terrain, max_px: int = MAX_DISPLAY_PX) -> int:
    """Every how many cells of ``terrain`` one is shown, so that its longer side fits
    ``max_px``."""
    return max(1, math.ceil(int(max(terrain.elevation_m.shape)) / max_px))


def hillshade(z: FloatArray, cell_m: float) -> FloatArray:
    """Light from the north-west at 45° on a north-up grid of ``cell_m`` cells, 0 to 1;
    NaN where ``z`` has no data."""
    filled = np.where(np.isfinite(z), z, np.nanmean(z) if np.isfinite(z).any() else 0.0)
    shade: FloatArray = LightSource(azdeg=315, altdeg=45).hillshade(
        filled, vert_exag=1.0, dx=cell_m, dy=cell_m
    )
    return np.where(np.isfinite(z), shade, np.nan)


def relief_rgb(z: FloatArray, cell_m: float) -> npt.NDArray[np.uint8]:
    """A north-up grid of heights as an opaque picture (rows, cols, 3): the hillshade in
    grey under the elevation tint, and no data in light red over the background; what
    :func:`~urpt_gcs.files.mapview.map_figure` draws in three layers."""
    finite = np.isfinite(z)
    shade = np.nan_to_num(hillshade(z, cell_m))
    low, high = (float(np.nanmin(z)), float(np.nanmax(z))) if finite.any() else (0.0, 1.0)
    tint = matplotlib.colormaps[TINT_CMAP](Normalize(low, high)(np.nan_to_num(z, nan=low)))
    rgb = (1.0 - TINT_ALPHA) * shade[..., None] + TINT_ALPHA * tint[..., :3]
    hole = (1.0 - NODATA_ALPHA) * np.array(to_rgb(BACKGROUND)) + NODATA_ALPHA * np.array(
        to_rgb(NODATA_COLOUR)
    )
    rgb = np.where(finite[..., None], rgb, hole)
    return np.asarray(np.round(np.clip(rgb, 0.0, 1.0) * 255.0), dtype=np.uint8)


def target_colours(count: int) -> list[str]:
    """The ``#rrggbb`` colours of ``count`` targets (and their regions), in order."""
    return [_TARGET_COLOURS[k % len(_TARGET_COLOURS)] for k in range(count)]


def region_rings(plan: Plan) -> list[FloatArray]:
    """The outline of each visibility region that is not empty, in the planning CRS."""
    return [np.asarray(r.polygon.exterior.coords) for r in plan.regions if not r.polygon.is_empty]


def widest_plan(plans: Sequence[Plan | None]) -> Plan:
    """Of a fleet's plans (None: a vehicle left idle), the one read over the largest DSM
    window (the highest layer's), whose DSM a fleet's map shows."""
    return max((p for p in plans if p is not None), key=lambda p: p.terrain.elevation_m.size)


def vehicle_label(number: int, plan: Plan) -> str:
    """What a fleet's map says of vehicle ``number``: its targets, length, time and layer."""
    return (
        f"vehicle {number}: {len(plan.targets.targets)} targets, "
        f"{plan.flown_length_m:.0f} m, {plan.flight_time_s / 60:.1f} min at "
        f"{plan.camera.altitude_m:.0f} m"
    )


def map_transformer(crs: pyproj.CRS) -> pyproj.Transformer:
    """From (lon, lat) in WGS84 to ``crs``, the planning CRS."""
    return pyproj.Transformer.from_crs(WGS84, crs, always_xy=True)


def sortie_routes(plan: Plan, to_map: pyproj.Transformer) -> list[FloatArray]:
    """Each sortie as flown, in the planning CRS: home, its missions' waypoints (with a photo
    or without), home."""
    routes = []
    for mission in plan.missions:
        home = (mission.home.lat_deg, mission.home.lon_deg)
        lat, lon = np.array([home, *waypoint_positions(mission), home]).T
        x, y = to_map.transform(lon, lat)
        routes.append(np.column_stack([x, y]))
    return routes


def geofence_xy(plan: Plan, to_map: pyproj.Transformer) -> FloatArray:
    """The geofence's vertices in the planning CRS."""
    fence_lat, fence_lon = zip(*plan.geofence_latlon, strict=True)
    fx, fy = to_map.transform(fence_lon, fence_lat)
    return np.column_stack([fx, fy])


def frame_footprints(plan: Plan) -> list[FloatArray]:
    """Each photo's frame on the ground, in the planning CRS: the rectangle turned by the
    stop's heading, at the mean ground height of the targets it is counted for (a frame
    camera only; empty for the cone)."""
    frame, tour = plan.camera.frame, plan.tour
    if frame is None or tour.headings_deg is None or tour.points_xy is None:
        return []
    out = []
    corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    eyes = eye_heights_m(plan)
    for k, (x, y) in enumerate(tour.points_xy):
        seen = np.flatnonzero(tour.sees[k])
        ground = float(plan.ground_m[seen].mean()) if seen.size else float(plan.ground_m.min())
        h = float(eyes[k]) - ground
        across, along = (
            corners[:, 0] * h * frame.half_tan_across,
            corners[:, 1] * h * frame.half_tan_along,
        )
        psi = math.radians(float(tour.headings_deg[k]))
        # Across the heading is its right-hand side: (cos, -sin); along it (sin, cos).
        dx = across * math.cos(psi) + along * math.sin(psi)
        dy = -across * math.sin(psi) + along * math.cos(psi)
        out.append(np.column_stack([x + dx, y + dy]))
    return out


def view_bounds(shapes: Sequence[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """The lower-left and upper-right corners of a view holding every point of ``shapes``
    (arrays of (x, y) rows) with a margin of 8 % of the larger side and 5 m."""
    everything = np.vstack(list(shapes))
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    pad = 0.08 * float(max(hi - lo)) + 5.0
    return lo - pad, hi + pad


def _camera_words(data: dict[str, Any]) -> str:
    camera = data.get("camera")
    if camera is None:
        return f"camera ±{data['fov_deg']:g}°"
    w, h = camera["sensor_mm"]
    gsd = f", worst GSD {camera['worst_gsd_cm']:.2f} cm/px"
    return f"frame {w:g}x{h:g} mm / {camera['focal_mm']:g} mm{gsd}"


def map_title(data: dict[str, Any]) -> str:
    """The map's title, two lines from the summary: targets, stops, the flight against the
    shortest possible, its time and sorties; then the altitude (or the band), the camera
    and the solver."""
    quality = flight_quality(data, short=True)
    count = len(data["sorties"])
    sorties = f" in {count} sorties, each from home and back" if count > 1 else ""
    return (
        f"{data['targets']} targets, {data['tour_stops']} stops, "
        f"{'flown' if count > 1 else 'tour'} {data['tour_length_m']:.0f} m"
        f" ({quality}), {data['flight_time_s'] / 60:.1f} min{sorties}\n"
        + (
            title_lines(data)
            if "band" in data
            else f"altitude {data['altitude_amsl_m']:.1f} m AMSL / "
            f"{data['altitude_above_home_m']:.1f} m above home"
        )
        + f", {_camera_words(data)}, solver {data['solver']}"
    )
