"""The plan for Google Earth (KML) and GIS tools (GeoJSON).

Both hold the same things: every target's visibility region as a polygon, the tour as a line
at its real altitude (the flight plane, in the DEM's vertical datum, which Google Earth takes
as height above mean sea level), each viewpoint with the targets it sees, each target, and
home. Coordinates are WGS84 longitude/latitude.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyproj

from urpt_gcs.planner import Plan
from urpt_gcs.terrain import WGS84, FloatArray

KML_NS = "http://www.opengis.net/kml/2.2"


@dataclass(frozen=True, slots=True)
class _Feature:
    name: str
    kind: str  # target | home | viewpoint | region | tour
    description: str
    coords: list[tuple[float, float, float]]  # lon, lat, alt


def _features(plan: Plan) -> list[_Feature]:
    to_geo = pyproj.Transformer.from_crs(plan.crs, WGS84, always_xy=True)

    def lonlat(xy: FloatArray) -> list[tuple[float, float]]:
        lon, lat = to_geo.transform(xy[:, 0], xy[:, 1])
        return list(zip(np.atleast_1d(lon).tolist(), np.atleast_1d(lat).tolist(), strict=True))

    altitude = plan.camera.altitude_m
    names = [t.name for t in plan.targets.targets]
    out = []
    for region, name in zip(plan.regions, names, strict=True):
        if region.polygon.is_empty:
            continue
        ring = lonlat(np.asarray(region.polygon.exterior.coords))
        out.append(
            _Feature(
                f"region {name}",
                "region",
                f"where {name} is seen from {altitude:.1f} m",
                [(x, y, 0.0) for x, y in ring],
            )
        )
    for t, ground in zip(plan.targets.targets, plan.ground_m, strict=True):
        out.append(
            _Feature(
                t.name, "target", f"ground {ground:.2f} m", [(t.lon_deg, t.lat_deg, float(ground))]
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
    stops = plan.tour.points_xy
    assert stops is not None
    stop_ll = lonlat(stops)
    for k, ((x, y), sees) in enumerate(zip(stop_ll, plan.tour.sees, strict=True), start=1):
        seen = ", ".join(names[t] for t in np.flatnonzero(sees).tolist())
        out.append(_Feature(f"{k}", "viewpoint", f"photo of {seen}", [(x, y, altitude)]))
    path = [
        (home.lon_deg, home.lat_deg, altitude),
        *[(x, y, altitude) for x, y in stop_ll],
        (home.lon_deg, home.lat_deg, altitude),
    ]
    out.append(_Feature("tour", "tour", f"{plan.tour.length:.1f} m at {altitude:.1f} m", path))
    return out


def _coords(points: list[tuple[float, float, float]]) -> str:
    return " ".join(f"{x:.9f},{y:.9f},{z:.2f}" for x, y, z in points)


def plan_kml(plan: Plan) -> str:
    """The plan as a KML document (folders: regions, targets, viewpoints, tour)."""
    ET.register_namespace("", KML_NS)
    q = f"{{{KML_NS}}}"
    kml = ET.Element(f"{q}kml")
    doc = ET.SubElement(kml, f"{q}Document")
    ET.SubElement(doc, f"{q}name").text = "urpt-gcs plan"
    folders = {
        kind: ET.SubElement(doc, f"{q}Folder")
        for kind in ("region", "target", "home", "viewpoint", "tour")
    }
    for kind, folder in folders.items():
        ET.SubElement(folder, f"{q}name").text = {
            "region": "Visibility regions",
            "target": "Targets",
            "home": "Home",
            "viewpoint": "Viewpoints",
            "tour": "Tour",
        }[kind]
    for f in _features(plan):
        mark = ET.SubElement(folders[f.kind], f"{q}Placemark")
        ET.SubElement(mark, f"{q}name").text = f.name
        ET.SubElement(mark, f"{q}description").text = f.description
        if f.kind == "region":
            poly = ET.SubElement(mark, f"{q}Polygon")
            ET.SubElement(poly, f"{q}altitudeMode").text = "clampToGround"
            ring = ET.SubElement(ET.SubElement(poly, f"{q}outerBoundaryIs"), f"{q}LinearRing")
            ET.SubElement(ring, f"{q}coordinates").text = _coords(f.coords)
        elif f.kind == "tour":
            line = ET.SubElement(mark, f"{q}LineString")
            ET.SubElement(line, f"{q}altitudeMode").text = "absolute"
            ET.SubElement(line, f"{q}coordinates").text = _coords(f.coords)
        else:
            point = ET.SubElement(mark, f"{q}Point")
            mode = "absolute" if f.kind == "viewpoint" else "clampToGround"
            ET.SubElement(point, f"{q}altitudeMode").text = mode
            ET.SubElement(point, f"{q}coordinates").text = _coords(f.coords)
    ET.indent(kml)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(kml, encoding="unicode")


def plan_geojson(plan: Plan) -> str:
    """The plan as a GeoJSON FeatureCollection (``kind`` property on every feature)."""
    features: list[dict[str, Any]] = []
    for f in _features(plan):
        if f.kind == "region":
            geometry: dict[str, Any] = {
                "type": "Polygon",
                "coordinates": [[[x, y] for x, y, _ in f.coords]],
            }
        elif f.kind == "tour":
            geometry = {"type": "LineString", "coordinates": [list(c) for c in f.coords]}
        else:
            geometry = {"type": "Point", "coordinates": list(f.coords[0])}
        features.append(
            {
                "type": "Feature",
                "geometry": geometry,
                "properties": {"name": f.name, "kind": f.kind, "description": f.description},
            }
        )
    return json.dumps({"type": "FeatureCollection", "features": features}, indent=1) + "\n"
