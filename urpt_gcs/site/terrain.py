"""Terrain: the part of a DSM/DEM GeoTIFF that a plan needs, in a metric projected CRS.

A raster in a projected CRS with metre units whose scale at the site is within 0.1 % of true
is read as is (a compound CRS such as UTM + EGM2008 height is fine: its horizontal part is
used). A raster in geographic coordinates, projected in other units, or in a projection that
stretches lengths at the site (Web Mercator) is georeferenced in the UTM zone of the targets:
the window read keeps its own pixels (no resampling, so its bilinear surface is exactly the
source's) and gets the affine map from its pixels to UTM that fits the true projection over
the window, to a small fraction of a cell (checked on read).
Only a window is ever read: :func:`read_terrain` takes the area of interest in the planning CRS.

Heights are converted to metres on read, from the unit of the CRS's vertical axis (feet, US
survey feet, ...). A raster without a vertical CRS is taken to be in metres, as Pix4D writes it.

Cells that are nodata (declared nodata, NaN, or an elevation no place on Earth has) become
NaN and are never used as an elevation: any bilinear sample touching one is NaN, and every
caller treats NaN as "unknown ground", which blocks a line of sight and fails a clearance test.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyproj
import rasterio
import rasterio.errors
import rasterio.io
import rasterio.warp
import rasterio.windows
from affine import Affine
from numba import njit
from pyproj.aoi import AreaOfInterest
from pyproj.database import query_utm_crs_info

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import DemError
from urpt_gcs.memory import require_memory
from urpt_gcs.site.inputs import require_regular_file

# Elevations as stored: float32 where that holds the source's values exactly, else float64.
ElevationArray = npt.NDArray[np.float32] | npt.NDArray[np.float64]

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
    ``vertical_unit`` is what its values are in; :func:`read_terrain` returns them in metres.
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


@dataclass(frozen=True, slots=True)
class Terrain:
    """Elevations of a raster window georeferenced in a projected, metric CRS.

    ``transform`` maps (col, row) of a pixel corner to (x, y) in ``crs``; it is north-up for a
    projected source and a fitted affine map for a geographic one. NaN marks no data.
    ``read_window_px`` is the window read from the source raster (col_off, row_off, width,
    height) and ``source_shape_px`` the source's (height, width), so what was read can be
    reported.

    A terrain read by :func:`read_mosaic` is sparse: only the source's blocks that some window
    touches are read, and every other cell is NaN, unknown ground like nodata. ``blocks_read``
    then says which source blocks (``block_px`` = (height, width) each, counted from the
    block holding the window's first cell) hold data, so that :func:`fill_along` can add the
    blocks a leg crosses later.
    """

    elevation_m: ElevationArray
    transform: Affine
    crs: pyproj.CRS
    source: str
    read_window_px: tuple[int, int, int, int]
    source_shape_px: tuple[int, int]
    block_px: tuple[int, int] = (0, 0)
    blocks_read: npt.NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        if self.elevation_m.ndim != 2 or self.elevation_m.dtype not in (np.float32, np.float64):
            raise ValueError("Terrain.elevation_m must be a 2-D float32 or float64 array")
        if abs(self.transform.determinant) < 1e-12:
            raise ValueError("Terrain.transform must be invertible")

    @property
    def cell_m(self) -> float:
        """The shorter side of a pixel, in metres."""
        t = self.transform
        return float(min(math.hypot(t.a, t.d), math.hypot(t.b, t.e)))

    def pixel_coords(self, x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (col, row) of points, with pixel centres at whole numbers."""
        inv = ~self.transform
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        col = inv.a * xa + inv.b * ya + inv.c - 0.5
        row = inv.d * xa + inv.e * ya + inv.f - 0.5
        return col, row

    def sample(self, x: npt.ArrayLike, y: npt.ArrayLike) -> FloatArray:
        """Bilinear elevation at points (x, y); NaN outside the grid or next to nodata.

        Pixel values sit at pixel centres. Between the outermost centres and the grid edge
        the edge value is used.
        """
        col, row = self.pixel_coords(x, y)
        rows, cols = self.elevation_m.shape
        inside = (col >= -0.5) & (col <= cols - 0.5) & (row >= -0.5) & (row <= rows - 0.5)
        col = np.clip(np.where(inside, col, 0.0), 0.0, cols - 1.0)
        row = np.clip(np.where(inside, row, 0.0), 0.0, rows - 1.0)
        c0 = np.minimum(np.floor(col).astype(np.intp), max(cols - 2, 0))
        r0 = np.minimum(np.floor(row).astype(np.intp), max(rows - 2, 0))
        c1 = np.minimum(c0 + 1, cols - 1)
        r1 = np.minimum(r0 + 1, rows - 1)
        fc = col - c0
        fr = row - r0
        z = self.elevation_m
        top = z[r0, c0] * (1.0 - fc) + z[r0, c1] * fc
        bottom = z[r1, c0] * (1.0 - fc) + z[r1, c1] * fc
        out = top * (1.0 - fr) + bottom * fr
        return np.where(inside, out, np.nan)


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
def _open(path: Path) -> Iterator[rasterio.io.DatasetReader]:
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
        with _open(path) as src:
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
            f"DEM '{name}' is not a readable raster ({_first_line(exc)}): give a GeoTIFF DSM/DEM"
        ) from exc
    except (rasterio.errors.RasterioError, pyproj.exceptions.CRSError) as exc:
        raise DemError(f"DEM '{name}' cannot be used ({_first_line(exc)})") from exc


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


def _first_line(exc: BaseException) -> str:
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
        names = " and ".join(z.name.rsplit(" ", 1)[-1] for z in zones[:2])
        raise DemError(
            f"DEM '{info.path}' {reason} and the targets straddle UTM zones {names}: "
            "plan each side separately, or reproject the DEM to one projected CRS (gdalwarp)"
        )
    return pyproj.CRS.from_authority(zones[0].auth_name, zones[0].code)


def _clean(values: npt.NDArray[np.generic], mask: npt.NDArray[np.bool_], to_m: float) -> FloatArray:
    z = values.astype(np.float64)
    z[mask] = np.nan
    if to_m != 1.0:
        z *= to_m
    z[(z < MIN_VALID_ELEVATION_M) | (z > MAX_VALID_ELEVATION_M)] = np.nan
    return z


def read_terrain(
    info: DemInfo, crs: pyproj.CRS, area: tuple[float, float, float, float]
) -> Terrain:
    """Read the part of the DEM covering ``area`` = (xmin, ymin, xmax, ymax) in ``crs``.

    Parameters
    ----------
    info
        The raster, from :func:`open_dem`.
    crs
        The planning CRS, from :func:`planning_crs`.
    area
        Box to cover, in ``crs``. Parts outside the raster are simply absent (NaN when
        sampled).

    Returns
    -------
    Terrain
        The elevations of the window in metres; nodata as NaN.
    """
    try:
        if info.needs_warp or crs != info.horizontal_crs:
            return _read_warped(info, crs, area)
        return _read_native(info, area)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({_first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc


def _window_for(
    info: DemInfo, src_crs_area: tuple[float, float, float, float], pad_px: int
) -> rasterio.windows.Window:
    xmin, ymin, xmax, ymax = src_crs_area
    inv = ~info.transform
    c_a, r_a = inv @ (xmin, ymax)
    c_b, r_b = inv @ (xmax, ymin)
    c0 = max(math.floor(min(c_a, c_b)) - pad_px, 0)
    c1 = min(math.ceil(max(c_a, c_b)) + pad_px, info.width_px)
    r0 = max(math.floor(min(r_a, r_b)) - pad_px, 0)
    r1 = min(math.ceil(max(r_a, r_b)) + pad_px, info.height_px)
    return rasterio.windows.Window(c0, r0, max(c1 - c0, 0), max(r1 - r0, 0))


def _read_window(
    info: DemInfo, area: tuple[float, float, float, float]
) -> tuple[rasterio.windows.Window, FloatArray]:
    """The window of the raster covering ``area`` (in the raster's CRS) and its elevations."""
    window = _window_for(info, area, pad_px=2)
    if window.width == 0 or window.height == 0:
        raise DemError(
            f"DEM '{info.path}' does not cover the targets' area: check that the targets "
            "belong to this site"
        )
    # The cells as read, as float64 elevations, and the nodata mask.
    per_cell = np.dtype(info.dtype).itemsize + 8 + 1
    require_memory(
        float(window.width) * float(window.height) * per_cell,
        f"DEM '{info.path}': the window of {int(window.width)} x {int(window.height)} cells "
        "around the targets",
        "plan targets that lie closer together, or lower --altitude/--clearance",
    )
    with _open(info.path) as src:
        band = src.read(info.band, window=window, masked=True)
    return window, _clean(np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m)


def _window_px(window: rasterio.windows.Window) -> tuple[int, int, int, int]:
    return (int(window.col_off), int(window.row_off), int(window.width), int(window.height))


def _read_native(info: DemInfo, area: tuple[float, float, float, float]) -> Terrain:
    window, z = _read_window(info, area)
    return Terrain(
        elevation_m=z,
        transform=rasterio.windows.transform(window, info.transform),
        crs=info.horizontal_crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
    )


def _read_warped(
    info: DemInfo, crs: pyproj.CRS, area: tuple[float, float, float, float]
) -> Terrain:
    src_area = rasterio.warp.transform_bounds(crs, info.horizontal_crs, *area, densify_pts=21)
    window, z = _read_window(info, src_area)
    transform, error_m = _fit_affine(info, crs, window)
    terrain = Terrain(
        elevation_m=z,
        transform=transform,
        crs=crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
    )
    if error_m > max(0.05 * terrain.cell_m, 0.005):
        raise DemError(
            f"DEM '{info.path}' is in {info.horizontal_crs.name} and the targets spread too far "
            f"to plan in one flat map ({error_m:.2f} m distortion): reproject the DEM to "
            "the local UTM zone (gdalwarp -t_srs) or plan fewer targets at a time"
        )
    return terrain


def _fit_affine(
    info: DemInfo, crs: pyproj.CRS, window: rasterio.windows.Window
) -> tuple[Affine, float]:
    """Least-squares affine map from window pixels to ``crs``, and its worst error in metres."""
    cols = np.linspace(0.0, float(window.width), 7)
    rows = np.linspace(0.0, float(window.height), 7)
    cc, rr = (a.ravel() for a in np.meshgrid(cols, rows))
    t = info.transform
    sx = t.a * (cc + window.col_off) + t.b * (rr + window.row_off) + t.c
    sy = t.d * (cc + window.col_off) + t.e * (rr + window.row_off) + t.f
    to_crs = pyproj.Transformer.from_crs(info.horizontal_crs, crs, always_xy=True)
    x, y = to_crs.transform(sx, sy)
    design = np.column_stack([cc, rr, np.ones_like(cc)])
    (a, b, c), *_ = np.linalg.lstsq(design, np.asarray(x), rcond=None)
    (d, e, f), *_ = np.linalg.lstsq(design, np.asarray(y), rcond=None)
    fitted = design @ np.array([[a, d], [b, e], [c, f]])
    error = float(np.max(np.hypot(fitted[:, 0] - x, fitted[:, 1] - y)))
    return Affine(float(a), float(b), float(c), float(d), float(e), float(f)), error


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
    with _open(info.path) as src:
        band = src.read(info.band, out_shape=shape, masked=True)
    unit = info.vertical_unit
    z = _clean(np.ma.getdata(band), np.ma.getmaskarray(band), unit.to_m)
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


# Boxes in source pixels: (col0, row0, col1, row1), ends exclusive.
PixelBoxes = npt.NDArray[np.int64]


def _storage_dtype(info: DemInfo) -> type[np.floating[Any]]:
    """float32 when it holds every source value exactly in metres, else float64."""
    exact32 = np.dtype(info.dtype) in (
        np.dtype(t) for t in ("float32", "int16", "uint16", "int8", "uint8")
    )
    return np.float32 if exact32 and not info.vertical_unit.converted else np.float64


def _block_shape(src: rasterio.io.DatasetReader, band: int) -> tuple[int, int]:
    bh, bw = src.block_shapes[band - 1]
    # A striped raster (one row per block) is read in squares of our own: a strip is cached
    # by GDAL once decompressed, and squares keep the count of read cells near the windows.
    if bh < 64 or bw < 64:
        return 256, 256
    return int(bh), int(bw)


def pixel_boxes(
    info: DemInfo, crs: pyproj.CRS, boxes: npt.ArrayLike, pad_px: int = 2
) -> PixelBoxes:
    """Source-pixel boxes, clipped to the raster, covering boxes (xmin, ymin, xmax, ymax) in
    ``crs`` with ``pad_px`` cells more on every side."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    xs = b[:, [0, 2, 0, 2]]
    ys = b[:, [1, 1, 3, 3]]
    if info.needs_warp or crs != info.horizontal_crs:
        to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
        xs, ys = (np.asarray(v).reshape(-1, 4) for v in to_src.transform(xs, ys))
    inv = ~info.transform
    cols = inv.a * xs + inv.b * ys + inv.c
    rows = inv.d * xs + inv.e * ys + inv.f
    out = np.column_stack(
        [
            np.floor(cols.min(axis=1)) - pad_px,
            np.floor(rows.min(axis=1)) - pad_px,
            np.ceil(cols.max(axis=1)) + pad_px,
            np.ceil(rows.max(axis=1)) + pad_px,
        ]
    )
    limits = np.array([info.width_px, info.height_px, info.width_px, info.height_px])
    clipped: PixelBoxes = np.clip(out, 0, limits).astype(np.int64)
    return clipped


class BlockCache:
    """What the altitude search has learnt of a DEM's blocks, so that none is decompressed twice.

    For every block read it keeps the block's maximum and its row and column maxima (enough
    for the exact maximum of a box that cuts the block on one axis only), and the cells of
    a block a box cuts on both axes or that lies in a camera cone; :func:`read_mosaic` takes
    the cone blocks from here instead of reading them again. Mutable, owned by one plan.
    """

    def __init__(self, info: DemInfo) -> None:
        self.info = info
        self.block_px: tuple[int, int] | None = None
        self.maxima: dict[tuple[int, int], tuple[float, FloatArray, FloatArray]] = {}
        self.cells: dict[tuple[int, int], ElevationArray] = {}
        self.decompressed = 0
        self.again = 0

    def block_window(self, j: int, i: int) -> tuple[int, int, int, int]:
        """Block (row j, column i)'s source cells (col0, row0, col1, row1), clipped."""
        assert self.block_px is not None
        bh, bw = self.block_px
        return (
            i * bw,
            j * bh,
            min((i + 1) * bw, self.info.width_px),
            min((j + 1) * bh, self.info.height_px),
        )


def _block_cells(
    info: DemInfo, src: rasterio.io.DatasetReader, window: tuple[int, int, int, int]
) -> ElevationArray:
    c0, r0, c1, r1 = window
    band = src.read(
        info.band, window=rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0), masked=True
    )
    z = _clean(np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m)
    return z.astype(_storage_dtype(info), copy=False)


def _top(z: npt.NDArray[np.floating[Any]], axis: int | None = None) -> Any:
    """Maximum over valid cells; -inf where there are none."""
    return np.where(np.isfinite(z), z, -np.inf).max(axis=axis, initial=-np.inf)


def area_max(
    info: DemInfo,
    crs: pyproj.CRS,
    area: tuple[float, float, float, float],
    cache: BlockCache | None = None,
    keep: npt.ArrayLike | None = None,
) -> float:
    """The highest valid elevation (metres) in ``area``; NaN when the area holds none.

    Blocks are read one at a time, and with a ``cache`` each only once over successive calls:
    a block already read contributes its recorded maxima. The cells of blocks that boxes
    ``keep`` (xmin, ymin, xmax, ymax in ``crs``) touch are kept in the cache for
    :func:`read_mosaic`; other blocks' cells are dropped once their maxima are known, unless
    the area cuts them on both axes (a later, wider area needs their exact maximum).
    """
    cache = BlockCache(info) if cache is None else cache
    box = [int(v) for v in pixel_boxes(info, crs, [area])[0]]
    keep_px = np.zeros((0, 4), dtype=np.int64) if keep is None else pixel_boxes(info, crs, keep)
    top = -math.inf
    try:
        with _open(info.path) as src:
            if cache.block_px is None:
                cache.block_px = _block_shape(src, info.band)
            bh, bw = cache.block_px
            for j in range(box[1] // bh, -(-box[3] // bh)):
                for i in range(box[0] // bw, -(-box[2] // bw)):
                    c0, r0, c1, r1 = cache.block_window(j, i)
                    a, b = max(c0, box[0]), max(r0, box[1])
                    c, d = min(c1, box[2]), min(r1, box[3])
                    if c <= a or d <= b:
                        continue
                    cut_cols, cut_rows = (a, c) != (c0, c1), (b, d) != (r0, r1)
                    key = (j, i)
                    z = cache.cells.get(key)
                    if key not in cache.maxima or (z is None and cut_cols and cut_rows):
                        # A block first seen uncut on an axis is cut on both only when the
                        # area shrinks, which the altitude search never does.
                        cache.again += key in cache.maxima
                        z = _block_cells(info, src, (c0, r0, c1, r1))
                        cache.decompressed += 1
                        cache.maxima[key] = (float(_top(z)), _top(z, 0), _top(z, 1))
                    whole, col_top, row_top = cache.maxima[key]
                    if cut_cols and cut_rows:
                        assert z is not None
                        here = float(_top(z[b - r0 : d - r0, a - c0 : c - c0]))
                    elif cut_cols:
                        here = float(col_top[a - c0 : c - c0].max())
                    elif cut_rows:
                        here = float(row_top[b - r0 : d - r0].max())
                    else:
                        here = whole
                    top = max(top, here)
                    kept = bool(
                        (
                            (keep_px[:, 0] < c1)
                            & (keep_px[:, 2] > c0)
                            & (keep_px[:, 1] < r1)
                            & (keep_px[:, 3] > r0)
                        ).any()
                    )
                    if z is not None and (kept or (cut_cols and cut_rows)):
                        cache.cells[key] = z
                    else:
                        cache.cells.pop(key, None)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({_first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    return top if math.isfinite(top) else math.nan


def read_mosaic(
    info: DemInfo, crs: pyproj.CRS, boxes: npt.ArrayLike, cache: BlockCache | None = None
) -> Terrain:
    """Read only the source blocks that boxes (xmin, ymin, xmax, ymax) in ``crs`` touch.

    The result spans the boxes' union; cells of blocks no box touches are NaN (unknown
    ground), never an elevation. Each block is read once, however many boxes touch it, and
    only one block's float64 copy is alive at a time; a block whose cells ``cache`` holds
    (kept by :func:`area_max`) is taken from it and not read again.

    Raises
    ------
    DemError
        When the boxes miss the raster, or the file cannot be read.
    MemoryBudgetError
        When the union's grid would not fit the memory budget.
    """
    px = pixel_boxes(info, crs, boxes)
    px = px[(px[:, 2] > px[:, 0]) & (px[:, 3] > px[:, 1])]
    if len(px) == 0:
        raise DemError(
            f"DEM '{info.path}' does not cover the targets' area: check that the targets "
            "belong to this site"
        )
    c0, r0 = int(px[:, 0].min()), int(px[:, 1].min())
    c1, r1 = int(px[:, 2].max()), int(px[:, 3].max())
    dtype = _storage_dtype(info)
    require_memory(
        float(c1 - c0) * float(r1 - r0) * np.dtype(dtype).itemsize,
        f"DEM '{info.path}': the grid of {c1 - c0} x {r1 - r0} cells spanning the targets' "
        "camera cones",
        "plan targets that lie closer together, or lower --altitude/--clearance",
    )
    window = rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0)
    try:
        with _open(info.path) as src:
            bh, bw = _block_shape(src, info.band)
            if cache is not None and cache.block_px not in (None, (bh, bw)):
                raise ValueError("read_mosaic: the cache was filled with other blocks")
            mask = np.zeros(
                ((r1 - 1) // bh - r0 // bh + 1, (c1 - 1) // bw - c0 // bw + 1), dtype=np.bool_
            )
            for a, b, c, d in (px - np.array([c0 // bw * bw, r0 // bh * bh] * 2)).tolist():
                mask[b // bh : (d - 1) // bh + 1, a // bw : (c - 1) // bw + 1] = True
            z = np.full((r1 - r0, c1 - c0), np.nan, dtype=dtype)
            _read_blocks(info, src, z, window, (bh, bw), mask, cache)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({_first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    if info.needs_warp or crs != info.horizontal_crs:
        transform, error_m = _fit_affine(info, crs, window)
    else:
        transform, error_m = rasterio.windows.transform(window, info.transform), 0.0
    terrain = Terrain(
        elevation_m=z,
        transform=transform,
        crs=crs if info.needs_warp or crs != info.horizontal_crs else info.horizontal_crs,
        source=str(info.path),
        read_window_px=_window_px(window),
        source_shape_px=(info.height_px, info.width_px),
        block_px=(bh, bw),
        blocks_read=mask,
    )
    if error_m > max(0.05 * terrain.cell_m, 0.005):
        raise DemError(
            f"DEM '{info.path}' is in {info.horizontal_crs.name} and the targets spread too far "
            f"to plan in one flat map ({error_m:.2f} m distortion): reproject the DEM to "
            "the local UTM zone (gdalwarp -t_srs) or plan fewer targets at a time"
        )
    return terrain


def _read_blocks(
    info: DemInfo,
    src: rasterio.io.DatasetReader,
    z: ElevationArray,
    window: rasterio.windows.Window,
    block_px: tuple[int, int],
    todo: npt.NDArray[np.bool_],
    cache: BlockCache | None = None,
) -> None:
    """Read the blocks ``todo`` marks into the grid ``z`` of ``window``, one at a time,
    taking (and dropping) from ``cache`` those whose cells it holds."""
    bh, bw = block_px
    c0, r0 = int(window.col_off), int(window.row_off)
    c1, r1 = c0 + int(window.width), r0 + int(window.height)
    first_r, first_c = r0 // bh * bh, c0 // bw * bw
    for j, i in np.argwhere(todo).tolist():
        br, bc = first_r + j * bh, first_c + i * bw
        a, b = max(bc, c0), max(br, r0)
        c, d = min(bc + bw, c1), min(br + bh, r1)
        if c <= a or d <= b:
            continue
        key = (br // bh, bc // bw)
        held = None if cache is None else cache.cells.pop(key, None)
        if held is not None:
            z[b - r0 : d - r0, a - c0 : c - c0] = held[b - br : d - br, a - bc : c - bc]
            continue
        if cache is not None:
            cache.again += key in cache.maxima
            cache.decompressed += 1
        band = src.read(info.band, window=rasterio.windows.Window(a, b, c - a, d - b), masked=True)
        z[b - r0 : d - r0, a - c0 : c - c0] = _clean(
            np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m
        )


def fill_along(info: DemInfo, terrain: Terrain, start_xy: FloatArray, end_xy: FloatArray) -> int:
    """Read into a mosaic from :func:`read_mosaic`, in place, the blocks that straight
    segments (within its grid) cross and it does not hold yet; return how many.

    Known ground only grows: every result computed on the terrain before stays valid.
    """
    if terrain.blocks_read is None:
        return 0
    a = np.asarray(start_xy, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(end_xy, dtype=np.float64).reshape(-1, 2)
    ca, ra = terrain.pixel_coords(a[:, 0], a[:, 1])
    cb, rb = terrain.pixel_coords(b[:, 0], b[:, 1])
    # Samples at most _STEP_PX apart, each widened by half a step and the bilinear support,
    # so every cell a segment's surface depends on lies in some sample's box.
    steps = np.maximum(np.ceil(np.hypot(cb - ca, rb - ra) / _STEP_PX), 1).astype(np.int64)
    k = np.repeat(np.arange(len(a)), steps + 1)
    t = np.concatenate([np.linspace(0.0, 1.0, n + 1) for n in steps.tolist()])
    cols = ca[k] + t * (cb - ca)[k]
    rows = ra[k] + t * (rb - ra)[k]
    keep = np.isfinite(cols) & np.isfinite(rows)
    cols, rows = cols[keep], rows[keep]
    bh, bw = terrain.block_px
    c0, r0, width, height = terrain.read_window_px
    phase_c, phase_r = c0 - c0 // bw * bw, r0 - r0 // bh * bh
    todo = np.zeros_like(terrain.blocks_read)
    jmax, imax = todo.shape[0] - 1, todo.shape[1] - 1
    reach = _STEP_PX / 2.0 + 2.0
    for dc in (-reach, reach):
        for dr in (-reach, reach):
            cc = np.clip(cols + dc, 0, width - 1) + phase_c
            rr = np.clip(rows + dr, 0, height - 1) + phase_r
            i = np.clip((cc // bw).astype(np.intp), 0, imax)
            j = np.clip((rr // bh).astype(np.intp), 0, jmax)
            todo[j, i] = True
    todo &= ~terrain.blocks_read
    count = int(todo.sum())
    if count:
        window = rasterio.windows.Window(c0, r0, width, height)
        try:
            with _open(info.path) as src:
                _read_blocks(info, src, terrain.elevation_m, window, (bh, bw), todo)
        except rasterio.errors.RasterioError as exc:
            raise DemError(
                f"DEM '{info.path}' could not be read ({_first_line(exc)}): "
                "the file may be truncated; export it again"
            ) from exc
        terrain.blocks_read[todo] = True
    return count


_STEP_PX = 32.0


def sample_points(info: DemInfo, crs: pyproj.CRS, xy: FloatArray) -> FloatArray:
    """Bilinear ground elevation (metres) at points in ``crs``, each from the few cells
    around it; NaN off the raster or next to nodata."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    sx, sy = pts[:, 0], pts[:, 1]
    if info.needs_warp or crs != info.horizontal_crs:
        to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
        sx, sy = (np.asarray(v, dtype=np.float64) for v in to_src.transform(sx, sy))
    inv = ~info.transform
    cols = inv.a * sx + inv.b * sy + inv.c
    rows = inv.d * sx + inv.e * sy + inv.f
    out = np.full(len(pts), np.nan)
    try:
        with _open(info.path) as src:
            for k in range(len(pts)):
                if not (np.isfinite(cols[k]) and np.isfinite(rows[k])):
                    continue
                c0 = max(math.floor(cols[k]) - 2, 0)
                r0 = max(math.floor(rows[k]) - 2, 0)
                c1 = min(math.floor(cols[k]) + 3, info.width_px)
                r1 = min(math.floor(rows[k]) + 3, info.height_px)
                if c1 <= c0 or r1 <= r0:
                    continue
                window = rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0)
                band = src.read(info.band, window=window, masked=True)
                z = _clean(np.ma.getdata(band), np.ma.getmaskarray(band), info.vertical_unit.to_m)
                out[k] = bilinear_at(z, cols[k] - c0 - 0.5, rows[k] - r0 - 0.5)
    except rasterio.errors.RasterioError as exc:
        raise DemError(
            f"DEM '{info.path}' could not be read ({_first_line(exc)}): "
            "the file may be truncated; export it again"
        ) from exc
    return out


@njit(cache=True, nogil=True)
def bilinear_at(z, col, row):  # type: ignore[no-untyped-def]
    """The surface at fractional (col, row) of ``z`` (pixel centres at whole numbers), as
    :meth:`Terrain.sample` gives it: the edge value beyond the outermost centres, NaN outside
    the grid or when any of the four corners is nodata. Compiled, for kernels and single
    points alike."""
    rows, cols = z.shape
    if not (-0.5 <= col <= cols - 0.5 and -0.5 <= row <= rows - 0.5):
        return math.nan
    col = min(max(col, 0.0), cols - 1.0)
    row = min(max(row, 0.0), rows - 1.0)
    c0 = min(math.floor(col), max(cols - 2, 0))
    r0 = min(math.floor(row), max(rows - 2, 0))
    c1, r1 = min(c0 + 1, cols - 1), min(r0 + 1, rows - 1)
    fc, fr = col - c0, row - r0
    top = z[r0, c0] * (1.0 - fc) + z[r0, c1] * fc
    bottom = z[r1, c0] * (1.0 - fc) + z[r1, c1] * fc
    return top * (1.0 - fr) + bottom * fr
