"""The first two stages: the site placed on the DEM, and the area of the DEM planned on.

:func:`read_site` reads the targets and the DEM's description, picks home and the planning CRS
(:class:`SiteInputs`); :func:`read_area` reads the window of the DEM the camera cones need and
fixes the flight plane over it (:class:`PlanArea`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.memory import require_memory
from urpt_gcs.pipeline.checks import (
    check_cone_width,
    check_ground,
    check_gsd,
    check_swapped,
    require_window,
)
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.instance import instance_bytes
from urpt_gcs.site.dem import WGS84, DemInfo, open_dem, planning_crs
from urpt_gcs.site.reading import BlockCache, area_max, read_mosaic, sample_points
from urpt_gcs.site.targets import TargetSet, check_names, read_targets
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import Camera

# Extra DEM read around the operating area, in cells, so bilinear samples at its edge exist.
_WINDOW_MARGIN_CELLS = 4


@dataclass(frozen=True, slots=True)
class SiteInputs:
    """The targets and home, placed in the planning CRS.

    Not :class:`urpt_gcs.flight.refinement.Site`, which is what refinement checks a stop
    against (built from this and a :class:`PlanArea`).

    Attributes
    ----------
    targets
        The targets as read, in file order.
    dem
        The DEM's description (its CRS, grid and units; no elevations read).
    crs
        The planning CRS: metres, conformal around the site.
    names
        Each target's name, in file order.
    targets_xy
        Each target's position in ``crs``, shape (targets, 2).
    home_lat_lon
        Home, WGS84 degrees.
    home_xy
        Home in ``crs``.
    home_source
        Where home came from (``--home``, a placemark, the targets' centroid), for messages.
    """

    targets: TargetSet
    dem: DemInfo
    crs: pyproj.CRS
    names: list[str]
    targets_xy: FloatArray
    home_lat_lon: tuple[float, float]
    home_xy: tuple[float, float]
    home_source: str


@dataclass(frozen=True, slots=True)
class PlanArea:
    """The DEM window planned on, the ground under the points and the flight plane.

    Attributes
    ----------
    terrain
        The DEM read where the camera cones need it, in the planning CRS (filled further
        along the legs as they are checked).
    ground_m
        The ground elevation under each target, metres above the DEM's vertical datum.
    home_ground_m
        The ground elevation at home.
    terrain_max_m
        The highest terrain of the operating area.
    camera
        The camera at the flight plane's altitude.
    """

    terrain: Terrain
    ground_m: FloatArray
    home_ground_m: float
    terrain_max_m: float
    camera: Camera


def read_site(dem_path: Path, targets_path: Path | TargetSet, settings: PlanSettings) -> SiteInputs:
    """Read the targets and the DEM's description; place them in the planning CRS.

    Parameters
    ----------
    dem_path
        GeoTIFF DSM/DEM of the site.
    targets_path
        KML/KMZ, GeoJSON or CSV of the targets, or the targets already read.
    settings
        The plan's settings (``home``, ``band``, ``samples`` for the memory check).

    Returns
    -------
    SiteInputs
        The targets and home in the planning CRS chosen for them.

    Raises
    ------
    urpt_gcs.errors.UrptError
        A target file or DEM that cannot be read, a point off the DEM or with lat and lon
        swapped, or more targets than the memory budget holds.
    """
    if isinstance(targets_path, TargetSet):
        targets = check_names(targets_path)
    else:
        targets = read_targets(targets_path)
    # Every target offers its nadir and a viewpoint per azimuth, each seeing at least its own
    # target, and the tour records which targets each stop sees (a stop per target at most):
    # refuse, before any work, a target count whose instance and tour could not fit.
    m = len(targets.targets)
    n = m * (settings.samples + 1)
    require_memory(
        instance_bytes(n, n) + float(m) * float(m),
        f"{m} targets in {targets.source!r} at --samples {settings.samples}: "
        f"{n} viewpoints, their cover sets and the tour's stop-by-target table",
        "plan fewer targets at a time (split the file) or use fewer --samples",
    )
    info = open_dem(dem_path, settings.band)
    home_lat, home_lon, home_source = _pick_home(targets, settings)
    check_swapped(info, targets, (home_lat, home_lon), home_source)
    lat_lon = [(t.lat_deg, t.lon_deg) for t in targets.targets]
    lats = [p[0] for p in lat_lon] + [home_lat]
    lons = [p[1] for p in lat_lon] + [home_lon]
    crs = planning_crs(info, (min(lons), min(lats), max(lons), max(lats)))
    home_xy = latlon_to_xy(crs, [(home_lat, home_lon)])[0]
    return SiteInputs(
        targets=targets,
        dem=info,
        crs=crs,
        names=[t.name for t in targets.targets],
        targets_xy=latlon_to_xy(crs, lat_lon),
        home_lat_lon=(home_lat, home_lon),
        home_xy=(float(home_xy[0]), float(home_xy[1])),
        home_source=home_source,
    )


def read_area(site: SiteInputs, settings: PlanSettings) -> PlanArea:
    """Read the DEM where the camera cones need it and fix the flight plane.

    Without ``--altitude`` the plane sits ``--clearance`` above the highest terrain of the
    operating area (the box of the points widened by the widest cone), found one block at a
    time; a higher plane widens the cones, which may widen the area: repeat until it holds
    them. Then only the source blocks the cone of some target (or home) touches are read.

    Parameters
    ----------
    site
        The site, from :func:`read_site`.
    settings
        The plan's settings (camera, ``altitude_m`` or ``clearance_m``, limits).

    Returns
    -------
    PlanArea
        The DEM window, the ground under the points and the camera on the flight plane.

    Raises
    ------
    urpt_gcs.errors.UrptError
        A point on nodata, a plane at or under the terrain, a window over the memory
        budget, or a camera cone too narrow or too high for ``--gsd``.
    """
    info, crs = site.dem, site.crs
    points_xy = np.vstack([site.targets_xy, np.array([site.home_xy])])
    tan = settings.camera_at(0.0).tan_fov
    cell_m = _cell_m(info, crs, points_xy)
    margin = _WINDOW_MARGIN_CELLS * cell_m
    # The ground under the points first, from the few cells around each.
    ground = check_ground(
        info,
        sample_points(info, crs, points_xy, settings.workers),
        [*(f"target '{n}'" for n in site.names), f"home ({site.home_source})"],
        [*((t.lat_deg, t.lon_deg) for t in site.targets.targets), site.home_lat_lon],
    )[:-1]

    def cone_boxes(altitude_m: float) -> FloatArray:
        cones = np.maximum(altitude_m - ground, 0.0) * tan
        return _boxes(points_xy, np.append(cones, 0.0) + margin)

    # The plane only rises from pass to pass, and the cones widen with it: blocks inside the
    # cones of the lowest plane possible so far are kept as read, for the mosaic.
    altitude = (
        settings.altitude_m
        if settings.altitude_m is not None
        else float(ground.max()) + settings.clearance_m
    )
    cache = BlockCache(info)
    area = _bbox(points_xy, 0.0)
    top = area_max(info, crs, area, cache, cone_boxes(altitude), settings.workers)
    for _ in range(12):
        altitude = (
            settings.altitude_m if settings.altitude_m is not None else (top + settings.clearance_m)
        )
        reach = max(altitude - float(ground.min()), 0.0) * tan
        need = _bbox(points_xy, reach + margin)
        if _contains(area, need):
            break
        require_window(info, cell_m, need, altitude, settings)
        area = need
        top = area_max(info, crs, area, cache, cone_boxes(altitude), settings.workers)
    terrain = read_mosaic(info, crs, cone_boxes(altitude), cache)
    # Heights from the grid planned on: a geographic DEM's fitted georeferencing differs
    # slightly from one grid to the next, and every line of sight ends on the target.
    all_ground = terrain.sample(points_xy[:, 0], points_xy[:, 1])
    ground, home_ground = all_ground[:-1], float(all_ground[-1])
    low = np.flatnonzero(ground >= altitude)
    if low.size:
        i = int(low[0])
        raise SettingsError.about(
            "{altitude_m} {altitude:g} m is at or below the terrain at target '{name}' "
            "({ground:.1f} m): raise it above {top:.1f} m or use {clearance_m}",
            altitude=altitude,
            name=site.names[i],
            ground=ground[i],
            top=float(ground.max()),
        )
    if home_ground >= altitude:
        raise SettingsError.about(
            "{altitude_m} {altitude:g} m is at or below the ground at home ({ground:.1f} m): "
            "raise it or use {clearance_m}",
            altitude=altitude,
            ground=home_ground,
        )
    camera = settings.camera_at(altitude)
    check_gsd(camera, ground, site.names)
    check_cone_width(camera, ground, site.names, settings.position_tolerance_m)
    return PlanArea(terrain, ground, home_ground, top, camera)


def read_band_area(site: SiteInputs, settings: PlanSettings) -> PlanArea:
    """Read the DEM for a flight inside the height band (``--agl``): where the cones of a
    plane at the band's ceiling over the highest terrain reach, which holds every point the
    band allows that can see a target.

    Parameters
    ----------
    site
        The site, from :func:`read_site`.
    settings
        The plan's settings; ``agl_band_m`` gives the band.

    Returns
    -------
    PlanArea
        The DEM window and the ground under the points; its camera's altitude is that plane's
        (the band's cameras take their height from each viewpoint).
    """
    assert settings.agl_band_m is not None
    ceiling = settings.agl_band_m[1]
    # The GSD caps what one photo sees from each viewpoint's own height, not the plane's.
    wide = dataclasses.replace(settings, altitude_m=None, clearance_m=ceiling, gsd_cm=None)
    area = read_area(site, wide)
    return dataclasses.replace(area, camera=settings.camera_at(area.camera.altitude_m))


def site_fields(site: SiteInputs, area: PlanArea) -> dict[str, Any]:
    """The fields of a :class:`~urpt_gcs.pipeline.result.Plan` that the site and the area
    planned on give (the DEM, the targets, home, the camera), by name."""
    return {
        "dem": site.dem,
        "terrain": area.terrain,
        "targets": site.targets,
        "crs": site.crs,
        "targets_xy": site.targets_xy,
        "ground_m": area.ground_m,
        "home_xy": site.home_xy,
        "home_ground_m": area.home_ground_m,
        "home_source": site.home_source,
        "camera": area.camera,
        "terrain_max_m": area.terrain_max_m,
    }


def altitude_rel(area: PlanArea) -> float:
    """The plane's height above home as written: centimetres, rounded up, since a higher eye
    only widens the cone and lifts every line of sight, so nothing checked is lost.

    Parameters
    ----------
    area
        The area planned on (its camera's altitude and the ground at home).

    Returns
    -------
    float
        Metres above home, as the mission writes it.
    """
    return math.ceil((area.camera.altitude_m - area.home_ground_m) * 100.0) / 100.0


def latlon_to_xy(crs: pyproj.CRS, lat_lon: list[tuple[float, float]]) -> FloatArray:
    """WGS84 points in the planning CRS.

    Parameters
    ----------
    crs
        The planning CRS.
    lat_lon
        (lat, lon) pairs, degrees.

    Returns
    -------
    FloatArray
        Shape (points, 2): x, y in ``crs``.
    """
    to_xy = pyproj.Transformer.from_crs(WGS84, crs, always_xy=True)
    x, y = to_xy.transform([p[1] for p in lat_lon], [p[0] for p in lat_lon])
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y)]).astype(np.float64)


def xy_to_latlon(crs: pyproj.CRS, xy: FloatArray) -> list[tuple[float, float]]:
    """Points of the planning CRS in WGS84.

    Parameters
    ----------
    crs
        The planning CRS.
    xy
        Shape (points, 2): x, y in ``crs``.

    Returns
    -------
    list of (float, float)
        (lat, lon) of each point, degrees.
    """
    to_geo = pyproj.Transformer.from_crs(crs, WGS84, always_xy=True)
    lon, lat = to_geo.transform(xy[:, 0], xy[:, 1])
    return list(zip(np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist(), strict=True))


def _pick_home(targets: TargetSet, settings: PlanSettings) -> tuple[float, float, str]:
    if settings.home is not None:
        return settings.home[0], settings.home[1], "--home"
    if targets.home is not None:
        return targets.home.lat_deg, targets.home.lon_deg, f"placemark '{targets.home.name}'"
    lat = float(np.mean([t.lat_deg for t in targets.targets]))
    lon = float(np.mean([t.lon_deg for t in targets.targets]))
    return lat, lon, "centroid of the targets (no Home placemark and no --home given)"


def _bbox(xy: FloatArray, pad: float) -> tuple[float, float, float, float]:
    lo = xy.min(axis=0) - pad
    hi = xy.max(axis=0) + pad
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _contains(
    outer: tuple[float, float, float, float], inner: tuple[float, float, float, float]
) -> bool:
    return (
        outer[0] <= inner[0]
        and outer[1] <= inner[1]
        and outer[2] >= inner[2]
        and outer[3] >= inner[3]
    )


def _boxes(xy: FloatArray, radius_m: FloatArray) -> FloatArray:
    """Boxes (xmin, ymin, xmax, ymax) around points, ``radius_m`` out on every side."""
    r = np.asarray(radius_m, dtype=np.float64)
    return np.column_stack([xy[:, 0] - r, xy[:, 1] - r, xy[:, 0] + r, xy[:, 1] + r])


def _cell_m(info: DemInfo, crs: pyproj.CRS, points_xy: FloatArray) -> float:
    """The DEM's cell size in metres in the planning CRS near the points."""
    t = info.transform
    if not (info.needs_warp or crs != info.horizontal_crs):
        return float(min(abs(t.a), abs(t.e)))
    to_src = pyproj.Transformer.from_crs(crs, info.horizontal_crs, always_xy=True)
    to_crs = pyproj.Transformer.from_crs(info.horizontal_crs, crs, always_xy=True)
    sx, sy = to_src.transform(float(points_xy[0, 0]), float(points_xy[0, 1]))
    x0, y0 = to_crs.transform(sx, sy)
    x1, y1 = to_crs.transform(sx + t.a, sy)
    x2, y2 = to_crs.transform(sx, sy + t.e)
    return float(min(math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x0, y2 - y0)))


__all__ = [
    "PlanArea",
    "SiteInputs",
    "altitude_rel",
    "latlon_to_xy",
    "read_area",
    "read_band_area",
    "read_site",
    "site_fields",
    "xy_to_latlon",
]
