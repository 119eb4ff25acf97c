"""What the map of a plan inside a height band (``--agl``) draws beside the plane's.

On the map the stops are coloured by their height above the surface (with a colorbar) and
the waypoints without a photo that follow the terrain are dotted on the routes. Below it a
panel per sortie shows its profile along the path's horizontal distance: the surface sampled
densely along the path, the band over it (surface + floor to surface + ceiling, shaded), and
the height flown (straight between the waypoints), its stops numbered.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from urpt_gcs.files.band_report import band_stops, path_profile
from urpt_gcs.files.report import sortie_colour
from urpt_gcs.pipeline.result import Plan

__all__ = [
    "BAND_COLOUR",
    "BAND_EDGE_COLOUR",
    "GROUND_COLOUR",
    "PROFILE_ROW_IN",
    "SURFACE_COLOUR",
    "draw_band_stops",
    "draw_profiles",
    "profile_grid",
    "title_lines",
]

# Height of a row of profile panels, in inches.
PROFILE_ROW_IN = 2.6
_HEIGHT_CMAP = "viridis"
# The profile's colours: the band over the surface and its limits, the ground under the
# surface, and the surface's line.
BAND_COLOUR = "#6baed6"
BAND_EDGE_COLOUR = "#3182bd"
GROUND_COLOUR = "#a1887f"
SURFACE_COLOUR = "#5d4037"


def profile_grid(sorties: int) -> tuple[int, int]:
    """Rows and columns of the profile panels for ``sorties`` sorties."""
    cols = 1 if sorties == 1 else 2 if sorties <= 12 else 3
    return math.ceil(sorties / cols), cols


def draw_band_stops(fig: Figure, ax: Any, plan: Plan) -> None:
    """Stops coloured by their height above the surface, with their order numbers and a
    colorbar; the waypoints without a photo as small dots in their sortie's colour."""
    flight = plan.band_flight
    assert flight is not None
    for number, (path, stop_of) in enumerate(
        zip(flight.paths_xyz, flight.path_stop, strict=True), start=1
    ):
        inserted = path[stop_of == -1]
        ax.scatter(
            inserted[:, 0],
            inserted[:, 1],
            s=10,
            color=sortie_colour(number),
            edgecolors="black",
            linewidths=0.5,
            zorder=9,
            label="waypoint without a photo" if number == 1 and len(inserted) else None,
        )
    stops = band_stops(plan)
    xs = [s.x_m for s in stops]
    ys = [s.y_m for s in stops]
    above = [s.above_surface_m for s in stops]
    dots = ax.scatter(
        xs,
        ys,
        c=above,
        cmap=_HEIGHT_CMAP,
        vmin=flight.band.floor_m,
        vmax=flight.band.ceiling_m,
        s=90,
        edgecolors="black",
        linewidths=0.9,
        zorder=10,
    )
    for stop in stops:
        ax.annotate(
            str(stop.order),
            (stop.x_m, stop.y_m),
            xytext=(6, 6),
            textcoords="offset points",
            fontsize=7,
            fontweight="bold",
            zorder=11,
            bbox={"boxstyle": "round,pad=0.15", "fc": sortie_colour(stop.sortie), "lw": 0.6},
        )
    bar = fig.colorbar(dots, ax=ax, shrink=0.6, pad=0.01)
    bar.set_label("stop height above the surface (m)")


def draw_profiles(axes: list[Any], plan: Plan) -> None:
    """Per sortie, its profile in its panel of ``axes`` (one per sortie)."""
    flight = plan.band_flight
    assert flight is not None
    floor, ceiling = flight.band.floor_m, flight.band.ceiling_m
    home_ground = plan.mission.home.amsl_m
    for k, ax in enumerate(axes):
        profile = path_profile(plan, k)
        at, surface = profile["at_m"], profile["surface_m"]
        ax.fill_between(
            at, surface + floor, surface + ceiling, color=BAND_COLOUR, alpha=0.3, lw=0, label="band"
        )
        ax.plot(at, surface + floor, color=BAND_EDGE_COLOUR, linewidth=0.6)
        ax.plot(at, surface + ceiling, color=BAND_EDGE_COLOUR, linewidth=0.6)
        ax.fill_between(at, np.nanmin(surface) - 0.05 * ceiling, surface, color=GROUND_COLOUR)
        ax.plot(at, surface, color=SURFACE_COLOUR, linewidth=0.9, label="surface")
        distance, z, stop = profile["distance_m"], profile["z_m"], profile["stop"]
        colour = sortie_colour(k + 1)
        # The climb from home and the landing back on it.
        ax.plot([0.0, 0.0], [home_ground, z[0]], ":", color="black", linewidth=0.9)
        ax.plot([distance[-1]] * 2, [z[-1], home_ground], ":", color="black", linewidth=0.9)
        ax.plot(distance, z, "-", color="black", linewidth=2.2, zorder=4)
        ax.plot(distance, z, "-", color=colour, linewidth=1.2, zorder=5, label="flight")
        inserted = stop == -1
        ax.plot(distance[inserted], z[inserted], "o", color=colour, mec="black", ms=3, zorder=6)
        for i in np.flatnonzero(stop >= 0).tolist():
            ax.plot(distance[i], z[i], "o", color="white", mec="black", ms=7, zorder=6)
            ax.annotate(
                str(int(stop[i]) + 1),
                (distance[i], z[i]),
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
                fontsize=6,
                fontweight="bold",
                zorder=7,
            )
        ax.set_title(f"sortie {k + 1}: profile along the path", fontsize=8)
        ax.set_xlabel("horizontal distance (m)", fontsize=7)
        ax.set_ylabel("height (m, DEM datum)", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_xlim(-0.02 * distance[-1] - 1.0, 1.02 * distance[-1] + 1.0)
        if k == 0:
            ax.legend(loc="upper right", fontsize=6, framealpha=0.8)


def title_lines(data: dict[str, Any]) -> str:
    """The map title's second line for a band plan (in place of the plane's altitude)."""
    band = data["band"]
    return (
        f"band {band['floor_m']:g}:{band['ceiling_m']:g} m above the surface, flown "
        f"{band['lowest_above_surface_m']:.1f} to {band['highest_above_surface_m']:.1f} m; "
        f"{band['inserted_waypoints']} waypoints follow the terrain"
    )
