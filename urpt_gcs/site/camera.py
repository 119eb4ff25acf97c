"""Cameras as operators specify them: a rectangular sensor behind a lens, and presets.

A frame is what :class:`urpt_gcs.visibility.regions.Camera` turns by the vehicle's heading; this
module holds only the figures (no terrain, nothing compiled), so mission files and their
checks can name a camera without the planning machinery.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyproj

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import SettingsError

__all__ = [
    "CAMERAS",
    "CameraPreset",
    "Frame",
    "camera_preset",
    "frame_from_flags",
    "grid_bearing_deg",
    "true_bearing_deg",
]


@dataclass(frozen=True, slots=True)
class Frame:
    """A rectangular sensor behind a lens, as camera makers specify it.

    On a nadir gimbal the sensor's width (its long side) lies across the vehicle and its
    height along the heading, as the photo's top edge points where the vehicle points.
    """

    sensor_w_mm: float
    sensor_h_mm: float
    focal_mm: float
    image_w_px: int
    image_h_px: int

    def __post_init__(self) -> None:
        # The messages name the settings (``sensor``, ``focal``, ``image``); the CLI shows
        # their flags (SettingsError.naming).
        for name, value in (
            ("{sensor} width", self.sensor_w_mm),
            ("{sensor} height", self.sensor_h_mm),
            ("{focal}", self.focal_mm),
        ):
            if not (math.isfinite(value) and 0.0 < value <= 200.0):
                raise SettingsError.about(
                    name + " {value} mm is out of range: give 0 to 200 mm", value=value
                )
        for name, pixels in (
            ("{image} width", self.image_w_px),
            ("{image} height", self.image_h_px),
        ):
            if not 1 <= pixels <= 1_000_000:
                raise SettingsError.about(
                    name + " {value} px is out of range: give 1 to 1000000 px", value=pixels
                )
        if self.diagonal_tan >= _MAX_DIAGONAL_TAN:
            raise SettingsError.about(
                "a {w:g} x {h:g} mm sensor behind a {f:g} mm lens sees more than 170 degrees "
                "across its diagonal: check {sensor} and {focal} (millimetres)",
                w=self.sensor_w_mm,
                h=self.sensor_h_mm,
                f=self.focal_mm,
            )

    @property
    def half_tan_across(self) -> float:
        """tan of the half-angle across the vehicle (the sensor's width)."""
        return self.sensor_w_mm / (2.0 * self.focal_mm)

    @property
    def half_tan_along(self) -> float:
        """tan of the half-angle along the heading (the sensor's height)."""
        return self.sensor_h_mm / (2.0 * self.focal_mm)

    @property
    def diagonal_tan(self) -> float:
        """tan of the angle from nadir to the frame's corner."""
        return math.hypot(self.half_tan_across, self.half_tan_along)

    @property
    def pixel_pitch_mm(self) -> float:
        """The coarser of the two pixel pitches (a non-square pixel counts by its long side)."""
        return max(self.sensor_w_mm / self.image_w_px, self.sensor_h_mm / self.image_h_px)

    def gsd_cm(self, distance_m: npt.ArrayLike) -> FloatArray:
        """Ground covered by one pixel at ``distance_m`` from the lens, in centimetres."""
        d = np.asarray(distance_m, dtype=np.float64)
        out: FloatArray = d * self.pixel_pitch_mm / self.focal_mm * 100.0
        return out

    def distance_for_gsd_m(self, gsd_cm: float) -> float:
        """The farthest distance from the lens at which one pixel covers ``gsd_cm``."""
        return gsd_cm / 100.0 * self.focal_mm / self.pixel_pitch_mm


# A frame wider than this across its diagonal (170 degrees) is a unit mistake, not a lens.
_MAX_DIAGONAL_TAN = math.tan(math.radians(85.0))


@dataclass(frozen=True, slots=True)
class CameraPreset:
    """A camera model: its frame and where each figure comes from."""

    name: str
    description: str
    frame: Frame
    source: str


CAMERAS: dict[str, CameraPreset] = {
    preset.name: preset
    for preset in (
        CameraPreset(
            "phantom4rtk",
            "DJI Phantom 4 RTK (FC6310R, 1-inch CMOS, 20 MP)",
            Frame(13.2, 8.8, 8.8, 5472, 3648),
            "DJI Phantom 4 RTK specifications: 1-inch CMOS, 20 MP, lens FOV 84 deg, "
            "8.8 mm (24 mm equivalent), image size 3:2 5472 x 3648; 13.2 x 8.8 mm is the "
            "1-inch type's active area (pixel 2.41 um, GSD = H/36.5 as DJI states)",
        ),
        CameraPreset(
            "mavic3e",
            "DJI Mavic 3 Enterprise wide camera (4/3 CMOS, 20 MP)",
            Frame(17.3, 13.0, 12.29, 5280, 3956),
            "DJI Mavic 3 Enterprise specifications: wide camera 4/3 CMOS, 20 MP, lens FOV "
            "84 deg, 24 mm equivalent, image size 5280 x 3956; 17.3 x 13.0 mm is the Four "
            "Thirds active area, 12.29 mm the focal length the camera writes to its EXIF",
        ),
    )
}


def camera_preset(name: str) -> CameraPreset:
    """The preset called ``name``, or an error listing those there are."""
    try:
        return CAMERAS[name.lower()]
    except KeyError:
        raise SettingsError.about(
            "{camera} {value!r} is not known: use one of {known}, or give {sensor} WxH "
            "{focal} F {image} WxH",
            value=name,
            known=", ".join(sorted(CAMERAS)),
        ) from None


def _pair(setting: str, text: str, unit: str) -> tuple[float, float]:
    parts = text.lower().replace("×", "x").replace(unit, "").split("x")
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise SettingsError.about(
            "{" + setting + "} {value!r} is not WIDTHxHEIGHT in {unit}: write it like 13.2x8.8",
            value=text,
            unit=unit,
        ) from None
    return a, b


def frame_from_flags(
    camera: str | None, sensor: str | None, focal_mm: float | None, image: str | None
) -> Frame | None:
    """The frame the settings ``camera`` (a name) or ``sensor`` (WxH mm), ``focal`` (mm) and
    ``image`` (WxH px) describe (None: neither was given, the camera is the cone of
    ``fov_deg``). Its errors name those settings; the CLI shows their flags."""
    custom = [
        "{" + name + "}"
        for name, v in (("sensor", sensor), ("focal", focal_mm), ("image", image))
        if v is not None
    ]
    if camera is not None:
        if custom:
            raise SettingsError.about(
                "{camera} {value} and " + ", ".join(custom) + " both describe the camera: give one",
                value=camera,
            )
        return camera_preset(camera).frame
    if not custom:
        return None
    if sensor is None or focal_mm is None or image is None:
        missing = [f for f in ("{sensor}", "{focal}", "{image}") if f not in custom]
        raise SettingsError.about(
            ", ".join(custom) + " without " + ", ".join(missing) + ": a frame camera needs "
            "{sensor} WxH (mm), {focal} F (mm) and {image} WxH (px)"
        )
    w_mm, h_mm = _pair("sensor", sensor, "mm")
    w_px, h_px = _pair("image", image, "px")
    if not (float(w_px).is_integer() and float(h_px).is_integer()):
        raise SettingsError.about(
            "{image} {value!r} must be whole pixels, like 5472x3648", value=image
        )
    return Frame(w_mm, h_mm, focal_mm, int(w_px), int(h_px))


def true_bearing_deg(crs: pyproj.CRS, xy: FloatArray, grid_deg: npt.ArrayLike) -> FloatArray:
    """The true bearing (clockwise from north, in [0, 360)) of grid bearing ``grid_deg`` at
    the points ``xy`` of ``crs``: they differ by the grid's meridian convergence, up to a few
    degrees in UTM."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    psi = np.radians(np.broadcast_to(np.asarray(grid_deg, dtype=np.float64), (len(pts),)))
    ahead = pts + 100.0 * np.column_stack([np.sin(psi), np.cos(psi)])
    to_geo = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon0, lat0 = to_geo.transform(pts[:, 0], pts[:, 1])
    lon1, lat1 = to_geo.transform(ahead[:, 0], ahead[:, 1])
    azimuth, _, _ = pyproj.Geod(ellps="WGS84").inv(lon0, lat0, lon1, lat1)
    out: FloatArray = np.asarray(azimuth, dtype=np.float64) % 360.0
    return out


def grid_bearing_deg(crs: pyproj.CRS, xy: FloatArray, true_deg: npt.ArrayLike) -> FloatArray:
    """The grid bearing of true bearing ``true_deg`` at ``xy`` (the inverse of
    :func:`true_bearing_deg`, to far below a hundredth of a degree)."""
    convergence = true_bearing_deg(crs, xy, 0.0)
    out: FloatArray = (np.asarray(true_deg, dtype=np.float64) - convergence) % 360.0
    return out
