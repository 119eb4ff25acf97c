"""The plan as one web page (``map.html``) that works offline: pan, zoom, layers to show or
hide, and what each stop does under the pointer.

It shows what ``map.png`` shows (:mod:`urpt_gcs.files.mapview`), from the same figures
(:mod:`urpt_gcs.files.mapbase`): the hillshaded DSM, the visibility regions, the targets with
their names, each sortie's route as flown from home and back in its own colour, its stops
(hovering one tells the targets it sees, its ETA from take-off, its height above the ground
below it and, for a frame camera, the ground resolution at each of its targets), home, the
geofence and, for a frame camera, each photo's frame on the ground. A plan inside a height
band adds a second figure, each sortie's profile: the surface, the band over it and the
height flown along the route. A fleet's page shows every vehicle in its own colour.

Drawn with Bokeh in the planning CRS (metres). The page holds everything it needs: Bokeh's
JavaScript inline and the DSM as a PNG data URI, so opening it makes no network request.
Every renderer has a stable ``name`` (``dsm``, ``regions``, ``targets``, ``target-names``,
``sortie-N``, ``stops``, ``stop-numbers``, ``home``, ``geofence``, ``frames``, ``waypoints``,
``profile-N``, ...; a fleet's are prefixed ``vehicle-K-``), so the page can be checked from
JavaScript with ``Bokeh.documents[0].get_model_by_name(name)``.

Text from the inputs (target names, the DEM's CRS name) is shown as plain text: drawn on the
canvas or escaped in tooltips, never read as HTML or TeX.
"""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Sequence
from typing import Any, TypeAlias

import matplotlib
import numpy as np
import pyproj
from bokeh.core.property.vectorization import Field
from bokeh.embed import file_html
from bokeh.layouts import column
from bokeh.model import Model
from bokeh.models import (
    BasicTickFormatter,
    BoxZoomTool,
    ColumnDataSource,
    HoverTool,
    LinearColorMapper,
    PanTool,
    PlainText,
    Range1d,
    ResetTool,
    SaveTool,
    WheelZoomTool,
)
from bokeh.models.annotations import ColorBar, Legend, LegendItem, ScaleBar, Title
from bokeh.models.renderers import DataRenderer, GlyphRenderer
from bokeh.palettes import Viridis256
from bokeh.plotting import figure
from bokeh.resources import INLINE
from bokeh.transform import linear_cmap
from matplotlib.colors import to_hex
from matplotlib.image import imsave

from urpt_gcs.arrays import FloatArray
from urpt_gcs.files.band_report import eye_heights_m, path_profile
from urpt_gcs.files.bandview import BAND_COLOUR, GROUND_COLOUR, SURFACE_COLOUR
from urpt_gcs.files.mapbase import (
    BACKGROUND,
    FENCE_COLOUR,
    TINT_CMAP,
    display_step,
    frame_footprints,
    geofence_xy,
    map_title,
    map_transformer,
    region_rings,
    relief_rgb,
    sortie_routes,
    target_colours,
    vehicle_label,
    view_bounds,
    widest_plan,
)
from urpt_gcs.files.report import photo_gsd_cm, sortie_colour
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.site.terrain import Terrain

__all__ = ["PAGE_TITLE", "render_fleet_page", "render_map_page"]

# The page's <title>.
PAGE_TITLE = "urpt-gcs plan map"
# Longest side of the DSM picture embedded in the page, in pixels: sharp on a screen, and a
# page of a few megabytes at most.
_PAGE_MAX_PX = 1000
# The map's drawing area: its width, and the least and most height for its aspect.
_MAP_WIDTH_PX = 900
_MAP_HEIGHT_PX = (360, 1000)
# The profile's drawing area under the map, as wide as it.
_PROFILE_HEIGHT_PX = 320
# What the pointer can do on the profile: pan, zoom with the wheel or a box, go back, save.
_PROFILE_TOOLS = "pan,wheel_zoom,box_zoom,reset,save"


def _relief_picture(terrain: Terrain) -> tuple[str, tuple[float, float, float, float]]:
    """The DSM as a north-up PNG data URI and where it lies: (left, top, width, height) in
    the planning CRS. A raster that is not north-up is resampled (nearest cell)."""
    step = display_step(terrain, _PAGE_MAX_PX)
    cell = terrain.cell_m * step
    rows, cols = terrain.elevation_m.shape
    t = terrain.transform
    c, r = np.array([0, cols, 0, cols]), np.array([0, 0, rows, rows])
    corner_x, corner_y = t.c + t.a * c + t.b * r, t.f + t.d * c + t.e * r
    left, right = float(corner_x.min()), float(corner_x.max())
    bottom, top = float(corner_y.min()), float(corner_y.max())
    nx = max(1, round((right - left) / cell))
    ny = max(1, round((top - bottom) / cell))
    x, y = np.meshgrid(
        left + (np.arange(nx) + 0.5) * (right - left) / nx,
        top - (np.arange(ny) + 0.5) * (top - bottom) / ny,
    )
    col, row = (np.rint(v).astype(np.intp) for v in terrain.pixel_coords(x, y))
    inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
    z = np.full(x.shape, np.nan)
    z[inside] = terrain.elevation_m[row[inside], col[inside]]
    png = io.BytesIO()
    imsave(png, relief_rgb(z, cell), format="png")
    uri = "data:image/png;base64," + base64.b64encode(png.getvalue()).decode("ascii")
    return uri, (float(left), float(top), float(right - left), float(top - bottom))


def _map_figure(
    terrain: Terrain, crs_name: str, lo: FloatArray, hi: FloatArray
) -> tuple[figure, GlyphRenderer[Any]]:
    """A map of the view from ``lo`` to ``hi`` at one scale on both axes, with the DSM drawn
    under everything, its elevation colour bar and a scale bar; and the DSM's renderer
    (``dsm``)."""
    span_x, span_y = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    height = int(np.clip(_MAP_WIDTH_PX * span_y / span_x, *_MAP_HEIGHT_PX))
    # Widen the shorter side so that a metre is as long across as up.
    scale = max(span_x / _MAP_WIDTH_PX, span_y / height)
    mid = (lo + hi) / 2.0
    half_x, half_y = scale * _MAP_WIDTH_PX / 2.0, scale * height / 2.0
    # What the pointer can do: pan, zoom with the wheel or a box of the map's aspect, go
    # back, save.
    wheel = WheelZoomTool()
    fig = figure(
        x_range=Range1d(start=float(mid[0]) - half_x, end=float(mid[0]) + half_x),
        y_range=Range1d(start=float(mid[1]) - half_y, end=float(mid[1]) + half_y),
        frame_width=_MAP_WIDTH_PX,
        frame_height=height,
        tools=[PanTool(), wheel, BoxZoomTool(match_aspect=True), ResetTool(), SaveTool()],
        active_scroll=wheel,
        background_fill_color=BACKGROUND,
        name="map",
    )
    fig.xaxis.axis_label = PlainText(text=f"easting (m, {crs_name})")
    fig.yaxis.axis_label = "northing (m)"
    fig.xaxis.formatter = BasicTickFormatter(use_scientific=False)
    fig.yaxis.formatter = BasicTickFormatter(use_scientific=False)
    fig.grid.visible = False
    fig.toolbar.logo = None
    uri, (left, top, width, tall) = _relief_picture(terrain)
    dsm = fig.image_url(
        url=[uri], x=left, y=top, w=width, h=tall, anchor="top_left", name="dsm", level="image"
    )
    z = terrain.elevation_m
    low, high = (float(np.nanmin(z)), float(np.nanmax(z))) if np.isfinite(z).any() else (0, 1)
    tint = [to_hex(c) for c in matplotlib.colormaps[TINT_CMAP](np.linspace(0.0, 1.0, 256))]
    fig.add_layout(
        ColorBar(
            color_mapper=LinearColorMapper(palette=tint, low=low, high=high),
            title="elevation (m, DEM datum); red: no data",
            width=12,
        ),
        "right",
    )
    fig.add_layout(ScaleBar(range=fig.x_range, unit="m", location="bottom_left"))
    return fig, dsm


def _titled(fig: figure, text: str) -> None:
    """Give ``fig`` a title of one or more lines, the first on top."""
    first, *more = text.splitlines()
    fig.title = first
    for line in more:
        fig.add_layout(Title(text=line), "above")


def _stop_rows(
    plan: Plan, data: dict[str, Any], to_map: pyproj.Transformer
) -> dict[str, list[Any]]:
    """The columns of the stops' source: where each stop is, its order and sortie, what it
    sees, its ETA, its height above the ground and the GSD at its targets."""
    stops = data["stops"]
    x, y = to_map.transform([s["lon_deg"] for s in stops], [s["lat_deg"] for s in stops])
    x, y = np.atleast_1d(x), np.atleast_1d(y)
    eyes = eye_heights_m(plan)
    ground = plan.terrain.sample(x, y)
    gsd = photo_gsd_cm(plan)
    names = [t.name for t in plan.targets.targets]
    above, resolution = [], []
    for stop, g in zip(stops, ground.tolist(), strict=True):
        k = stop["order"] - 1
        above.append(round(float(eyes[k]) - g, 1) if math.isfinite(g) else math.nan)
        resolution.append(
            ""
            if gsd is None
            else ", ".join(f"{names[t]} {cm:.2f} cm/px" for t, cm in gsd[k].items())
        )
    return {
        "x": x.tolist(),
        "y": y.tolist(),
        "order": [s["order"] for s in stops],
        "number": [str(s["order"]) for s in stops],
        "sortie": [s["sortie"] for s in stops],
        "sees": [", ".join(s["sees"]) for s in stops],
        "eta": [f"{s['eta_s'] / 60:.1f} min ({s['eta_s']:.0f} s) from take-off" for s in stops],
        "above_ground_m": above,
        "gsd": resolution,
    }


_Layers: TypeAlias = "dict[str, list[GlyphRenderer[Any]]]"


def _draw_plan(
    fig: figure, plan: Plan, data: dict[str, Any], prefix: str, vehicle: str | None
) -> _Layers:
    """Draw one plan's layers on the map; return them by legend label, in legend order.

    Names are ``prefix`` + the layer's name; ``vehicle``, a fleet vehicle's colour, colours
    everything of the plan (otherwise each target and its region has its colour and each
    sortie its own).
    """
    to_map = map_transformer(plan.crs)
    palette = [vehicle] * len(plan.targets_xy) if vehicle else target_colours(len(plan.targets_xy))
    layers: _Layers = {}
    shown = [r for r in plan.regions if not r.polygon.is_empty]
    if shown:
        regions = ColumnDataSource(
            {
                "xs": [list(r.polygon.exterior.xy[0]) for r in shown],
                "ys": [list(r.polygon.exterior.xy[1]) for r in shown],
                "colour": [palette[r.target] for r in shown],
            }
        )
        layers["visibility regions"] = [
            fig.patches(
                "xs",
                "ys",
                source=regions,
                fill_color="colour",
                line_color="colour",
                fill_alpha=0.18,
                line_width=1.2,
                name=f"{prefix}regions",
            )
        ]
    fence = geofence_xy(plan, to_map)
    ring = np.vstack([fence, fence[:1]])
    layers["geofence"] = [
        fig.line(
            ring[:, 0],
            ring[:, 1],
            line_color=vehicle or FENCE_COLOUR,
            line_dash="dashed",
            line_width=1.5,
            name=f"{prefix}geofence",
        )
    ]
    frames = frame_footprints(plan)
    if frames:
        layers["photo frames"] = [
            fig.patches(
                xs=[f[:, 0].tolist() for f in frames],
                ys=[f[:, 1].tolist() for f in frames],
                fill_alpha=0.0,
                line_color="black",
                line_dash="dotted",
                name=f"{prefix}frames",
            )
        ]
    layers |= _draw_routes(fig, plan, to_map, prefix, vehicle)
    layers["stops"] = _draw_stops(fig, plan, data, to_map, prefix, vehicle)
    layers["targets"] = _draw_targets(fig, plan, palette, prefix)
    hx, hy = plan.home_xy
    layers["home"] = [
        fig.scatter(
            [hx],
            [hy],
            marker="star",
            size=24,
            fill_color=vehicle or "white",
            line_color="black",
            line_width=1.5,
            name=f"{prefix}home",
        )
    ]
    return layers


def _draw_routes(
    fig: figure, plan: Plan, to_map: pyproj.Transformer, prefix: str, vehicle: str | None
) -> _Layers:
    """Each sortie's route as flown (``sortie-N``, on a black casing ``sortie-N-casing``)
    and, in a band, the waypoints without a photo that follow the terrain (``waypoints``)."""
    layers: _Layers = {}
    many = len(plan.sorties) > 1
    for number, (route, sortie) in enumerate(
        zip(sortie_routes(plan, to_map), plan.sorties, strict=True), start=1
    ):
        label = (
            f"sortie {number}: {sortie.stop - sortie.first} stops, {sortie.length_m:.0f} m, "
            f"{sortie.flight_time_s / 60:.1f} min"
            if many
            else "tour"
        )
        x, y = route[:, 0], route[:, 1]
        layers[label] = [
            fig.line(
                x, y, line_color="black", line_width=4.0, name=f"{prefix}sortie-{number}-casing"
            ),
            fig.line(
                x,
                y,
                line_color=vehicle or sortie_colour(number),
                line_width=2.2,
                name=f"{prefix}sortie-{number}",
            ),
        ]
    band = plan.band_flight
    if band is None:
        return layers
    dots = [
        (float(p[0]), float(p[1]), vehicle or sortie_colour(n))
        for n, (path, stop_of) in enumerate(
            zip(band.paths_xyz, band.path_stop, strict=True), start=1
        )
        for p in path[stop_of == -1]
    ]
    if dots:
        wx, wy, colours = (list(v) for v in zip(*dots, strict=True))
        layers["waypoints without a photo"] = [
            fig.scatter(
                wx, wy, size=5, fill_color=colours, line_color="black", name=f"{prefix}waypoints"
            )
        ]
    return layers


def _draw_stops(
    fig: figure,
    plan: Plan,
    data: dict[str, Any],
    to_map: pyproj.Transformer,
    prefix: str,
    vehicle: str | None,
) -> list[GlyphRenderer[Any]]:
    """The stops (``stops``), each with its order number (``stop-numbers``) and a tooltip;
    in its sortie's colour, or in a band coloured by its height above the surface."""
    rows = _stop_rows(plan, data, to_map)
    rows["colour"] = [vehicle or sortie_colour(n) for n in rows["sortie"]]
    source = ColumnDataSource(rows)
    band = plan.band_flight
    fill: str | Field = "colour"
    if band is not None:
        fill = linear_cmap("above_ground_m", Viridis256, band.band.floor_m, band.band.ceiling_m)
    stops = fig.scatter(
        "x",
        "y",
        source=source,
        size=16,
        fill_color=fill,
        line_color="black" if band is None else "colour",
        line_width=2.0,
        name=f"{prefix}stops",
    )
    # A band's stop is coloured by its height: its number goes beside it, on its sortie's
    # colour.
    numbers = fig.text(
        "x",
        "y",
        text="number",
        source=source,
        text_align="center" if band is None else "left",
        text_baseline="middle" if band is None else "bottom",
        x_offset=0 if band is None else 8,
        y_offset=0 if band is None else -8,
        text_font_size="8pt",
        text_font_style="bold",
        background_fill_color=None if band is None else "colour",
        name=f"{prefix}stop-numbers",
    )
    tooltips = [
        ("stop", "@order (sortie @sortie)"),
        ("sees", "@sees"),
        ("ETA", "@eta"),
        ("above ground", "@above_ground_m{0.0} m"),
    ]
    if plan.camera.frame is not None:
        tooltips.append(("GSD", "@gsd"))
    fig.add_tools(HoverTool(renderers=[stops], tooltips=tooltips))
    return [stops, numbers]


def _draw_targets(
    fig: figure, plan: Plan, palette: list[str], prefix: str
) -> list[GlyphRenderer[Any]]:
    """The targets (``targets``) and their names beside them (``target-names``)."""
    source = ColumnDataSource(
        {
            "x": plan.targets_xy[:, 0].tolist(),
            "y": plan.targets_xy[:, 1].tolist(),
            "name": [t.name for t in plan.targets.targets],
            "colour": palette,
        }
    )
    targets = fig.scatter(
        "x",
        "y",
        source=source,
        marker="triangle",
        size=13,
        fill_color="colour",
        line_color="black",
        name=f"{prefix}targets",
    )
    names = fig.text(
        "x",
        "y",
        text="name",
        source=source,
        x_offset=7,
        y_offset=-7,
        text_font_size="8pt",
        text_baseline="bottom",
        background_fill_color="white",
        background_fill_alpha=0.7,
        name=f"{prefix}target-names",
    )
    fig.add_tools(HoverTool(renderers=[targets], tooltips=[("target", "@name")]))
    return [targets, names]


def _legend(fig: figure, layers: _Layers) -> None:
    """A legend beside the figure whose entries show or hide their layers when clicked."""
    items = [LegendItem(label=label, renderers=r) for label, r in layers.items()]
    fig.add_layout(Legend(items=items, click_policy="hide", title="click to show or hide"), "right")


def _profile_figure(plan: Plan) -> figure:
    """Per sortie, the surface along its route, the band over it and the height flown
    (``profile-N``), its stops (``profile-stops-N``); the first sortie shown, the others a
    click away in the legend."""
    flight = plan.band_flight
    assert flight is not None
    floor, ceiling = flight.band.floor_m, flight.band.ceiling_m
    home_ground = plan.mission.home.amsl_m
    fig = figure(
        frame_width=_MAP_WIDTH_PX,
        frame_height=_PROFILE_HEIGHT_PX,
        tools=_PROFILE_TOOLS,
        active_scroll="wheel_zoom",
        title="profile along each sortie's route: the surface, the band over it and the "
        "height flown",
        x_axis_label="horizontal distance from home (m)",
        y_axis_label="height (m, DEM datum)",
        name="profiles",
    )
    fig.toolbar.logo = None
    layers: _Layers = {}
    hover: list[DataRenderer] = []
    for k in range(len(plan.missions)):
        number = k + 1
        colour = sortie_colour(number)
        profile = path_profile(plan, k)
        at, surface = profile["at_m"], profile["surface_m"]
        distance, z, stop = profile["distance_m"], profile["z_m"], profile["stop"]
        base = float(np.nanmin(surface)) - 0.05 * ceiling
        drawn: list[GlyphRenderer[Any]] = [
            fig.varea(
                at,
                y1=base,
                y2=surface,
                fill_color=GROUND_COLOUR,
                fill_alpha=0.5,
                name=f"ground-{number}",
            ),
            fig.varea(
                at,
                y1=surface + floor,
                y2=surface + ceiling,
                fill_color=BAND_COLOUR,
                fill_alpha=0.25,
                name=f"band-{number}",
            ),
            fig.line(
                at, surface, line_color=SURFACE_COLOUR, line_width=1.2, name=f"surface-{number}"
            ),
            # The climb from home and the landing back on it.
            fig.segment(
                x0=[0.0, float(distance[-1])],
                y0=[home_ground, float(z[-1])],
                x1=[0.0, float(distance[-1])],
                y1=[float(z[0]), home_ground],
                line_color="black",
                line_dash="dotted",
                name=f"climb-{number}",
            ),
            fig.line(distance, z, line_color="black", line_width=3.6, name=f"casing-{number}"),
            fig.line(distance, z, line_color=colour, line_width=2.0, name=f"profile-{number}"),
        ]
        at_stop = stop >= 0
        ground = np.interp(distance[at_stop], at, surface)
        stops = fig.scatter(
            "distance",
            "z",
            source=ColumnDataSource(
                {
                    "distance": distance[at_stop].tolist(),
                    "z": z[at_stop].tolist(),
                    "order": (stop[at_stop] + 1).tolist(),
                    "above_ground_m": (z[at_stop] - ground).tolist(),
                }
            ),
            size=9,
            fill_color="white",
            line_color="black",
            name=f"profile-stops-{number}",
        )
        hover.append(stops)
        drawn.append(stops)
        for renderer in drawn:
            renderer.visible = k == 0
        layers[f"sortie {number}"] = drawn
    fig.add_tools(
        HoverTool(
            renderers=hover,
            tooltips=[
                ("stop", "@order"),
                ("height", "@z{0.0} m"),
                ("above the surface", "@above_ground_m{0.0} m"),
                ("from home", "@distance{0} m"),
            ],
        )
    )
    _legend(fig, layers)
    return fig


def render_map_page(plan: Plan, data: dict[str, Any]) -> str:
    """``map.html``: the plan as one self-contained page.

    Parameters
    ----------
    plan
        The plan.
    data
        Its summary (:func:`~urpt_gcs.files.report.summary`): the title's figures and every
        stop's ETA come from it.

    Returns
    -------
    str
        The page, with Bokeh's JavaScript and the DSM inline.
    """
    to_map = map_transformer(plan.crs)
    lo, hi = view_bounds(
        [
            *sortie_routes(plan, to_map),
            plan.targets_xy,
            geofence_xy(plan, to_map),
            *region_rings(plan),
        ]
    )
    fig, dsm = _map_figure(plan.terrain, plan.crs.name, lo, hi)
    _titled(fig, map_title(data))
    layers = {"DSM": [dsm]}
    layers |= _draw_plan(fig, plan, data, "", None)
    _legend(fig, layers)
    if plan.band_flight is None:
        return _page(fig)
    return _page(column(fig, _profile_figure(plan)))


def render_fleet_page(
    plans: Sequence[Plan | None], summaries: Sequence[dict[str, Any] | None], title: str
) -> str:
    """The top ``map.html`` of a fleet: every vehicle's regions, targets, routes, stops,
    home and geofence in its own colour over the DSM of the widest window; one legend entry
    per vehicle shows or hides all of it. None, a vehicle left idle, is not drawn.

    Parameters
    ----------
    plans
        Each vehicle's plan, None for one left idle.
    summaries
        Each vehicle's summary (as in its ``summary.json``), None for one left idle.
    title
        The page's title, one or more lines.
    """
    widest = widest_plan(plans)
    to_map = map_transformer(widest.crs)
    shapes = [
        shape
        for plan in plans
        if plan is not None
        for shape in [*sortie_routes(plan, to_map), plan.targets_xy, *region_rings(plan)]
    ]
    lo, hi = view_bounds(shapes)
    fig, dsm = _map_figure(widest.terrain, widest.crs.name, lo, hi)
    _titled(fig, title)
    layers = {"DSM": [dsm]}
    for number, (plan, data) in enumerate(zip(plans, summaries, strict=True), start=1):
        if plan is None or data is None:
            continue
        drawn = _draw_plan(fig, plan, data, f"vehicle-{number}-", sortie_colour(number))
        layers[vehicle_label(number, plan)] = [r for group in drawn.values() for r in group]
    _legend(fig, layers)
    return _page(fig)


def _page(root: Model) -> str:
    html: str = file_html(root, resources=INLINE, title=PAGE_TITLE)
    return html
