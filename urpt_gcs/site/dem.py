"""Opening a DSM/DEM GeoTIFF: its CRS, its height unit, its nodata, and the CRS plans use.

A raster in a projected CRS with metre units whose scale at the site is within 0.1 % of true
is read as is (a compound CRS such as UTM + EGM2008 height is fine: its horizontal part is
used). A raster in geographic coordinates, projected in other units, or in a projection that
stretches lengths at the site (Web Mercator) is georeferenced in the UTM zone of the targets
(:func:`planning_crs`); :mod:`urpt_gcs.site.reading` then reads its pixels.

Heights are converted to metres on read, from the unit of the CRS's vertical axis (feet, US
survey feet, ...). A raster without a vertical CRS is taken to be in metres, as Pix4D writes it.

Cells that are nodata (declared nodata, NaN, or an elevation no place on Earth has) become
NaN (:func:`clean_elevations`) and are never used as an elevation: any bilinear sample
touching one is NaN, and every caller treats NaN as "unknown ground", which blocks a line of
sight and fails a clearance test.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyproj
import rasterio
import rasterio.errors
import rasterio.io
from affine import Affine
from pyproj.aoi import AreaOfInterest
from pyproj.database import query_utm_crs_info

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import DemError
from urpt_gcs.site.inputs import require_regular_file

__all__ = [
    "ASSUMED_METRES",
    "MAX_SCALE_ERROR",
    "MAX_VALID_ELEVATION_M",
    "MIN_VALID_ELEVATION_M",
    "WGS84",
    "DemInfo",
    "VerticalUnit",
    "check_elevations",
    "clean_elevations",
    "crs_label",
    "first_line",
    "open_dem",
    "open_raster",
    "planning_crs",
    "scale_error",
    "vertical_unit",
]

# Beyond these no terrain on Earth exists; such values are undeclared nodata fill.
MIN_VALID_ELEVATION_M = -1000.0
MAX_VALID_ELEVATION_M = 9000.0
# A projection whose scale at the site is off by more than this (Web Mercator: 49 % at 47.7 N)
# is planned in UTM instead; UTM's own 0.9996 on its central meridian stays native.
MAX_SCALE_ERROR = 1e-3
WGS84 = pyproj.CRS.from_epsg(4326)


@dataclass(frozen=True, slots=True)
class VerticalUnit:
    """The unit a raster's heights are stored in.

    ``to_m`` converts a stored value to metres; ``declared`` is False when the CRS has no
    vertical axis and metres are assumed.
    """

    name: str
    to_m: float
    declared: bool

    def __post_init__(self) -> None:
        if not (math.isfinite(self.to_m) and self.to_m > 0.0):
            raise ValueError("VerticalUnit.to_m must be a positive number")

    @property
    def converted(self) -> bool:
        """Whether stored heights are multiplied on read (they are not in metres)."""
        return self.to_m != 1.0


ASSUMED_METRES = VerticalUnit("metre", 1.0, declared=False)


@dataclass(frozen=True, slots=True)
class DemInfo:
    """What is known about a raster before any pixel is read.

    ``band`` is the band read as elevation (from 1); ``dtype`` and ``nodata`` are that band's.
    ``vertical_unit`` is what its values are in; :func:`~urpt_gcs.site.reading.read_terrain`
    returns them in metres.
    """

    path: Path
    crs: pyproj.CRS
    horizontal_crs: pyproj.CRS
    width_px: int
    height_px: int
    transform: Affine
    dtype: str
    nodata: float | None
    band: int = 1
    vertical_unit: VerticalUnit = ASSUMED_METRES

    @property
    def needs_warp(self) -> bool:
        """True unless the raster is projected in metres (whether its scale at the site is
        close enough to true is for :func:`planning_crs` to say)."""
        return not _is_metric_projected(self.horizontal_crs)


def _is_metric_projected(crs: pyproj.CRS) -> bool:
    if not crs.is_projected:
        return False
    units = {axis.unit_name for axis in crs.axis_info[:2]}
    return units <= {"metre", "meter"}


def _horizontal(crs: pyproj.CRS) -> pyproj.CRS:
    if crs.is_compound:
        return crs.sub_crs_list[0]
    return crs


def _vertical_axis_unit(crs: pyproj.CRS) -> tuple[str, float, bool] | None:
    """(name, factor to metres, whether it is a length) of the height axis, if there is one."""
    if crs.is_bound and crs.source_crs is not None:
        # A datum shift (TOWGS84) wrapped around the CRS; the axes are the source's.
        crs = crs.source_crs
    if crs.is_compound:
        verticals = [sub for sub in crs.sub_crs_list if sub.is_vertical]
        if not verticals:
            return None
        cs, axis_index = verticals[0], 0
    elif len(crs.axis_info) == 3:
        cs, axis_index = crs, 2
    else:
        return None
    axis = cs.axis_info[axis_index]
    # PROJ JSON names the unit's kind; pyproj's Axis does not.
    unit = cs.to_json_dict()["coordinate_system"]["axis"][axis_index]["unit"]
    is_length = unit == "metre" or (isinstance(unit, dict) and unit.get("type") == "LinearUnit")
    return axis.unit_name, float(axis.unit_conversion_factor), is_length


def vertical_unit(crs: pyproj.CRS, source: str) -> VerticalUnit:
    """The unit of the heights of a raster in ``crs``; metres when it declares none.

    Raises
    ------
    DemError
        When the vertical axis's unit is unknown or not a length.
    """
    found = _vertical_axis_unit(crs)
    if found is None:
        return ASSUMED_METRES
    name, to_m, is_length = found
    if not is_length or name.lower() == "unknown" or not (math.isfinite(to_m) and to_m > 0.0):
        horizontal = _horizontal(crs).to_epsg()
        example = f"EPSG:{horizontal}+5773" if horizontal is not None else "EPSG:<h>+5773"
        kind = "an unknown unit" if name.lower() == "unknown" else f"'{name}', not a length"
        raise DemError(
            f"DEM '{source}' declares its heights in {kind}: give it a vertical CRS in metres "
            f"or feet (e.g. gdal_edit.py -a_srs {example}, EGM96 height in metres)"
        )
    if abs(to_m - 1.0) < 1e-12:
        return VerticalUnit("metre", 1.0, declared=True)
    return VerticalUnit(name, to_m, declared=True)


@contextlib.contextmanager
def open_raster(path: Path) -> Iterator[rasterio.io.DatasetReader]:
    """Open a raster for reading without rasterio's NotGeoreferencedWarning.

    A DEM without georeferencing is refused by :func:`open_dem` with an error that says what
    to do; the warning would print two lines of rasterio's own before it, telling nothing more.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(path) as src:
            yield src


def open_dem(path: Path, band: int | None = None) -> DemInfo:
    """Check that ``path`` is a usable elevation raster and describe it without reading pixels.

    Parameters
    ----------
    path
        The GeoTIFF DSM/DEM.
    band
        The band (from 1) holding the elevations; may be omitted for a single-band raster.

    Raises
    ------
    DemError
        When the raster cannot be used: missing, unreadable, without CRS or geotransform,
        rotated, several bands and none named, a complex band, or heights in a unit that is
        not a length.
    """
    name = str(path)
    require_regular_file(path, "DEM", "--dem", DemError)
    try:
        with open_raster(path) as src:
            if src.crs is None:
                raise DemError(
                    f"DEM '{name}' has no coordinate reference system: assign one "
                    "(e.g. gdal_edit.py -a_srs EPSG:32632) or export it georeferenced"
                )
            if src.count < 1:
                raise DemError(f"DEM '{name}' has no raster band: export the DSM again")
            chosen = _pick_band(name, src.count, band)
            dtype = src.dtypes[chosen - 1]
            if np.issubdtype(np.dtype(dtype), np.complexfloating):
                raise DemError(
                    f"DEM '{name}' band {chosen} holds complex numbers ({dtype}), not "
                    "elevations: export the DSM as a real-valued band (e.g. float32)"
                )
            transform = src.transform
            if transform.is_identity:
                raise DemError(
                    f"DEM '{name}' has no geotransform (pixel size and position): export it "
                    "georeferenced, or warp it (gdalwarp) if it holds ground control points"
                )
            if transform.b != 0.0 or transform.d != 0.0 or transform.e >= 0.0:
                raise DemError(
                    f"DEM '{name}' is rotated or not north-up: warp it north-up "
                    "(gdalwarp) before planning"
                )
            crs = pyproj.CRS.from_wkt(src.crs.to_wkt())
            nodata = src.nodatavals[chosen - 1]
            return DemInfo(
                path=path,
                crs=crs,
                horizontal_crs=_horizontal(crs),
                width_px=src.width,
                height_px=src.height,
                transform=transform,
                dtype=dtype,
                nodata=None if nodata is None else float(nodata),
                band=chosen,
                vertical_unit=vertical_unit(crs, name),
            )
    except rasterio.errors.RasterioIOError as exc:
        raise DemError(
            f"DEM '{name}' is not a readable raster ({first_line(exc)}): give a GeoTIFF DSM/DEM"
        ) from exc
    except (rasterio.errors.RasterioError, pyproj.exceptions.CRSError) as exc:
        raise DemError(f"DEM '{name}' cannot be used ({first_line(exc)})") from exc


def _pick_band(name: str, count: int, band: int | None) -> int:
    if band is None:
        if count > 1:
            raise DemError(
                f"DEM '{name}' has {count} bands: name the one holding the elevations "
                f"with --band N (1 to {count})"
            )
        return 1
    if not 1 <= band <= count:
        bands = "1 band" if count == 1 else f"{count} bands"
        raise DemError(
            f"DEM '{name}' has {bands}, so there is no band {band}: give --band 1 to {count}"
        )
    return band


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (its type's name when it has none), for an
    error message of one line."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def scale_error(crs: pyproj.CRS, lon_lat_bounds: tuple[float, float, float, float]) -> float:
    """How far lengths in the projected ``crs`` are from true over a lon/lat box: the largest
    ``|scale - 1|`` in any direction (Tissot's semi-axes) at its corners and centre.

    An infinite result means the projection cannot be evaluated there.
    """
    west, south, east, north = lon_lat_bounds
    lons = np.array([west, east, west, east, (west + east) / 2.0])
    lats = np.array([south, south, north, north, (south + north) / 2.0])
    try:
        factors = pyproj.Proj(crs).get_factors(lons, lats, errcheck=True)
    except pyproj.exceptions.ProjError:
        return math.inf
    semi = np.concatenate(
        [np.atleast_1d(factors.tissot_semimajor), np.atleast_1d(factors.tissot_semiminor)]
    )
    if not np.isfinite(semi).all():
        return math.inf
    return float(np.max(np.abs(semi - 1.0)))


def planning_crs(info: DemInfo, lon_lat_bounds: tuple[float, float, float, float]) -> pyproj.CRS:
    """The metric CRS plans are made in: the DEM's own, or the UTM zone of the points.

    ``lon_lat_bounds`` is (west, south, east, north) of the targets and home. The DEM's own CRS
    is used when it is projected in metres and true to scale there (see ``MAX_SCALE_ERROR``);
    otherwise the plan is made in UTM. A DEM whose points straddle a UTM zone edge is then
    refused: one flat map would distort one side.
    """
    hcrs = info.horizontal_crs
    if not info.needs_warp:
        error = scale_error(hcrs, lon_lat_bounds)
        if error <= MAX_SCALE_ERROR:
            return hcrs
        reason = f"is in {hcrs.name}, whose scale at the site is off by " + (
            f"{100.0 * error:.1f} %" if math.isfinite(error) else "an unknown amount"
        )
    elif hcrs.is_geographic:
        reason = "is geographic"
    else:
        reason = f"is projected in units of {hcrs.axis_info[0].unit_name}"
    west, south, east, north = lon_lat_bounds
    zones = query_utm_crs_info(
        datum_name="WGS 84",
        area_of_interest=AreaOfInterest(west, south, east, north),
    )
    hemisphere = "N" if (south + north) / 2.0 >= 0 else "S"
    zones = [z for z in zones if z.name.endswith(hemisphere)]
    if not zones:
        raise DemError(
            f"DEM '{info.path}' {reason} and no UTM zone covers the targets: "
            "reproject it to a local metric CRS first"
        )
    if len(zones) > 1:
        # Named by the points' own zones: the query lists every zone between them, from 1.
        if east - west > 180.0:
            where = f"the antimeridian (UTM zones {_utm_zone(east)}{hemisphere} and 1{hemisphere})"
        else:
            where = f"UTM zones {_utm_zone(west)}{hemisphere} and {_utm_zone(east)}{hemisphere}"
        raise DemError(
            f"DEM '{info.path}' {reason} and the targets straddle {where}: "
            "plan each side separately, or reproject the DEM to one projected CRS (gdalwarp)"
        )
    return pyproj.CRS.from_authority(zones[0].auth_name, zones[0].code)


def crs_label(crs: pyproj.CRS, code_first: bool = False) -> str:
    """A CRS as a person names it, in one short line, never its WKT: its name (``WGS 84 /
    Pseudo-Mercator``) or, with ``code_first`` or without a name, its authority code
    (``EPSG:32632``); failing both, what kind of CRS it is (``a custom Transverse Mercator
    CRS``)."""
    found = crs.to_authority(min_confidence=90)
    code = None if found is None else f"{found[0]}:{found[1]}"
    name = " ".join((crs.name or "").split())
    if name.lower() in ("", "unknown", "unnamed", "undefined"):
        name = ""
    elif len(name) > 80:
        name = name[:77] + "..."
    for label in (code, name) if code_first else (name, code):
        if label:
            return label
    operation = crs.coordinate_operation
    if crs.is_projected and operation is not None and operation.method_name:
        return f"a custom {operation.method_name} CRS"
    return "a custom geographic CRS" if crs.is_geographic else "a custom CRS"


def _utm_zone(lon: float) -> int:
    """The number (1..60) of the UTM zone holding longitude ``lon``."""
    return int((lon + 180.0) // 6.0) % 60 + 1


def clean_elevations(
    values: npt.NDArray[np.generic], mask: npt.NDArray[np.bool_], to_m: float
) -> FloatArray:
    """Cells as read, as float64 metres: masked cells and values outside
    [``MIN_VALID_ELEVATION_M``, ``MAX_VALID_ELEVATION_M``] become NaN."""
    z = values.astype(np.float64)
    z[mask] = np.nan
    if to_m != 1.0:
        z *= to_m
    z[(z < MIN_VALID_ELEVATION_M) | (z > MAX_VALID_ELEVATION_M)] = np.nan
    return z


def check_elevations(info: DemInfo) -> None:
    """Refuse a raster that holds no valid elevation, saying why, from a decimated read (small
    in memory).

    Raises
    ------
    DemError
        When every cell is nodata, or every value lies outside the range terrain on Earth has
        (after conversion to metres): a wrong vertical unit or an undeclared nodata value.
    """
    scale = max(info.width_px, info.height_px) / 512.0
    shape = (
        max(int(info.height_px / max(scale, 1.0)), 1),
        max(int(info.width_px / max(scale, 1.0)), 1),
    )
    with open_raster(info.path) as src:
        band = src.read(info.band, out_shape=shape, masked=True)
    unit = info.vertical_unit
    z = clean_elevations(np.ma.getdata(band), np.ma.getmaskarray(band), unit.to_m)
    if np.isfinite(z).any():
        return
    values = np.ma.getdata(band)[~np.ma.getmaskarray(band)].astype(np.float64) * unit.to_m
    values = values[~np.isnan(values)]
    if values.size == 0:
        raise DemError(
            f"DEM '{info.path}' holds no elevation at all (every cell is nodata): "
            "export the DSM again"
        )
    converted = f", converted from {unit.name}" if unit.converted else ""
    raise DemError(
        f"DEM '{info.path}' holds no elevation in the valid range "
        f"[{MIN_VALID_ELEVATION_M:g}, {MAX_VALID_ELEVATION_M:g}] m (its values run from "
        f"{float(values.min()):.6g} to {float(values.max()):.6g} m{converted}): check its "
        "vertical unit and its nodata value"
    )
