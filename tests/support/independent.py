"""An independent check of a planned mission against the DEM.

It shares no code with ``urpt_gcs``: it reads the raster itself with rasterio, in the raster's
own CRS (no warping), interpolates with scipy's ``map_coordinates`` and measures ground
distances on the WGS84 ellipsoid with pyproj's ``Geod``. The mission comes from the written
``.waypoints`` file, read with pymavlink's loader.

Each NAV_WAYPOINT flies at its own height above home (line 0's AMSL plus its relative z), so
a mission that follows the terrain inside a height band reads as one on a flight plane does;
only the waypoints a photo item (DO_DIGICAM_CONTROL or IMAGE_START_CAPTURE) follows take a
photo. :func:`band_excursions` samples every written leg against the surface for the band.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
import rasterio
from pymavlink import mavutil, mavwp
from scipy.ndimage import map_coordinates

__all__ = [
    "GEOD",
    "BandExcursions",
    "FlownMission",
    "FrameCamera",
    "Raster",
    "band_excursions",
    "check_mission",
    "leg_clearances",
    "load_raster",
    "read_waypoints_file",
    "sees",
    "sees_in_frame",
]

GEOD = pyproj.Geod(ellps="WGS84")
# The items that take a photo at the NAV_WAYPOINT before them.
PHOTO_COMMANDS = (
    mavutil.mavlink.MAV_CMD_DO_DIGICAM_CONTROL,
    mavutil.mavlink.MAV_CMD_IMAGE_START_CAPTURE,
)


@dataclass
class Raster:
    z: np.ndarray
    transform: rasterio.Affine
    to_src: pyproj.Transformer
    cell: float  # in the raster's units

    def height(self, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        x, y = self.to_src.transform(lon, lat)
        col = (np.asarray(x) - self.transform.c) / self.transform.a - 0.5
        row = (np.asarray(y) - self.transform.f) / self.transform.e - 0.5
        return map_coordinates(
            self.z, [row, col], order=1, mode="constant", cval=np.nan, prefilter=False
        )


def load_raster(path: Path) -> Raster:
    with rasterio.open(path) as src:
        band = src.read(1, masked=True).astype(np.float64)
        z = band.filled(np.nan)
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt())
        if crs.is_compound:
            crs = crs.sub_crs_list[0]
        return Raster(
            z=z,
            transform=src.transform,
            to_src=pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True),
            cell=min(abs(src.transform.a), abs(src.transform.e)),
        )


@dataclass
class FlownMission:
    home: tuple[float, float, float]  # lat, lon, AMSL
    waypoints: list[tuple[float, float, float]]  # every NAV_WAYPOINT: lat, lon, AMSL
    # The heading each waypoint's photo is taken at (true, degrees; None: not commanded).
    headings: list[float | None] | None = None
    # Per waypoint, whether a photo item follows it (None: every waypoint takes one).
    photos: list[bool] | None = None
    # The take-off's height above home (None: the first waypoint's).
    takeoff_rel_m: float | None = None

    @property
    def photo_waypoints(self) -> list[tuple[float, float, float]]:
        """The waypoints a photo is taken at, in flight order."""
        flags = self.photos or [True] * len(self.waypoints)
        return [w for w, f in zip(self.waypoints, flags, strict=True) if f]

    @property
    def photo_headings(self) -> list[float | None]:
        """The heading of each photo waypoint's photo (None: not commanded)."""
        flags = self.photos or [True] * len(self.waypoints)
        headings = self.headings or [None] * len(self.waypoints)
        return [h for h, f in zip(headings, flags, strict=True) if f]

    @property
    def takeoff_amsl_m(self) -> float:
        """The height the vehicle climbs to over home before the first leg (AMSL)."""
        if self.takeoff_rel_m is not None:
            return self.home[2] + self.takeoff_rel_m
        return self.waypoints[0][2]

    def path(self) -> list[tuple[float, float, float]]:
        """Every point flown through: over home at the take-off height, every waypoint, and
        back over home (at the take-off height, unless the last waypoint is over home)."""
        over_home = (self.home[0], self.home[1], self.takeoff_amsl_m)
        points = [over_home, *self.waypoints]
        last = self.waypoints[-1] if self.waypoints else over_home
        _, _, back = GEOD.inv(last[1], last[0], self.home[1], self.home[0])
        if back > 0.01:
            points.append(over_home)
        return points


@dataclass
class FrameCamera:
    """A nadir frame camera: the sensor's width across the vehicle, its height along it."""

    sensor_w_mm: float
    sensor_h_mm: float
    focal_mm: float
    image_w_px: int
    image_h_px: int
    gsd_cm: float | None = None


def read_waypoints_file(path: Path) -> FlownMission:
    loader = mavwp.MAVWPLoader()
    loader.load(str(path))
    items = [loader.wp(i) for i in range(loader.count())]
    home = items[0]
    assert home.frame == mavutil.mavlink.MAV_FRAME_GLOBAL
    wps = []
    headings: list[float | None] = []
    photos: list[bool] = []
    takeoff: float | None = None
    pending: float | None = None
    for w in items[1:]:
        if w.command == mavutil.mavlink.MAV_CMD_CONDITION_YAW and w.param4 == 0:
            pending = float(w.param1)
        if w.command == mavutil.mavlink.MAV_CMD_NAV_TAKEOFF and takeoff is None:
            assert w.frame == mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
            takeoff = float(w.z)
        if w.command == mavutil.mavlink.MAV_CMD_NAV_WAYPOINT:
            assert w.frame == mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, w.frame
            wps.append((w.x, w.y, home.z + w.z))
            headings.append(pending)
            photos.append(False)
            pending = None
        if w.command in PHOTO_COMMANDS and photos:
            photos[-1] = True
    return FlownMission(
        home=(home.x, home.y, home.z),
        waypoints=wps,
        headings=headings,
        photos=photos,
        takeoff_rel_m=takeoff,
    )


def sees_in_frame(
    raster: Raster,
    target: tuple[float, float],
    eye: tuple[float, float, float],
    heading_deg: float,
    camera: FrameCamera,
) -> tuple[bool, str]:
    """Whether a photo from eye=(lat, lon, AMSL) with the vehicle heading ``heading_deg``
    (true north) holds target=(lat, lon) inside its frame, within the GSD distance, in sight.

    Offsets come from the geodesic from the eye to the target: its true azimuth against the
    heading gives the parts along and across the vehicle."""
    z_t = float(raster.height(np.array([target[1]]), np.array([target[0]]))[0])
    if not math.isfinite(z_t):
        return False, "target on unknown ground"
    azimuth, _, dist = GEOD.inv(eye[1], eye[0], target[1], target[0])
    h = eye[2] - z_t
    turn = math.radians(azimuth - heading_deg)
    along, across = dist * math.cos(turn), dist * math.sin(turn)
    half_along = h * camera.sensor_h_mm / (2.0 * camera.focal_mm)
    half_across = h * camera.sensor_w_mm / (2.0 * camera.focal_mm)
    if abs(along) > half_along * 1.001 + 0.01 or abs(across) > half_across * 1.001 + 0.01:
        return False, (
            f"outside the frame (along {along:.2f}/{half_along:.2f} m, across "
            f"{across:.2f}/{half_across:.2f} m)"
        )
    if camera.gsd_cm is not None:
        pitch = max(camera.sensor_w_mm / camera.image_w_px, camera.sensor_h_mm / camera.image_h_px)
        gsd = math.hypot(dist, h) * pitch / camera.focal_mm * 100.0
        if gsd > camera.gsd_cm * 1.001:
            return False, f"too coarse ({gsd:.2f} cm/px > {camera.gsd_cm:g})"
    return sees(raster, target, eye, 89.9)


def _segment(
    raster: Raster,
    a: tuple[float, float],
    b: tuple[float, float],
    metres: float,
    cells_per_sample: float = 0.125,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """lon, lat and fraction t of dense samples from a=(lat, lon) to b."""
    xa, ya = raster.to_src.transform(a[1], a[0])
    xb, yb = raster.to_src.transform(b[1], b[0])
    length_cells = math.hypot(xb - xa, yb - ya) / raster.cell
    n = max(int(length_cells / cells_per_sample), 2) + 1
    t = np.linspace(0.0, 1.0, n)
    lon = a[1] + (b[1] - a[1]) * t
    lat = a[0] + (b[0] - a[0]) * t
    return lon, lat, t


def sees(
    raster: Raster, target: tuple[float, float], eye: tuple[float, float, float], fov_deg: float
) -> tuple[bool, str]:
    """Whether a camera at eye=(lat, lon, AMSL) sees target=(lat, lon) on the ground."""
    z_t = float(raster.height(np.array([target[1]]), np.array([target[0]]))[0])
    if not math.isfinite(z_t):
        return False, "target on unknown ground"
    _, _, dist = GEOD.inv(target[1], target[0], eye[1], eye[0])
    cone = (eye[2] - z_t) * math.tan(math.radians(fov_deg))
    if dist > cone * 1.001 + 0.01:
        return False, f"outside the cone ({dist:.2f} m > {cone:.2f} m)"
    lon, lat, t = _segment(raster, target, eye[:2], dist)
    inner = (t > 0.0) & (t < 1.0)
    ground = raster.height(lon[inner], lat[inner])
    line = z_t + (eye[2] - z_t) * t[inner]
    above = ~(ground <= line + 1e-6)
    if above.any():
        k = int(np.argmax(above))
        return False, f"blocked at t={t[inner][k]:.3f} (ground {ground[k]:.2f} > {line[k]:.2f})"
    return True, ""


def check_mission(
    dem: Path,
    waypoints_file: Path | list[Path],
    targets: list[tuple[str, float, float]],
    fov_deg: float,
    min_clearance_m: float = 0.0,
    frame: FrameCamera | None = None,
) -> list[str]:
    """Every problem found: unseen targets and legs that clip the terrain. Several files are
    the sorties of one plan: together they must see every target. With a ``frame`` camera a
    target counts only inside the frame of a photo at its commanded heading."""
    raster = load_raster(dem)
    files = waypoints_file if isinstance(waypoints_file, list) else [waypoints_file]
    sorties = [read_waypoints_file(f) for f in files]
    assert sorties, "no mission file"
    # Only the waypoints that take a photo, each at its own altitude.
    eyes = [w for flown in sorties for w in flown.photo_waypoints]
    headings = [h for flown in sorties for h in flown.photo_headings]
    problems = []
    if not eyes:
        problems.append("no waypoint takes a photo")
    if frame is not None and None in headings:
        problems.append("a frame camera's mission leaves some photo's heading to the vehicle")
    for name, lat, lon in targets:
        reasons = []
        for eye, heading in zip(eyes, headings, strict=True):
            if frame is not None and heading is not None:
                ok, why = sees_in_frame(raster, (lat, lon), eye, heading, frame)
            else:
                ok, why = sees(raster, (lat, lon), eye, fov_deg)
            if ok:
                break
            reasons.append(why)
        else:
            problems.append(f"target {name} is seen from no waypoint: {sorted(set(reasons))[:3]}")
    for number, clearances in enumerate(leg_clearances(raster, sorties), start=1):
        for k, clearance in enumerate(clearances, start=1):
            if clearance < min_clearance_m:
                problems.append(
                    f"sortie {number} leg {k} passes {clearance:.2f} m over the terrain"
                )
    return problems


def _leg_heights(
    raster: Raster,
    a: tuple[float, float, float],
    b: tuple[float, float, float],
    cells_per_sample: float,
) -> np.ndarray:
    """Heights above the surface of dense samples of the straight leg from a to b (lat, lon,
    AMSL; the height linear in the horizontal fraction), nan over no data."""
    _, _, dist = GEOD.inv(a[1], a[0], b[1], b[0])
    lon, lat, t = _segment(raster, a[:2], b[:2], dist, cells_per_sample)
    line = a[2] + (b[2] - a[2]) * t
    result: np.ndarray = line - raster.height(lon, lat)
    return result


def leg_clearances(
    raster: Raster, sorties: list[FlownMission], cells_per_sample: float = 0.125
) -> list[list[float]]:
    """Per sortie, the least height of each leg (home, waypoints, home) above the terrain,
    from samples every ``cells_per_sample`` cells (nan over no data). Each waypoint is at its
    own altitude; on a flight plane every leg is at the plane's."""
    out = []
    for flown in sorties:
        legs = []
        for a, b in itertools.pairwise(flown.path()):
            h = _leg_heights(raster, a, b, cells_per_sample)
            known = h[np.isfinite(h)]
            legs.append(float(known.min()) if known.size else math.nan)
        out.append(legs)
    return out


@dataclass
class BandExcursions:
    """How a band mission's written legs lie against the surface, from dense samples.

    ``lowest_m`` and ``highest_m`` are the least and the greatest height above the surface
    sampled anywhere; ``outside`` names every leg that leaves [floor, ceiling] (or crosses
    no data), with how far."""

    lowest_m: float
    highest_m: float
    outside: list[str]
    legs: int


def band_excursions(
    dem: Path,
    waypoints_files: Path | list[Path],
    floor_m: float,
    ceiling_m: float,
    step_cells: float = 0.125,
    slack_m: float = 0.0,
) -> BandExcursions:
    """Sample every written leg (from over home at the take-off height, through every
    waypoint, back over home) every ``step_cells`` cells against the DSM; a leg is outside
    where some sample is more than ``slack_m`` below ``floor_m`` or above ``ceiling_m`` over
    the surface, or over no data."""
    raster = load_raster(dem)
    files = waypoints_files if isinstance(waypoints_files, list) else [waypoints_files]
    lowest, highest = math.inf, -math.inf
    outside: list[str] = []
    count = 0
    for number, path in enumerate(files, start=1):
        flown = read_waypoints_file(path)
        for k, (a, b) in enumerate(itertools.pairwise(flown.path()), start=1):
            count += 1
            h = _leg_heights(raster, a, b, step_cells)
            where = f"{Path(path).name} (sortie {number}) leg {k}"
            if not np.isfinite(h).all():
                outside.append(f"{where} crosses no data")
                h = h[np.isfinite(h)]
                if not h.size:
                    continue
            low, high = float(h.min()), float(h.max())
            lowest, highest = min(lowest, low), max(highest, high)
            if low < floor_m - slack_m or high > ceiling_m + slack_m:
                outside.append(f"{where} runs {low:.2f} to {high:.2f} m above the surface")
    return BandExcursions(lowest, highest, outside, count)
