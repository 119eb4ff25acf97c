"""Targets: the points to photograph, read from KML/KMZ, GeoJSON or CSV.

One small reader per format turns the bytes into raw points; :func:`_check` then validates them
(positions and names alike, whatever the format), takes out the home point and names unnamed
targets. Every problem is a one-line TargetsError.

Names are data: they reach the map, the KML and the GeoJSON as the file writes them (a tab
read as a space, blanks around trimmed), so a name no output can hold is refused here, with
the target's position in the file, rather than mangled on the way out.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import math
import re
import unicodedata
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, ParseError

import defusedxml.ElementTree as safe_et
import pyproj
from defusedxml import DefusedXmlException

from urpt_gcs.errors import TargetsError
from urpt_gcs.site.inputs import TARGETS_MAX_BYTES, read_capped

__all__ = [
    "HOME_NAMES",
    "SAME_PLACE_DEG",
    "SWAP_FIX",
    "Target",
    "TargetSet",
    "check_names",
    "read_targets",
]


@dataclass(frozen=True, slots=True)
class Target:
    """A named point on the ground, WGS84 degrees."""

    name: str
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True, slots=True)
class TargetSet:
    """The targets of one file and the take-off point it names, if any."""

    targets: tuple[Target, ...]
    home: Target | None
    source: str


# Two targets closer than this (in both latitude and longitude) are the same place, ~1 cm.
SAME_PLACE_DEG = 1e-7
HOME_NAMES = frozenset({"home", "launch"})
# A KMZ member is decompressed at most this far, so a zip bomb cannot exhaust memory.
_KMZ_MEMBER_LIMIT_BYTES = 64 * 1024 * 1024
_KML_FIX = "fix the file or export it again from Google Earth"
_WGS84 = pyproj.CRS.from_epsg(4326)
_CSV_COLUMNS = {"name": ("name",), "lat": ("lat", "latitude"), "lon": ("lon", "lng", "longitude")}
# What a damaged, encrypted or oddly compressed zip can raise.
_ZIP_ERRORS: tuple[type[Exception], ...] = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error)
_ZIP_ERRORS += (EOFError, OSError, RuntimeError, ValueError)


@dataclass(frozen=True, slots=True)
class _Point:
    """A point as read from the file, before home and default names are settled."""

    name: str | None  # as the file gives it; a multi-point placemark's for each of its points
    where: str  # where the operator finds it in the file: "placemark 3", "row 4", ...
    is_home: bool
    lat_deg: float
    lon_deg: float
    part: int = 0  # k for the k-th point of a multi-point placemark or feature, else 0

    def place(self) -> str:
        return f"{self.where}, point {self.part}" if self.part else self.where

    def label(self) -> str:
        return f"{'point ' + _q(self.name) if self.name else 'unnamed point'} ({self.place()})"


def _q(text: str, limit: int = 60) -> str:
    """Quote text from the file for a message: one line, bounded length."""
    shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return f"'{shown[:limit]}...'" if len(shown) > limit else f"'{shown}'"


def _error(source: str, problem: str, fix: str) -> TargetsError:
    return TargetsError(f"targets file {_q(source, 200)} {problem}: {fix}")


def _points(name: str | None, where: str, lon_lats: list[tuple[float, float]]) -> list[_Point]:
    """Raw points of one placemark/feature; a multi-point one gets its points numbered."""
    # Only blanks are trimmed (str.strip would also cut control characters, unseen).
    name = (name.replace("\t", " ").strip(" \r\n") if name else "") or None
    is_home = name is not None and name.casefold() in HOME_NAMES
    if len(lon_lats) == 1:
        return [_Point(name, where, is_home, lon_lats[0][1], lon_lats[0][0])]
    return [
        _Point(name, where, is_home, lat, lon, part=k)
        for k, (lon, lat) in enumerate(lon_lats, start=1)
    ]


# What no output can hold: control characters (C0 but the tab, DEL, C1; XML 1.0 forbids most
# and the rest are invisible), surrogates (a lone one cannot even be written as UTF-8),
# noncharacters (U+FDD0..U+FDEF and the last two code points of every plane), and the
# invisible marks that turn the text's direction (U+202A..U+202E, U+2066..U+2069): a name
# holding one shows in a map or a list as another name.
_UNFIT = re.compile(
    "[\x00-\x1f\x7f-\x9f\ud800-\udfff\ufdd0-\ufdef\u202a-\u202e\u2066-\u2069"
    + "".join(chr(plane << 16 | 0xFFFE) + chr(plane << 16 | 0xFFFF) for plane in range(17))
    + "]"
)


def _name_problem(name: str) -> str | None:
    """What in ``name`` no output can hold, in the operator's words; None if nothing."""
    found = _UNFIT.search(name)
    if found is None:
        return None
    char = found.group()
    code = f"U+{ord(char):04X}"
    if unicodedata.category(char) == "Cc":
        return f"the control character {code}"
    if unicodedata.category(char) == "Cs":
        return f"a lone surrogate {code} (half of a UTF-16 pair)"
    if unicodedata.category(char) == "Cf":
        return f"the invisible text-direction mark {code}"
    return f"the noncharacter {code}"


def _decode(source: str, data: bytes, fix: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _error(source, f"is not UTF-8 text (bad byte at offset {exc.start})", fix) from exc


def _local(tag: object) -> str:
    """An element's tag without its namespace, so every KML version reads alike."""
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


# KML's geometry elements (gx:Track and gx:MultiTrack of Google's extension included).
_KML_GEOMETRIES = frozenset(
    (
        "Point",
        "LineString",
        "LinearRing",
        "Polygon",
        "MultiGeometry",
        "Model",
        "Track",
        "MultiTrack",
    )
)


def _kml_points(source: str, data: bytes) -> list[_Point]:
    try:
        root: Element = safe_et.fromstring(data, forbid_dtd=True)
    except DefusedXmlException as exc:
        problem = "declares a DTD (<!DOCTYPE>); urpt-gcs refuses XML entity declarations"
        fix = "remove the <!DOCTYPE ...> block or export the file again from Google Earth"
        raise _error(source, problem, fix) from exc
    except ParseError as exc:
        line, column = exc.position
        reason = str(exc).rsplit(": line", 1)[0]
        problem = f"is not well-formed XML ({reason}, line {line}, column {column + 1})"
        raise _error(source, problem, _KML_FIX) from exc
    except LookupError as exc:
        raise _error(source, f"has an unknown encoding ({_q(str(exc))})", _KML_FIX) from exc
    points: list[_Point] = []
    # "{*}" matches any namespace or none, so every KML version reads alike.
    itself = [root] if _local(root.tag) == "Placemark" else []
    placemarks = itertools.chain(itself, root.iterfind(".//{*}Placemark"))
    for number, placemark in enumerate(placemarks, start=1):
        name_element = placemark.find("{*}name")
        name = None if name_element is None else "".join(name_element.itertext())
        where = f"placemark {number}"
        # Points directly or in (nested) MultiGeometry; placemarks do not nest in valid KML.
        lon_lats = [_kml_lon_lat(source, where, name, e) for e in placemark.iterfind(".//{*}Point")]
        if lon_lats:
            points.extend(_points(name, where, lon_lats))
        elif not any(_local(e.tag) in _KML_GEOMETRIES for e in placemark.iter()):
            # A line or a polygon is not a target; a placemark with no place at all is a
            # target the file forgot to locate.
            shown = where if name is None else f"{where} {_q(name)}"
            problem = f"has {shown} with no geometry"
            raise _error(source, problem, "give it a Point or remove the placemark")
    if not points:
        problem = "contains no Point placemarks (lines and polygons are ignored)"
        raise _error(source, problem, "add a Placemark with a Point for each target")
    return points


def _kml_lon_lat(source: str, where: str, name: str | None, point: Element) -> tuple[float, float]:
    element = point.find("{*}coordinates")
    text = "" if element is None else "".join(element.itertext())
    # Tuples are whitespace-separated; tolerate blanks around the commas inside one.
    tuples = re.sub(r"\s*,\s*", ",", text.strip()).split()
    fields = tuples[0].split(",") if len(tuples) == 1 else []
    if len(fields) in (2, 3):
        with contextlib.suppress(ValueError):
            return float(fields[0]), float(fields[1])
    shown = f"{where} {_q(name.strip())}" if name and name.strip() else where
    problem = f"has a Point in {shown} with <coordinates> {_q(text.strip())}"
    raise _error(source, problem, "give one 'lon,lat' or 'lon,lat,alt' tuple of numbers")


def _kmz_points(source: str, data: bytes) -> list[_Point]:
    """The points of a KMZ's one KML, as Google Earth picks it (the KML 2.2 convention): the
    ``doc.kml`` at the archive's root, else the one ``.kml`` at the root, else the one
    ``.kml`` in its folders. Several candidates and no ``doc.kml`` are refused, not guessed
    between; the other ``.kml`` files beside a root ``doc.kml`` are not read."""
    fix = "export the file again as KMZ, or save it as KML"
    candidates: list[str] = []
    kml = b""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            names = [i.filename for i in archive.infolist() if not i.is_dir()]
            kml_names = [n for n in names if n.lower().endswith(".kml")]
            at_root = [n for n in kml_names if "/" not in n and "\\" not in n]
            docs = [n for n in at_root if n.lower() == "doc.kml"]
            candidates = docs or at_root or kml_names
            if len(candidates) == 1:
                with archive.open(candidates[0]) as stream:
                    kml = stream.read(_KMZ_MEMBER_LIMIT_BYTES + 1)
    except _ZIP_ERRORS as exc:
        raise _error(source, f"is not a readable KMZ (zip) archive ({_q(str(exc))})", fix) from exc
    if not candidates:
        raise _error(source, "is a KMZ archive without a .kml file inside", fix)
    if len(candidates) > 1:
        count = len(candidates)
        shown = ", ".join(_q(n) for n in candidates[:4]) + (", ..." if count > 4 else "")
        if docs:
            problem = f"holds {count} .kml files named doc.kml ({shown})"
        elif at_root:
            problem = f"holds {count} .kml files at its root ({shown}) and no doc.kml"
        else:
            problem = f"holds {count} .kml files in folders ({shown}), none at its root"
        fix = "keep one of them, or name the one to read doc.kml at the archive's root"
        raise _error(source, f"{problem} to say which to read", fix)
    member = candidates[0]
    if len(kml) > _KMZ_MEMBER_LIMIT_BYTES:
        raise _error(source, f"has a KML member {_q(member)} over 64 MiB", fix)
    return _kml_points(f"{source}!{member}", kml)


def _geojson_points(source: str, data: bytes) -> list[_Point]:
    fix = "fix the file or export it again as GeoJSON"
    try:
        doc = json.loads(_decode(source, data, fix))
    except json.JSONDecodeError as exc:
        problem = f"is not valid JSON ({exc.msg}, line {exc.lineno}, column {exc.colno})"
        raise _error(source, problem, fix) from exc
    except (ValueError, RecursionError) as exc:  # over-long integers, absurd nesting
        raise _error(source, f"is not usable JSON ({_q(str(exc))})", fix) from exc
    kind = doc.get("type") if isinstance(doc, dict) else None
    if kind == "FeatureCollection" and isinstance(doc.get("features"), list):
        features = [(f"feature {i}", f) for i, f in enumerate(doc["features"], start=1)]
    elif kind == "Feature":
        features = [("feature 1", doc)]
    elif kind in ("Point", "MultiPoint", "GeometryCollection"):
        features = [("the top-level geometry", {"geometry": doc})]
    else:
        problem = "is not GeoJSON (expected a FeatureCollection, a Feature or a geometry)"
        raise _error(source, problem, fix)
    points: list[_Point] = []
    for where, feature in features:
        if not isinstance(feature, dict):
            raise _error(source, f"has {where} that is not a JSON object", fix)
        geometry = feature.get("geometry")
        if not isinstance(geometry, dict):
            # RFC 7946 allows an unlocated feature; a target without a place cannot be flown.
            name = _geojson_name(feature)
            shown = f"{where} {_q(name)}" if name else f"{where} (unnamed)"
            if "geometry" not in feature:
                why = "the 'geometry' member is missing"
            elif geometry is None:
                why = "null"
            else:
                why = f"a JSON {_JSON_KINDS[type(geometry)]}, not a geometry object"
            problem = f"has {shown} with no geometry ({why})"
            raise _error(source, problem, "give it a Point geometry or remove the feature")
        lon_lats = _geojson_lon_lats(source, where, geometry)
        if lon_lats:
            points.extend(_points(_geojson_name(feature), where, lon_lats))
    if not points:
        problem = "contains no Point features (lines and polygons are ignored)"
        raise _error(source, problem, "add a Point feature for each target")
    crs = _geojson_crs(source, doc.get("crs"))
    return points if crs is None else _to_wgs84(source, crs, points)


_JSON_KINDS = {list: "array", str: "string", bool: "true or false", int: "number", float: "number"}


def _geojson_crs(source: str, member: Any) -> pyproj.CRS | None:
    """The CRS a GeoJSON 2008 ``crs`` member names (QGIS still writes one), or None for WGS84.

    RFC 7946 dropped the member and fixed WGS84 lon/lat; a file that has one is read in the
    CRS it names, since reading UTM metres as degrees would put every point off the globe or,
    worse, somewhere else on it.
    """
    if member is None:
        return None
    fix = "export the file again in WGS84 (EPSG:4326), as RFC 7946 GeoJSON"
    properties = member.get("properties") if isinstance(member, dict) else None
    name = properties.get("name") if isinstance(properties, dict) else None
    if member.get("type") != "name" or not isinstance(name, str):
        shown = _q(json.dumps(member), 120)
        raise _error(source, f"has a 'crs' member {shown} that does not name a CRS", fix)
    try:
        crs = pyproj.CRS.from_user_input(name)
    except pyproj.exceptions.CRSError:
        raise _error(source, f"names a CRS {_q(name)} that is not known", fix) from None
    if not (crs.is_geographic or crs.is_projected):
        raise _error(
            source, f"names a CRS {_q(name)} that is neither geographic nor projected", fix
        )
    return None if crs.equals(_WGS84, ignore_axis_order=True) else crs


def _to_wgs84(source: str, crs: pyproj.CRS, points: list[_Point]) -> list[_Point]:
    # GeoJSON's positions are x, y (easting, northing) in every CRS, whatever its axis order.
    to_wgs84 = pyproj.Transformer.from_crs(crs, _WGS84, always_xy=True)
    # The readers keep a position's x in lon_deg and its y in lat_deg until this point.
    lon, lat = to_wgs84.transform([p.lon_deg for p in points], [p.lat_deg for p in points])
    converted = []
    for p, x, y in zip(points, lon, lat, strict=True):
        if not _on_globe(y, x):
            problem = f"has {p.label()} at ({p.lon_deg}, {p.lat_deg}), outside {crs.name}"
            raise _error(source, problem, "fix the coordinates or the file's 'crs' member")
        converted.append(replace(p, lat_deg=float(y), lon_deg=float(x)))
    return converted


def _geojson_lon_lats(source: str, where: str, geometry: Any) -> list[tuple[float, float]]:
    """The positions of Point/MultiPoint geometries, also inside GeometryCollections."""
    positions: list[Any] = []
    stack = [geometry]
    while stack:
        item = stack.pop()
        kind = item.get("type") if isinstance(item, dict) else None
        coordinates = item.get("coordinates") if isinstance(item, dict) else None
        if kind == "Point":
            positions.append(coordinates)
        elif kind == "MultiPoint":
            # A malformed MultiPoint is kept whole, so the check below reports it.
            positions.extend(coordinates if isinstance(coordinates, list) else [coordinates])
        elif kind == "GeometryCollection" and isinstance(item.get("geometries"), list):
            stack.extend(reversed(item["geometries"]))
    lon_lats = []
    for position in positions:
        numbers = [_json_number(v) for v in position] if isinstance(position, list) else []
        valid = [n for n in numbers if n is not None]
        if len(valid) not in (2, 3) or len(valid) != len(numbers):
            problem = f"has a point in {where} with coordinates {_q(json.dumps(position))}"
            raise _error(source, problem, "give [lon, lat] or [lon, lat, alt] in decimal degrees")
        lon_lats.append((valid[0], valid[1]))
    return lon_lats


def _json_number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    in_range = isinstance(value, float) or abs(value) < 1e308  # JSON integers are unbounded
    return float(value) if in_range else (math.inf if value > 0 else -math.inf)


def _geojson_name(feature: dict[str, Any]) -> str | None:
    properties = feature.get("properties")
    keys = ("name", "Name", "title", "id")
    values = [properties.get(k) for k in keys] if isinstance(properties, dict) else []
    for value in [*values, feature.get("id")]:
        if isinstance(value, (str, int)) and not isinstance(value, bool) and str(value).strip():
            return str(value)
    return None


def _csv_points(source: str, data: bytes) -> list[_Point]:
    fix = "save it as UTF-8 CSV with a header row name,lat,lon"
    text = _decode(source, data, fix)
    first = next((line for line in text.split("\n") if line.strip()), "")
    delimiter = max(",;\t", key=first.count)  # ties keep the comma
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    points: list[_Point] = []
    try:
        header = next((row for row in reader if any(f.strip() for f in row)), [])
        columns = _csv_columns(source, [h.strip().lower() for h in header], fix)
        starts = reader.line_num + 1
        for row in reader:
            # A row is named by the line it starts on: a quoted field may span lines.
            where, starts = f"row {starts}", reader.line_num + 1
            if not any(field.strip() for field in row):
                continue
            fields = {key: row[i] if i < len(row) else "" for key, i in columns.items()}
            lat = _csv_number(source, where, "lat", fields["lat"].strip(), delimiter)
            lon = _csv_number(source, where, "lon", fields["lon"].strip(), delimiter)
            points.extend(_points(fields.get("name"), where, [(lon, lat)]))
    except csv.Error as exc:
        problem = f"is not readable CSV at line {reader.line_num} ({_q(str(exc))})"
        raise _error(source, problem, fix) from exc
    if not points:
        raise _error(source, "has a header but no data rows", "add one row per target")
    return points


def _csv_columns(source: str, header: list[str], fix: str) -> dict[str, int]:
    columns: dict[str, int] = {}
    for key, aliases in _CSV_COLUMNS.items():
        found = [h for h in header if h in aliases]
        if len(found) > 1:
            problem = f"has more than one {key!r} column ({', '.join(found)})"
            raise _error(source, problem, "keep one of them")
        if found:
            columns[key] = header.index(found[0])
        elif key != "name":
            problem = f"has no {key!r} column (header is {_q(','.join(header))})"
            also = ", ".join(repr(a) for a in aliases[1:])
            raise _error(source, problem, f"add a {key!r} column (also read as {also})")
    return columns


def _csv_number(source: str, where: str, column: str, text: str, delimiter: str) -> float:
    if delimiter == ";" and "," in text and "." not in text:
        text = text.replace(",", ".")  # decimal comma, as spreadsheets in many locales write
    try:
        return float(text)
    except ValueError:
        problem = f"has {column} value {_q(text)} in {where} that is not a number"
        raise _error(source, problem, "fix the value (decimal degrees, e.g. 47.3971)") from None


# A point with lat and lon swapped is taken to belong with the file's others this close to one.
_SWAP_NEAR_DEG = 1.0
_KML_ORDER = "KML writes lon,lat: swap the two numbers"
_GEOJSON_ORDER = "GeoJSON writes [lon, lat]: swap the two numbers"
SWAP_FIX = {
    ".kml": _KML_ORDER,
    ".kmz": _KML_ORDER,
    ".geojson": _GEOJSON_ORDER,
    ".json": _GEOJSON_ORDER,
    ".csv": "swap the lat and lon values (or the column names)",
}

_READERS: dict[str, Callable[[str, bytes], list[_Point]]] = {
    ".kml": _kml_points,
    ".kmz": _kmz_points,
    ".geojson": _geojson_points,
    ".json": _geojson_points,
    ".csv": _csv_points,
}


def _on_globe(lat: float, lon: float) -> bool:
    return math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180


def _looks_swapped(p: _Point, points: list[_Point]) -> bool:
    """Whether ``p``, off the globe, lands among the file's other points with lat and lon swapped.

    Either the whole file is swapped (p swapped lies near the others swapped) or this one point
    is (p swapped lies near the others as given); a lone point only has to land on the globe.
    A typo (a latitude of 95 among points at 47 N) lands near neither, and gets no hint.
    """
    if not _on_globe(p.lon_deg, p.lat_deg):
        return False
    others = [q for q in points if q is not p]
    if not others:
        return True
    return any(
        abs(p.lon_deg - a) <= _SWAP_NEAR_DEG and abs(p.lat_deg - b) <= _SWAP_NEAR_DEG
        for q in others
        for a, b in ((q.lat_deg, q.lon_deg), (q.lon_deg, q.lat_deg))
    )


def _check(source: str, points: list[_Point], swap_fix: str) -> TargetSet:
    """Validate raw points and sort them into home and targets."""
    for p in points:
        for axis, value, bound in (("latitude", p.lat_deg, 90), ("longitude", p.lon_deg, 180)):
            if not (math.isfinite(value) and -bound <= value <= bound):
                why = f"outside [-{bound}, {bound}]" if math.isfinite(value) else "not finite"
                problem = f"has {p.label()} with {axis} {value}, {why}"
                fix = "fix the coordinates (decimal degrees, WGS84)"
                if _looks_swapped(p, points):
                    fix = f"did you swap lat and lon? {swap_fix[0].upper()}{swap_fix[1:]}"
                raise _error(source, problem, fix)
        if p.name is not None and (unfit := _name_problem(p.name)) is not None:
            # The placemark's name, not one point's: a multi-point one shares it.
            problem = f"has point {_q(p.name)} ({p.where}) whose name holds {unfit}"
            raise _error(source, problem, "remove it from the name")
    homes = [p for p in points if p.is_home]
    if len(homes) > 1:
        problem = f"names two homes, {homes[0].label()} and {homes[1].label()}"
        raise _error(source, problem, "keep one point named Home or Launch")
    kept = [p for p in points if not p.is_home]
    if not kept:
        raise _error(source, "has no targets besides the home point", "add the points to visit")
    names = _target_names(kept)
    targets = [Target(n, p.lat_deg, p.lon_deg) for n, p in zip(names, kept, strict=True)]
    duplicate = _first_duplicate(targets)
    if duplicate is not None:
        labels = [f"point {_q(names[i])} ({kept[i].place()})" for i in duplicate]
        problem = f"has {labels[0]} and {labels[1]} at the same place"
        raise _error(source, problem, "remove one of them")
    _refuse_a_name_given_twice(source, kept)
    home = Target(homes[0].name or "Home", homes[0].lat_deg, homes[0].lon_deg) if homes else None
    return TargetSet(targets=tuple(targets), home=home, source=source)


def _target_names(points: list[_Point]) -> list[str]:
    """Each target's name: the one the file gives it, else one made up that no other target
    has. A made-up name is ``T<n>`` (n counts targets, 1-based) or, for the k-th point of a
    multi-point placemark, ``<name>-<k>``; should the file give another target that name,
    `` (2)``, `` (3)``, ... is added until it is free."""
    taken = {p.name for p in points if p.name is not None and not p.part}
    names = []
    for n, p in enumerate(points, start=1):
        if p.name is not None and not p.part:
            names.append(p.name)
            continue
        made = f"T{n}" if p.name is None else f"{p.name}-{p.part}"
        name, k = made, 1
        while name in taken:
            k += 1
            name = f"{made} ({k})"
        taken.add(name)
        names.append(name)
    return names


def _refuse_a_name_given_twice(source: str, points: list[_Point]) -> None:
    """Refuse two placemarks (features, rows) the file gives one name: a name is how the
    operator finds a target in the outputs, so it must say which one."""
    first: dict[str, _Point] = {}
    for p in points:
        if p.name is None or p.part > 1:  # a multi-point placemark names its points once
            continue
        earlier = first.setdefault(p.name, p)
        if earlier is not p:
            problem = f"has two targets named {_q(p.name)} ({earlier.where} and {p.where})"
            raise _error(source, problem, "rename one of them")


def check_names(site: TargetSet) -> TargetSet:
    """``site`` as given, once its names are fit for every output: what :func:`read_targets`
    holds a file's names to, for a set built in Python rather than read from a file.

    Raises
    ------
    TargetsError
        If a name (the home's included) holds a control character, a noncharacter, a lone
        surrogate or an invisible text-direction mark, or two targets have one name.
    """
    labelled = [(f"target {k}", t) for k, t in enumerate(site.targets, start=1)]
    labelled += [] if site.home is None else [("home", site.home)]
    seen: set[str] = set()
    for where, t in labelled:
        if (unfit := _name_problem(t.name)) is not None:
            problem = f"has {where} {_q(t.name)} whose name holds {unfit}"
            raise _error(site.source, problem, "remove it from the name")
        if where != "home" and t.name in seen:
            raise _error(site.source, f"has two targets named {_q(t.name)}", "rename one of them")
        seen.add(t.name)
    return site


def _first_duplicate(targets: list[Target]) -> tuple[int, int] | None:
    """The first target (in file order) at the same place as an earlier one, with that one.

    Targets are hashed on a grid of ``SAME_PLACE_DEG`` cells: two points within that distance
    on both axes sit in the same or adjacent cells, so each point is compared with the few
    points of its 3 x 3 block, not with every other point.
    """
    grid: dict[tuple[int, int], list[int]] = {}
    for j, t in enumerate(targets):
        row, col = math.floor(t.lat_deg / SAME_PLACE_DEG), math.floor(t.lon_deg / SAME_PLACE_DEG)
        near = (
            i
            for d_row in (-1, 0, 1)
            for d_col in (-1, 0, 1)
            for i in grid.get((row + d_row, col + d_col), ())
        )
        for i in sorted(near):
            if (
                abs(targets[i].lat_deg - t.lat_deg) <= SAME_PLACE_DEG
                and abs(targets[i].lon_deg - t.lon_deg) <= SAME_PLACE_DEG
            ):
                return i, j
        grid.setdefault((row, col), []).append(j)
    return None


def read_targets(path: Path) -> TargetSet:
    """Read the points to photograph, and the home point if the file names one.

    Parameters
    ----------
    path
        A ``.kml``/``.kmz`` (Placemarks with a Point, also in folders and MultiGeometry),
        ``.geojson``/``.json`` (Point and MultiPoint features, named by the ``name``,
        ``Name``, ``title`` or ``id`` property) or ``.csv`` file (a header with ``lat`` or
        ``latitude``, ``lon``, ``lng`` or ``longitude``, optionally ``name``; ``,`` or ``;``).

    Returns
    -------
    TargetSet
        The targets in file order, named as the file names them (a tab read as a space,
        blanks around trimmed), unnamed ones ``T<n>`` (1-based among targets) and the k-th
        point of a multi-point placemark ``<name>-<k>``, made-up names kept apart from the
        file's by `` (2)``, `` (3)``, ...; the point named ``Home`` or ``Launch`` (any case)
        as ``home``; ``source`` is ``str(path)``. A KMZ is read from its root ``doc.kml``,
        else its one ``.kml`` file (see :func:`_kmz_points`).

    Raises
    ------
    TargetsError
        If the file is missing, not a regular file, over 64 MiB, unreadable, empty, of an
        unknown kind, malformed or declares XML entities; if it has no targets, a point off
        the globe, two homes or two targets within 1e-7 degrees of each other; if two
        targets have one name, or a name holds a control character, a noncharacter, a lone
        surrogate or an invisible text-direction mark; if a GeoJSON feature or a KML
        placemark has no geometry (a line or a polygon is ignored); if a KMZ holds several
        ``.kml`` files and no ``doc.kml`` to say which to read.
    """
    source = str(path)
    reader = _READERS.get(path.suffix.lower())
    if reader is None:
        kinds = ", ".join(_READERS)
        problem = f"has an unknown extension {_q(path.suffix or '(none)')}"
        raise _error(source, problem, f"use one of {kinds}")
    data = read_capped(
        path,
        "targets file",
        "--targets",
        TargetsError,
        TARGETS_MAX_BYTES,
        "split the targets into several files and plan them one by one",
    )
    if not data.strip():
        raise _error(source, "is empty", "export the targets again")
    return _check(source, reader(source, data), SWAP_FIX[path.suffix.lower()])
