"""Judge a replayed flight against the terrain: was every target seen, was clearance kept?

A target counts as photographed when some photo was taken from a position that sees it: the
target is inside the camera's nadir cone (half-angle ``fov``) and the straight line from the
camera to the target clears the DEM (:func:`urpt_gcs.visibility.line_of_sight`). Photo
positions are those CAMERA_FEEDBACK reported, at the altitude above home it reported plus the
planned home's ground elevation, so the DEM's vertical datum cancels out as in planning.

Clearance is measured along the cruise legs: between consecutive GLOBAL_POSITION_INT fixes
at the flight plane's altitude, the straight segment's least height above the DEM's bilinear
surface, exactly (:func:`urpt_gcs.segments.segment_profile`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyproj

from urpt_gcs.mission import Mission
from urpt_gcs.segments import segment_profile
from urpt_gcs.targets import read_targets
from urpt_gcs.terrain import WGS84, FloatArray, Terrain, open_dem, planning_crs, read_terrain
from urpt_gcs.visibility import line_of_sight

if TYPE_CHECKING:
    from urpt_gcs.sitl.replay import Flight, ReplaySettings

# Photo positions are on MAVLink's 1e-7 degree grid (about 1 cm): allow that on the cone.
CONE_TOLERANCE_M = 0.02
# Fixes within this of the planned altitude are on a cruise leg.
CRUISE_BAND_M = 0.5
# Terrain read around the points, so bilinear samples at the edge exist.
TERRAIN_MARGIN_M = 10.0


@dataclass(frozen=True, slots=True)
class TargetSeen:
    """Which photo saw a target (``photo`` None if none did), and why not if not."""

    name: str
    photo: int | None
    offset_m: float | None
    reason: str = ""


@dataclass(frozen=True, slots=True)
class ReplayReport:
    """The verdict on one replayed flight."""

    plan: str
    flight: Flight
    targets: tuple[TargetSeen, ...]
    min_clearance_m: float | None
    required_clearance_m: float
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """True when every target was seen and the clearance was kept."""
        return not self.problems


def _xy(transformer: pyproj.Transformer, lat: list[float], lon: list[float]) -> FloatArray:
    x, y = transformer.transform(lon, lat)
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y)]).astype(np.float64)


def judge(
    flight: Flight,
    mission: Mission,
    dem_path: Path,
    targets_path: Path,
    settings: ReplaySettings,
    plan_name: str,
) -> ReplayReport:
    """Check a flight's photos and track against the DEM; see the module docstring."""
    targets = read_targets(targets_path).targets
    info = open_dem(dem_path)
    lats = [t.lat_deg for t in targets] + [mission.home.lat_deg]
    lons = [t.lon_deg for t in targets] + [mission.home.lon_deg]
    crs = planning_crs(info, (min(lons), min(lats), max(lons), max(lats)))
    to_xy = pyproj.Transformer.from_crs(WGS84, crs, always_xy=True)
    target_xy = _xy(to_xy, [t.lat_deg for t in targets], [t.lon_deg for t in targets])
    photo_xy = _xy(to_xy, [p.lat_deg for p in flight.photos], [p.lon_deg for p in flight.photos])
    track_xy = _xy(to_xy, [p.lat_deg for p in flight.track], [p.lon_deg for p in flight.track])
    ground0 = mission.home.amsl_m
    eye_z = ground0 + np.array([p.alt_rel_m for p in flight.photos], dtype=np.float64)
    track_z = ground0 + np.array([p.alt_rel_m for p in flight.track], dtype=np.float64)
    tan = math.tan(math.radians(settings.fov_deg))

    # Every line of sight and leg runs between these points, so their box is all it needs.
    points = np.vstack([target_xy, photo_xy.reshape(-1, 2), track_xy.reshape(-1, 2)])
    lo, hi = points.min(axis=0) - TERRAIN_MARGIN_M, points.max(axis=0) + TERRAIN_MARGIN_M
    terrain = read_terrain(info, crs, (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])))
    ground_t = terrain.sample(target_xy[:, 0], target_xy[:, 1])

    problems: list[str] = []
    if not flight.photos:
        problems.append("no photo was taken: check the mission's DO_DIGICAM_CONTROL items")
    seen = _targets_seen(
        terrain, [t.name for t in targets], target_xy, ground_t, photo_xy, eye_z, tan
    )
    for row in seen:
        if row.photo is None:
            problems.append(f"target {row.name} was photographed from no position that sees it")
    clearance = _min_clearance(terrain, track_xy, track_z, flight, mission)
    if clearance is None:
        problems.append("no position at the flight altitude was received: the flight is unchecked")
    elif clearance < settings.min_clearance_m:
        problems.append(
            f"the track passed {clearance:.1f} m above the terrain, under the required "
            f"{settings.min_clearance_m:g} m"
        )
    return ReplayReport(
        plan_name, flight, seen, clearance, settings.min_clearance_m, tuple(problems)
    )


def _targets_seen(
    terrain: Terrain,
    names: list[str],
    target_xy: FloatArray,
    ground_t: FloatArray,
    photo_xy: FloatArray,
    eye_z: FloatArray,
    tan: float,
) -> tuple[TargetSeen, ...]:
    rows = []
    for i, name in enumerate(names):
        if not math.isfinite(float(ground_t[i])):
            rows.append(TargetSeen(name, None, None, "no elevation under the target"))
            continue
        if photo_xy.size == 0:
            rows.append(TargetSeen(name, None, None, "no photos"))
            continue
        offset = np.hypot(photo_xy[:, 0] - target_xy[i, 0], photo_xy[:, 1] - target_xy[i, 1])
        cone = (eye_z - ground_t[i]) * tan
        inside = np.flatnonzero(offset <= cone + CONE_TOLERANCE_M)
        clear = np.zeros(0, dtype=bool)
        if inside.size:
            eyes = np.column_stack([photo_xy[inside], eye_z[inside]])
            tgt = np.tile([target_xy[i, 0], target_xy[i, 1], ground_t[i]], (inside.size, 1))
            clear = line_of_sight(terrain, eyes, tgt)
        if clear.any():
            k = int(inside[np.flatnonzero(clear)[0]])
            rows.append(TargetSeen(name, k + 1, float(offset[k])))
            continue
        nearest = int(np.argmin(offset - cone))
        reason = (
            f"photo {nearest + 1} sees it only past terrain"
            if inside.size
            else f"nearest photo {nearest + 1} is {offset[nearest] - cone[nearest]:.1f} m "
            "outside its camera cone"
        )
        rows.append(TargetSeen(name, None, None, reason))
    return tuple(rows)


def _min_clearance(
    terrain: Terrain,
    track_xy: FloatArray,
    track_z: FloatArray,
    flight: Flight,
    mission: Mission,
) -> float | None:
    cruise = np.array(
        [p.alt_rel_m >= mission.altitude_rel_m - CRUISE_BAND_M for p in flight.track], dtype=bool
    )
    legs = np.flatnonzero(cruise[:-1] & cruise[1:])
    if legs.size == 0:
        return None
    a = np.column_stack([track_xy[legs], track_z[legs]])
    b = np.column_stack([track_xy[legs + 1], track_z[legs + 1]])
    excess = segment_profile(terrain, a, b).excess_m
    known = np.isfinite(excess)
    return float(-excess[known].max()) if known.any() else None


def report_text(report: ReplayReport) -> str:
    """The replay's report for the operator, one screen."""
    flight = report.flight
    upload = flight.upload
    ratio = flight.sim_time_s / flight.wall_time_s if flight.wall_time_s > 0 else math.nan
    lines = [
        f"replay of {report.plan} on {flight.vehicle.describe()}",
        f"  upload    {upload.items} items verified in {upload.elapsed_s:.2f} s "
        f"({upload.attempts} attempt{'s' if upload.attempts != 1 else ''})",
        f"  flight    {flight.sim_time_s:.1f} s simulated in {flight.wall_time_s:.1f} s wall "
        f"({ratio:.0f}x)",
        f"  photos    {len(flight.photos)}",
        f"  targets   {sum(r.photo is not None for r in report.targets)} of "
        f"{len(report.targets)} seen",
    ]
    width = max((len(r.name) for r in report.targets), default=0)
    for row in report.targets:
        if row.photo is not None:
            lines.append(
                f"    {row.name:<{width}}  photo {row.photo} ({row.offset_m:.1f} m off nadir)"
            )
        else:
            lines.append(f"    {row.name:<{width}}  NOT SEEN: {row.reason}")
    if report.min_clearance_m is not None:
        lines.append(
            f"  clearance {report.min_clearance_m:.1f} m least above the terrain on cruise legs "
            f"(required {report.required_clearance_m:g} m)"
        )
    lines.append(f"  result    {'PASS' if report.ok else 'FAIL'}")
    lines.extend(f"  problem   {problem}" for problem in report.problems)
    return "\n".join(lines)
