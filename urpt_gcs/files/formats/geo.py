"""The plan for Google Earth (KML) and GIS tools (GeoJSON).

Both hold the same things: every target's visibility region as a polygon, each target, home,
and each sortie as flown: its route from home through its stops and back home, at the flight
plane's altitude (in the DEM's vertical datum, which Google Earth takes as height above mean
sea level), and its stops with their order numbers, what each sees and when the copter gets
there. Routes and stops are the missions' written waypoints
(:func:`urpt_gcs.files.report.flown_stops`), so they are what the vehicle flies.
Coordinates are WGS84 longitude/latitude and altitude: routes and stops at their absolute
altitude (KML ``absolute``, GeoJSON's third coordinate), so they stand in 3-D.

A plan inside a height band (``--agl``) has no plane and no regions: each route runs over
home at the take-off height, through every waypoint of its mission (the stops and the
waypoints without a photo that follow the terrain) at its own altitude, and back over home;
its stops carry ``height_amsl_m``, ``height_above_home_m`` and ``height_above_surface_m``
too, and its sorties ``waypoints`` (how many points the route has).

Every GeoJSON feature has a ``kind`` property (``region``, ``target``, ``home``, ``stop``,
``sortie``); stops carry ``order``, ``sortie``, ``sees`` (target names) and ``eta_s`` (from
arming), sorties ``sortie``, ``stops``, ``length_m``, ``flight_time_s`` and ``colour``. In
KML each kind has its style, and each sortie a colour of its own shared by its route and its
stops; a stop's ``ExtendedData`` holds the same fields as in GeoJSON.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pyproj
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.arrays import FloatArray, IntArray
from urpt_gcs.files.band_report import band_stops
from urpt_gcs.files.report import flown_stops, sortie_colour
from urpt_gcs.flight.mission import Mission
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.site.dem import WGS84

KML_NS = "http://www.opengis.net/kml/2.2"
_NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
# Google Earth's stock icons, so the file needs nothing beside it.
_ICONS = {
    "target": "http://maps.google.com/mapfiles/kml/shapes/triangle.png",
    "home": "http://maps.google.com/mapfiles/kml/shapes/homegardenbusiness.png",
    "stop": "http://maps.google.com/mapfiles/kml/shapes/placemark_circle.png",
}
_TARGET_COLOUR = "#d62728"
_REGION_COLOUR = "#1f77b4"


@dataclass(frozen=True, slots=True)
class _Feature:
    name: str
    kind: str  # region | target | home | stop | sortie
    description: str
    coords: list[tuple[float, float, float]]  # lon, lat, alt
    sortie: int | None = None
    properties: dict[str, Any] = field(default_factory=dict)


def _features(plan: Plan) -> list[_Feature]:
    to_geo = pyproj.Transformer.from_crs(plan.crs, WGS84, always_xy=True)

    def lonlat(xy: FloatArray) -> list[tuple[float, float]]:
        lon, lat = to_geo.transform(xy[:, 0], xy[:, 1])
        return list(zip(np.atleast_1d(lon).tolist(), np.atleast_1d(lat).tolist(), strict=True))

    altitude = plan.camera.altitude_m
    names = [t.name for t in plan.targets.targets]
    out = []
    # A band plan has no regions (no plane to draw them on).
    for region, name in zip(plan.regions, names if plan.regions else [], strict=True):
        if region.polygon.is_empty:
            continue
        ring = lonlat(np.asarray(region.polygon.exterior.coords))
        out.append(
            _Feature(
                f"region {name}",
                "region",
                f"where {name} is seen from {altitude:.1f} m",
                [(x, y, 0.0) for x, y in ring],
                properties={"target": name},
            )
        )
    for t, ground in zip(plan.targets.targets, plan.ground_m, strict=True):
        out.append(
            _Feature(
                t.name,
                "target",
                f"ground {ground:.2f} m",
                [(t.lon_deg, t.lat_deg, float(ground))],
                properties={"ground_m": round(float(ground), 2)},
            )
        )
    home = plan.mission.home
    out.append(
        _Feature(
            "Home",
            "home",
            f"take-off ({plan.home_source}), ground {home.amsl_m:.2f} m",
            [(home.lon_deg, home.lat_deg, home.amsl_m)],
        )
    )
    stops = flown_stops(plan)
    band = plan.band_flight
    heights = band_stops(plan) if band is not None else None
    for number, (sortie, mission) in enumerate(zip(plan.sorties, plan.missions, strict=True), 1):
        mine = [s for s in stops if s.sortie == number]
        properties: dict[str, Any] = {
            "sortie": number,
            "stops": len(mine),
            "length_m": round(sortie.length_m, 2),
            "flight_time_s": round(sortie.flight_time_s, 1),
            "colour": sortie_colour(number),
        }
        if band is None:
            start = (mission.home.lon_deg, mission.home.lat_deg, altitude)
            route = [start, *((s.lon_deg, s.lat_deg, altitude) for s in mine), start]
            words = f"{sortie.length_m:.1f} m at {altitude:.1f} m"
            stop_alt = [altitude] * len(mine)
        else:
            route = _band_route(mission)
            properties["waypoints"] = len(route)
            inserted = len(route) - 2 - len(mine)
            words = (
                f"{sortie.length_m:.1f} m horizontally in the band {band.band.describe()} "
                f"above the surface, {inserted} waypoints without a photo"
            )
            stop_alt = [route[i][2] for i in _photo_points(band.path_stop[number - 1])]
        out.append(
            _Feature(
                f"sortie {number}",
                "sortie",
                f"{len(mine)} stops, {words}, "
                f"{sortie.flight_time_s / 60:.1f} min from home and back",
                route,
                sortie=number,
                properties=properties,
            )
        )
        for stop, alt in zip(mine, stop_alt, strict=True):
            extra: dict[str, Any] = {}
            where = ""
            if heights is not None:
                b = heights[stop.order - 1]
                surface = b.above_surface_m if np.isfinite(b.above_surface_m) else None
                extra = {
                    "height_amsl_m": b.amsl_m,
                    "height_above_home_m": b.above_home_m,
                    "height_above_surface_m": surface,
                }
                where = f", {b.amsl_m:.1f} m AMSL" + (
                    "" if surface is None else f", {surface:.1f} m above the surface"
                )
            out.append(
                _Feature(
                    str(stop.order),
                    "stop",
                    f"sortie {number}, stop {stop.order}: photo of {', '.join(stop.sees)} "
                    f"at {stop.eta_s:.0f} s{where}",
                    [(stop.lon_deg, stop.lat_deg, alt)],
                    sortie=number,
                    properties={
                        "order": stop.order,
                        "sortie": number,
                        "sees": list(stop.sees),
                        "eta_s": stop.eta_s,
                        **extra,
                    },
                )
            )
    return out


def _band_route(mission: Mission) -> list[tuple[float, float, float]]:
    """A band sortie as its mission flies it: over home at the take-off height, then every
    NAV_WAYPOINT at home's altitude plus its own height above home."""
    home = mission.home
    route = [(home.lon_deg, home.lat_deg, round(home.amsl_m + mission.altitude_rel_m, 2))]
    route += [
        (item.params[5], item.params[4], round(home.amsl_m + item.params[6], 2))
        for item in mission.items
        if item.command == _NAV_WAYPOINT
    ]
    return route


def _photo_points(path_stop: IntArray) -> list[int]:
    """The indices along a band path of its stops."""
    return [int(i) for i in np.flatnonzero(path_stop >= 0)]


def _coords(points: list[tuple[float, float, float]]) -> str:
    return " ".join(f"{x:.9f},{y:.9f},{z:.2f}" for x, y, z in points)


def _kml_colour(rgb: str, alpha: int) -> str:
    """``#rrggbb`` as KML's ``aabbggrr``."""
    r, g, b = rgb[1:3], rgb[3:5], rgb[5:7]
    return f"{alpha:02x}{b}{g}{r}"


def _style(doc: ET.Element, q: str, style_id: str, **parts: dict[str, str]) -> None:
    style = ET.SubElement(doc, f"{q}Style", id=style_id)
    for part, fields in parts.items():
        element = ET.SubElement(style, f"{q}{part}")
        for key, value in fields.items():
            if key == "href":
                ET.SubElement(ET.SubElement(element, f"{q}Icon"), f"{q}href").text = value
            else:
                ET.SubElement(element, f"{q}{key}").text = value


def _styles(doc: ET.Element, q: str, sorties: int) -> None:
    _style(
        doc,
        q,
        "target",
        IconStyle={
            "color": _kml_colour(_TARGET_COLOUR, 255),
            "scale": "0.9",
            "href": _ICONS["target"],
        },
        LabelStyle={"scale": "0.8"},
    )
    _style(doc, q, "home", IconStyle={"scale": "1.3", "href": _ICONS["home"]})
    _style(
        doc,
        q,
        "region",
        LineStyle={"color": _kml_colour(_REGION_COLOUR, 200), "width": "1.5"},
        PolyStyle={"color": _kml_colour(_REGION_COLOUR, 60)},
    )
    for number in range(1, sorties + 1):
        colour = sortie_colour(number)
        _style(
            doc,
            q,
            f"sortie-{number}",
            IconStyle={"color": _kml_colour(colour, 255), "href": _ICONS["stop"]},
            LabelStyle={"color": _kml_colour(colour, 255)},
            LineStyle={"color": _kml_colour(colour, 255), "width": "3"},
        )


def plan_kml(plan: Plan) -> str:
    """The plan as a KML document: folders of regions, targets and home, and one folder per
    sortie with its route and its numbered stops; a style per kind and per sortie."""
    return _kml(_features(plan), len(plan.sorties), "Sortie")


def _fleet_features(plans: Sequence[Plan | None]) -> list[_Feature]:
    """Every vehicle's features, its routes and stops in the vehicle's colour (``sortie`` is
    the vehicle's number here) and every feature's properties naming its vehicle; a vehicle
    left idle (None) has none."""
    out = []
    for number, plan in enumerate(plans, start=1):
        if plan is None:
            continue
        for f in _features(plan):
            grouped = f.sortie is not None
            properties = {**f.properties, "vehicle": number}
            if f.kind == "sortie":
                properties["colour"] = sortie_colour(number)
            name = f.name if f.kind in ("region", "target") else f"vehicle {number} {f.name}"
            out.append(
                replace(
                    f,
                    name=name,
                    sortie=number if grouped else None,
                    properties=properties,
                )
            )
    return out


def fleet_kml(plans: Sequence[Plan | None]) -> str:
    """A fleet's plans as one KML document: a folder and a colour per vehicle (None: a
    vehicle left idle, drawn nowhere)."""
    return _kml(_fleet_features(plans), len(plans), "Vehicle")


def fleet_geojson(plans: Sequence[Plan | None]) -> str:
    """A fleet's plans as one GeoJSON FeatureCollection; every feature has a ``vehicle``."""
    return _geojson(_fleet_features(plans))


def _kml(features: list[_Feature], groups: int, group_word: str) -> str:
    ET.register_namespace("", KML_NS)
    q = f"{{{KML_NS}}}"
    kml = ET.Element(f"{q}kml")
    doc = ET.SubElement(kml, f"{q}Document")
    ET.SubElement(doc, f"{q}name").text = "urpt-gcs plan"
    _styles(doc, q, groups)
    folders: dict[str, ET.Element] = {}

    def folder(key: str, name: str) -> ET.Element:
        if key not in folders:
            folders[key] = ET.SubElement(doc, f"{q}Folder")
            ET.SubElement(folders[key], f"{q}name").text = name
        return folders[key]

    if any(f.kind == "region" for f in features):
        folder("region", "Visibility regions")
    folder("target", "Targets")
    folder("home", "Home")
    for f in features:
        if f.sortie is None:
            parent, style = folders[f.kind], f.kind
        else:
            key = f"{group_word} {f.sortie}"
            parent, style = folder(key.lower(), key), f"sortie-{f.sortie}"
        mark = ET.SubElement(parent, f"{q}Placemark")
        ET.SubElement(mark, f"{q}name").text = f.name
        ET.SubElement(mark, f"{q}description").text = f.description
        ET.SubElement(mark, f"{q}styleUrl").text = f"#{style}"
        if f.kind == "stop":
            extended = ET.SubElement(mark, f"{q}ExtendedData")
            for key, value in f.properties.items():
                data = ET.SubElement(extended, f"{q}Data", name=key)
                text = ", ".join(value) if isinstance(value, list) else str(value)
                ET.SubElement(data, f"{q}value").text = text
        if f.kind == "region":
            poly = ET.SubElement(mark, f"{q}Polygon")
            ET.SubElement(poly, f"{q}altitudeMode").text = "clampToGround"
            ring = ET.SubElement(ET.SubElement(poly, f"{q}outerBoundaryIs"), f"{q}LinearRing")
            ET.SubElement(ring, f"{q}coordinates").text = _coords(f.coords)
        elif f.kind == "sortie":
            line = ET.SubElement(mark, f"{q}LineString")
            ET.SubElement(line, f"{q}altitudeMode").text = "absolute"
            ET.SubElement(line, f"{q}coordinates").text = _coords(f.coords)
        else:
            point = ET.SubElement(mark, f"{q}Point")
            mode = "absolute" if f.kind == "stop" else "clampToGround"
            ET.SubElement(point, f"{q}altitudeMode").text = mode
            ET.SubElement(point, f"{q}coordinates").text = _coords(f.coords)
    ET.indent(kml)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(kml, encoding="unicode")


def plan_geojson(plan: Plan) -> str:
    """The plan as a GeoJSON FeatureCollection (see the module docstring for properties)."""
    return _geojson(_features(plan))


def _geojson(plan_features: list[_Feature]) -> str:
    features: list[dict[str, Any]] = []
    for f in plan_features:
        if f.kind == "region":
            geometry: dict[str, Any] = {
                "type": "Polygon",
                "coordinates": [[[x, y] for x, y, _ in f.coords]],
            }
        elif f.kind == "sortie":
            geometry = {"type": "LineString", "coordinates": [list(c) for c in f.coords]}
        else:
            geometry = {"type": "Point", "coordinates": list(f.coords[0])}
        features.append(
            {
                "type": "Feature",
                "geometry": geometry,
                "properties": {
                    "name": f.name,
                    "kind": f.kind,
                    "description": f.description,
                    **f.properties,
                },
            }
        )
    return json.dumps({"type": "FeatureCollection", "features": features}, indent=1) + "\n"


__all__ = [
    "KML_NS",
    "fleet_geojson",
    "fleet_kml",
    "plan_geojson",
    "plan_kml",
]
