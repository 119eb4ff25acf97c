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
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrow
from matplotlib.patches import Polygon as PolygonPatch
from matplotlib.transforms import Affine2D

from urpt_gcs.arrays import FloatArray
from urpt_gcs.files.bandview import PROFILE_ROW_IN, draw_band_stops, draw_profiles, profile_grid
from urpt_gcs.files.mapbase import (
    BACKGROUND,
    FENCE_COLOUR,
    NODATA_ALPHA,
    NODATA_COLOUR,
    TINT_ALPHA,
    TINT_CMAP,
    display_step,
    frame_footprints,
    geofence_xy,
    hillshade,
    map_title,
    map_transformer,
    region_rings,
    sortie_routes,
    target_colours,
    vehicle_label,
    view_bounds,
    widest_plan,
)
from urpt_gcs.files.report import flown_stops, sortie_colour
from urpt_gcs.flight.mission import photo_positions
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.site.terrain import Terrain

# Text properties for words from the inputs: drawn as written, whatever the rcParams say.
_PLAIN: dict[str, Any] = {"parse_math": False, "usetex": False}


def _nice_length(span_m: float) -> float:
    """A round scale-bar length near a fifth of ``span_m``."""
    raw = span_m / 5.0
    power = 10.0 ** math.floor(math.log10(raw))
    return float(next(k * power for k in (5, 2, 1) if k * power <= raw))


def render_map(plan: Plan, data: dict[str, Any]) -> bytes:
    """A PNG of the plan, for the operator to check at a glance."""
    fig = map_figure(plan, data)
    out = io.BytesIO()
    fig.savefig(out, format="png")
    return out.getvalue()


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


def _terrain_figure(terrain: Terrain, profiles: int = 0) -> tuple[Figure, Any, list[Any]]:
    """A figure with the DSM drawn hillshaded and tinted, in the planning CRS, and below it
    ``profiles`` empty panels (see :func:`~urpt_gcs.files.bandview.profile_grid`)."""
    step = display_step(terrain)
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
    ax.set_facecolor(BACKGROUND)

    rows, cols = z.shape
    extent = (0.0, float(cols), float(rows), 0.0)
    shade = np.ma.masked_invalid(hillshade(z, terrain.cell_m * step))
    gray = ax.imshow(shade, cmap="gray", extent=extent, interpolation="nearest", vmin=0, vmax=1)
    gray.set_transform(pixel_to_map + ax.transData)
    tint = ax.imshow(
        np.ma.masked_invalid(z),
        cmap=TINT_CMAP,
        alpha=TINT_ALPHA,
        extent=extent,
        interpolation="nearest",
    )
    tint.set_transform(pixel_to_map + ax.transData)
    nodata = np.ma.masked_where(np.isfinite(z), np.ones_like(z))
    hole = ax.imshow(
        nodata,
        cmap=ListedColormap([NODATA_COLOUR]),
        extent=extent,
        alpha=NODATA_ALPHA,
        interpolation="nearest",
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
    palette = target_colours(len(plan.regions) or len(plan.targets_xy))
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
    to_map = map_transformer(plan.crs)
    paths = _draw_sorties(ax, plan, to_map)
    if band is not None:
        draw_band_stops(fig, ax, plan)
    _draw_frames(ax, plan)
    ax.scatter(
        [hx], [hy], marker="*", s=260, c="white", edgecolors="black", zorder=11, label="home"
    )

    fence = geofence_xy(plan, to_map)
    ax.add_patch(
        PolygonPatch(
            fence,
            closed=True,
            fill=False,
            edgecolor=FENCE_COLOUR,
            linestyle="--",
            linewidth=1.2,
            zorder=4,
            label="geofence",
        )
    )
    lo, hi = view_bounds([*paths, plan.targets_xy, fence, *region_rings(plan)])
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    _scale_bar_and_north(ax, lo, hi)
    ax.set_xlabel(f"easting (m, {plan.crs.name})", **_PLAIN)
    ax.set_ylabel("northing (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)
    ax.set_title(map_title(data), fontsize=10)
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
    widest = widest_plan(plans)
    fig, ax, _ = _terrain_figure(widest.terrain)
    to_map = map_transformer(widest.crs)
    drawn = []
    for number, plan in enumerate(plans, start=1):
        if plan is None:
            continue
        colour = sortie_colour(number)
        for ring in region_rings(plan):
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
        label = vehicle_label(number, plan)
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
    lo, hi = view_bounds(drawn)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    _scale_bar_and_north(ax, lo, hi)
    ax.set_xlabel(f"easting (m, {widest.crs.name})", **_PLAIN)
    ax.set_ylabel("northing (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    return fig


__all__ = ["fleet_figure", "map_figure", "render_fleet_map", "render_map"]
