"""The plan on a map: hillshaded DSM, regions, targets, the sorties as flown (each from home
and back, in its own colour, stops numbered in flight order), home, scale bar and north arrow.

Drawn with matplotlib's object API (no pyplot, no global state) in the planning CRS, so
distances on the picture are metres on the ground. A plan inside a height band has no
regions; its stops are coloured by their height above the surface and a profile per sortie
is drawn below the map (:mod:`urpt_gcs.files.bandview`).

Text from the inputs (target names, the DEM's CRS name) is drawn as plain text: a ``$`` in
a name is a dollar sign, never the start of matplotlib math or TeX.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyproj
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LightSource
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrow
from matplotlib.patches import Polygon as PolygonPatch
from matplotlib.transforms import Affine2D

from urpt_gcs.arrays import FloatArray
from urpt_gcs.files.band_report import eye_heights_m
from urpt_gcs.files.bandview import (
    PROFILE_ROW_IN,
    draw_band_stops,
    draw_profiles,
    profile_grid,
    title_lines,
)
from urpt_gcs.files.report import flight_quality, flown_stops, sortie_colour
from urpt_gcs.flight.mission import photo_positions, waypoint_positions
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.site.dem import WGS84
from urpt_gcs.site.terrain import Terrain

# Longest side of the raster drawn, in pixels; larger windows are decimated for display.
_MAX_DISPLAY_PX = 1600
# Text properties for words from the inputs: drawn as written, whatever the rcParams say.
_PLAIN: dict[str, Any] = {"parse_math": False, "usetex": False}


def _nice_length(span_m: float) -> float:
    """A round scale-bar length near a fifth of ``span_m``."""
    raw = span_m / 5.0
    power = 10.0 ** math.floor(math.log10(raw))
    return float(next(k * power for k in (5, 2, 1) if k * power <= raw))


def _hillshade(z: FloatArray, cell_m: float) -> FloatArray:
    filled = np.where(np.isfinite(z), z, np.nanmean(z) if np.isfinite(z).any() else 0.0)
    shade: FloatArray = LightSource(azdeg=315, altdeg=45).hillshade(
        filled, vert_exag=1.0, dx=cell_m, dy=cell_m
    )
    return np.where(np.isfinite(z), shade, np.nan)


def render_map(plan: Plan, data: dict[str, Any]) -> bytes:
    """A PNG of the plan, for the operator to check at a glance."""
    fig = map_figure(plan, data)
    out = io.BytesIO()
    fig.savefig(out, format="png")
    return out.getvalue()


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


def _draw_sorties(ax: Any, plan: Plan, to_map: pyproj.Transformer) -> list[FloatArray]:
    """Each sortie's route in its colour, with the stops' order numbers; the routes drawn."""
    routes = sortie_routes(plan, to_map)
    stops = flown_stops(plan)
    many = len(routes) > 1
    numbered = plan.band_flight is None  # a band's stops are drawn by their height
    for number, (route, sortie) in enumerate(zip(routes, plan.sorties, strict=True), start=1):
        colour = sortie_colour(number)
        label = (
            f"sortie {number}: {sortie.stop - sortie.first} stops, {sortie.length_m:.0f} m, "
            f"{sortie.flight_time_s / 60:.1f} min"
            if many
            else "tour"
        )
        ax.plot(route[:, 0], route[:, 1], "-", color="black", linewidth=2.4, zorder=7)
        ax.plot(
            route[:, 0],
            route[:, 1],
            "-",
            color=colour,
            linewidth=1.4,
            zorder=8,
            label=label,
            gid=f"sortie {number}",
        )
        lat, lon = np.array(photo_positions(plan.missions[number - 1])).T
        at = np.column_stack(to_map.transform(lon, lat))
        mine = (s for s in stops if s.sortie == number)
        for stop, (x, y) in zip(mine, at if numbered else [], strict=numbered):
            ax.annotate(
                str(stop.order),
                (x, y),
                ha="center",
                va="center",
                fontsize=7,
                fontweight="bold",
                zorder=10,
                bbox={"boxstyle": "circle,pad=0.2", "fc": colour, "ec": "black", "lw": 0.8},
            )
    return routes


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


def _draw_frames(ax: Any, plan: Plan) -> None:
    for k, ring in enumerate(frame_footprints(plan)):
        ax.add_patch(
            PolygonPatch(
                ring,
                closed=True,
                fill=False,
                edgecolor="black",
                linestyle=":",
                linewidth=0.9,
                zorder=6,
                label="photo frame" if k == 0 else None,
            )
        )


def _camera_words(data: dict[str, Any]) -> str:
    camera = data.get("camera")
    if camera is None:
        return f"camera ±{data['fov_deg']:g}°"
    w, h = camera["sensor_mm"]
    gsd = f", worst GSD {camera['worst_gsd_cm']:.2f} cm/px"
    return f"frame {w:g}x{h:g} mm / {camera['focal_mm']:g} mm{gsd}"


def _terrain_figure(terrain: Terrain, profiles: int = 0) -> tuple[Figure, Any, list[Any]]:
    """A figure with the DSM drawn hillshaded and tinted, in the planning CRS, and below it
    ``profiles`` empty panels (see :func:`~urpt_gcs.files.bandview.profile_grid`)."""
    step = max(1, math.ceil(max(terrain.elevation_m.shape) / _MAX_DISPLAY_PX))
    z = np.asarray(terrain.elevation_m[::step, ::step], dtype=np.float64)
    t = terrain.transform
    pixel_to_map = Affine2D.from_values(t.a * step, t.d * step, t.b * step, t.e * step, t.c, t.f)

    rows, cols = profile_grid(profiles) if profiles else (0, 1)
    fig = Figure(figsize=(11, 10 + PROFILE_ROW_IN * rows), dpi=110)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(1 + rows, cols, height_ratios=[10.0] + [PROFILE_ROW_IN] * rows)
    ax = fig.add_subplot(grid[0, :])
    panels = [fig.add_subplot(grid[1 + k // cols, k % cols]) for k in range(profiles)]
    ax.set_aspect("equal")
    ax.set_facecolor("#eeeeee")

    rows, cols = z.shape
    extent = (0.0, float(cols), float(rows), 0.0)
    shade = np.ma.masked_invalid(_hillshade(z, terrain.cell_m * step))
    gray = ax.imshow(shade, cmap="gray", extent=extent, interpolation="nearest", vmin=0, vmax=1)
    gray.set_transform(pixel_to_map + ax.transData)
    tint = ax.imshow(
        np.ma.masked_invalid(z), cmap="terrain", alpha=0.45, extent=extent, interpolation="nearest"
    )
    tint.set_transform(pixel_to_map + ax.transData)
    nodata = np.ma.masked_where(np.isfinite(z), np.ones_like(z))
    hole = ax.imshow(
        nodata, cmap="Reds", vmin=0, vmax=3, extent=extent, alpha=0.55, interpolation="nearest"
    )
    hole.set_transform(pixel_to_map + ax.transData)
    bar = fig.colorbar(tint, ax=ax, shrink=0.6, pad=0.01)
    bar.set_label("elevation (m, DEM datum); red: no data")
    return fig, ax, panels


def map_figure(plan: Plan, data: dict[str, Any]) -> Figure:
    """The map as a matplotlib figure; each sortie's route is the line with gid
    ``sortie N``."""
    band = plan.band_flight
    fig, ax, panels = _terrain_figure(plan.terrain, 0 if band is None else len(plan.missions))
    # A colour per target and its region; a band plan has no regions.
    palette = [f"C{k % 10}" for k in range(len(plan.regions) or len(plan.targets_xy))]
    for region, colour in zip(plan.regions, palette if plan.regions else [], strict=True):
        if region.polygon.is_empty:
            continue
        ring = np.asarray(region.polygon.exterior.coords)
        ax.add_patch(
            PolygonPatch(
                ring, closed=True, facecolor=colour, edgecolor=colour, alpha=0.18, linewidth=1.2
            )
        )
        ax.add_patch(PolygonPatch(ring, closed=True, fill=False, edgecolor=colour, linewidth=1.2))

    names = [t.name for t in plan.targets.targets]
    tx, ty = plan.targets_xy[:, 0], plan.targets_xy[:, 1]
    ax.scatter(tx, ty, marker="^", s=60, c=palette, edgecolors="black", zorder=5, label="target")
    for x, y, name in zip(tx, ty, names, strict=True):
        ax.annotate(
            name,
            (x, y),
            xytext=(4, 4),
            textcoords="offset points",
            fontsize=7,
            zorder=6,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.7, "lw": 0},
            **_PLAIN,
        )

    hx, hy = plan.home_xy
    to_map = pyproj.Transformer.from_crs(WGS84, plan.crs, always_xy=True)
    paths = _draw_sorties(ax, plan, to_map)
    if band is not None:
        draw_band_stops(fig, ax, plan)
    _draw_frames(ax, plan)
    ax.scatter(
        [hx], [hy], marker="*", s=260, c="white", edgecolors="black", zorder=11, label="home"
    )

    fence_lat, fence_lon = zip(*plan.geofence_latlon, strict=True)
    fx, fy = to_map.transform(fence_lon, fence_lat)
    ax.add_patch(
        PolygonPatch(
            np.column_stack([fx, fy]),
            closed=True,
            fill=False,
            edgecolor="#c00000",
            linestyle="--",
            linewidth=1.2,
            zorder=4,
            label="geofence",
        )
    )
    everything = np.vstack(
        [*paths, plan.targets_xy, np.column_stack([fx, fy])]
        + [np.asarray(r.polygon.exterior.coords) for r in plan.regions if not r.polygon.is_empty]
    )
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    pad = 0.08 * float(max(hi - lo)) + 5.0
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    _scale_bar_and_north(ax, lo - pad, hi + pad)
    ax.set_xlabel(f"easting (m, {plan.crs.name})", **_PLAIN)
    ax.set_ylabel("northing (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)
    quality = flight_quality(data, short=True)
    count = len(data["sorties"])
    sorties = f" in {count} sorties, each from home and back" if count > 1 else ""
    ax.set_title(
        f"{data['targets']} targets, {data['tour_stops']} stops, "
        f"{'flown' if count > 1 else 'tour'} {data['tour_length_m']:.0f} m"
        f" ({quality}), {data['flight_time_s'] / 60:.1f} min{sorties}\n"
        + (
            title_lines(data)
            if band is not None
            else f"altitude {data['altitude_amsl_m']:.1f} m AMSL / "
            f"{data['altitude_above_home_m']:.1f} m above home"
        )
        + f", {_camera_words(data)}, solver {data['solver']}",
        fontsize=10,
    )
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    if band is not None:
        draw_profiles(panels, plan)
    fig.tight_layout()
    _draw_altitude_curve(fig, data)
    return fig


def _draw_altitude_curve(fig: Figure, data: dict[str, Any]) -> None:
    """With --altitude auto, the curve in the upper left corner: altitude against tour
    length and flight time, the kept altitude marked."""
    curve = [p for p in data.get("altitude_curve", []) if p["flight_time_s"] is not None]
    if not curve:
        return
    inset = fig.add_axes((0.09, 0.72, 0.2, 0.16))
    altitude = [p["altitude_amsl_m"] for p in curve]
    minutes = [p["flight_time_s"] / 60.0 for p in curve]
    length = [p["tour_length_m"] for p in curve]
    inset.plot(altitude, minutes, "o-", color="C3", markersize=3, label="flight (min)")
    inset.axvline(data["altitude_best_amsl_m"], color="black", linestyle=":", linewidth=0.8)
    inset.set_xlabel("altitude (m AMSL)", fontsize=6)
    inset.set_ylabel("flight time (min)", fontsize=6, color="C3")
    inset.tick_params(labelsize=6)
    twin = inset.twinx()
    twin.plot(altitude, length, "s--", color="C0", markersize=3)
    twin.set_ylabel("tour (m)", fontsize=6, color="C0")
    twin.tick_params(labelsize=6)
    inset.set_title("--altitude auto", fontsize=7)
    inset.patch.set_alpha(0.85)


def _scale_bar_and_north(ax: Any, lo: FloatArray, hi: FloatArray) -> None:
    span = float(hi[0] - lo[0])
    length = _nice_length(span)
    x0 = float(lo[0]) + 0.05 * span
    y0 = float(lo[1]) + 0.05 * float(hi[1] - lo[1])
    ax.plot(
        [x0, x0 + length], [y0, y0], color="black", linewidth=4, zorder=12, solid_capstyle="butt"
    )
    ax.plot(
        [x0, x0 + length],
        [y0, y0],
        color="white",
        linewidth=2,
        zorder=13,
        solid_capstyle="butt",
        dashes=(4, 4),
    )
    ax.text(
        x0 + length / 2,
        y0 + 0.015 * float(hi[1] - lo[1]),
        f"{length:g} m",
        ha="center",
        va="bottom",
        fontsize=8,
        zorder=13,
    )
    height = float(hi[1] - lo[1])
    ax_x = float(hi[0]) - 0.06 * span
    ax_y = float(hi[1]) - 0.16 * height
    ax.add_patch(
        FancyArrow(
            ax_x,
            ax_y,
            0.0,
            0.08 * height,
            width=0.012 * span,
            head_width=0.035 * span,
            head_length=0.03 * height,
            color="black",
            zorder=12,
        )
    )
    ax.text(
        ax_x,
        ax_y + 0.11 * height,
        "N",
        ha="center",
        va="bottom",
        fontsize=12,
        fontweight="bold",
        zorder=12,
    )


def render_fleet_map(plans: Sequence[Plan | None], title: str) -> bytes:
    """A PNG of a fleet's plans: each vehicle's regions, targets, routes and home in its own
    colour over the DSM of the widest window (the highest layer's); None, a vehicle left
    idle, is not drawn."""
    fig = fleet_figure(plans, title)
    out = io.BytesIO()
    fig.savefig(out, format="png")
    return out.getvalue()


def fleet_figure(plans: Sequence[Plan | None], title: str) -> Figure:
    """The fleet map as a matplotlib figure; vehicle k's routes are the lines with gid
    ``vehicle k sortie N``."""
    widest = max((p for p in plans if p is not None), key=lambda p: p.terrain.elevation_m.size)
    fig, ax, _ = _terrain_figure(widest.terrain)
    to_map = pyproj.Transformer.from_crs(WGS84, widest.crs, always_xy=True)
    drawn = []
    for number, plan in enumerate(plans, start=1):
        if plan is None:
            continue
        colour = sortie_colour(number)
        for region in plan.regions:
            if region.polygon.is_empty:
                continue
            ring = np.asarray(region.polygon.exterior.coords)
            drawn.append(ring)
            ax.add_patch(
                PolygonPatch(ring, closed=True, facecolor=colour, alpha=0.15, edgecolor=colour)
            )
        tx, ty = plan.targets_xy[:, 0], plan.targets_xy[:, 1]
        ax.scatter(tx, ty, marker="^", s=50, color=colour, edgecolors="black", zorder=5)
        for x, y, t in zip(tx, ty, plan.targets.targets, strict=True):
            ax.annotate(
                t.name, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=6, **_PLAIN
            )
        label = (
            f"vehicle {number}: {len(plan.targets.targets)} targets, "
            f"{plan.flown_length_m:.0f} m, {plan.flight_time_s / 60:.1f} min at "
            f"{plan.camera.altitude_m:.0f} m"
        )
        for k, route in enumerate(sortie_routes(plan, to_map), start=1):
            drawn.append(route)
            ax.plot(route[:, 0], route[:, 1], "-", color="black", linewidth=2.4, zorder=7)
            ax.plot(
                route[:, 0],
                route[:, 1],
                "-",
                color=colour,
                linewidth=1.4,
                zorder=8,
                label=label if k == 1 else None,
                gid=f"vehicle {number} sortie {k}",
            )
        hx, hy = plan.home_xy
        ax.scatter([hx], [hy], marker="*", s=220, color=colour, edgecolors="black", zorder=11)
    everything = np.vstack(drawn)
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    pad = 0.08 * float(max(hi - lo)) + 5.0
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    _scale_bar_and_north(ax, lo - pad, hi + pad)
    ax.set_xlabel(f"easting (m, {widest.crs.name})", **_PLAIN)
    ax.set_ylabel("northing (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    return fig


__all__ = [
    "fleet_figure",
    "frame_footprints",
    "map_figure",
    "render_fleet_map",
    "render_map",
    "sortie_routes",
]
