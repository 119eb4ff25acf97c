"""Judge a replayed flight against the terrain: was every target seen, was clearance kept?

A target counts as photographed when some photo was taken from a position that sees it: the
target is inside the camera's nadir cone (half-angle ``fov``) and the straight line from the
camera to the target clears the DEM (:func:`urpt_gcs.visibility.regions.line_of_sight`); for a frame
camera, inside the frame turned by the heading the photo's CAMERA_FEEDBACK reported (which
must be within 5 degrees of the one its waypoint turns to) and within the GSD distance. Photo
positions are those CAMERA_FEEDBACK reported, at the altitude above home it reported plus the
planned home's ground elevation, so the DEM's vertical datum cancels out as in planning.

What is checked comes with the mission (:mod:`urpt_gcs.replay.expected`): the camera, the
clearance and the targets of its sortie; a plan's only sortie replayed alone is judged on
every target of the target file as well. Several sorties replayed together are judged each on
its own targets and, by :func:`judge_set`, all their photos on every target of the file.

Clearance is measured along the cruise legs: between consecutive GLOBAL_POSITION_INT fixes
at the flight plane's altitude, the straight segment's least height above the DEM's bilinear
surface, exactly (:func:`urpt_gcs.visibility.segments.segment_profile`).

A plan inside a height band (``--agl``) flies no one plane: its summary names the band, its
missions carry waypoints without a photo that follow the terrain (a summary's stops are the
mission's photo waypoints), its cruise legs are every pair of fixes away from home, and every
fix away from home is judged against the band (:mod:`urpt_gcs.replay.band_track`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyproj

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.flight.mission import Mission, photo_headings
from urpt_gcs.replay.band_track import HOME_RADIUS_M, BandTrack, band_track, band_track_text
from urpt_gcs.replay.expected import (
    DEFAULT_FOV_DEG,
    DEFAULT_MIN_CLEARANCE_M,
    SAME_PLACE_DEG,
    SUMMARY_FILE,
    Expected,
    Unplanned,
    chosen_targets,
    expected_checks,
    target_set,
)
from urpt_gcs.replay.record import Flight
from urpt_gcs.site.camera import Frame, grid_bearing_deg
from urpt_gcs.site.dem import WGS84, open_dem, planning_crs
from urpt_gcs.site.reading import read_terrain
from urpt_gcs.site.targets import TargetSet
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.visibility.regions import in_frame, line_of_sight
from urpt_gcs.visibility.segments import segment_profile

__all__ = [
    "CONE_TOLERANCE_M",
    "CRUISE_BAND_M",
    "DEFAULT_FOV_DEG",
    "DEFAULT_MIN_CLEARANCE_M",
    "HEADING_TOLERANCE_DEG",
    "SAME_PLACE_DEG",
    "SUMMARY_FILE",
    "TERRAIN_MARGIN_M",
    "Expected",
    "ReplayReport",
    "SetReport",
    "TargetSeen",
    "expected_checks",
    "judge",
    "judge_set",
    "report_text",
    "set_report_text",
]

# Photo positions are on MAVLink's 1e-7 degree grid (about 1 cm): allow that on the cone.
CONE_TOLERANCE_M = 0.02
# A frame camera's photo must be taken within this of the heading its waypoint turns to.
HEADING_TOLERANCE_DEG = 5.0
# Fixes within this of the planned altitude are on a cruise leg.
CRUISE_BAND_M = 0.5
# Terrain read around the points, so bilinear samples at the edge exist.
TERRAIN_MARGIN_M = 10.0


# What a report judged on when it does not say (frozen: one instance serves all).
_UNSTATED = Expected(DEFAULT_FOV_DEG, DEFAULT_MIN_CLEARANCE_M)


@dataclass(frozen=True, slots=True)
class TargetSeen:
    """Which photo saw a target (``photo`` None if none did), and why not if not; ``plan``
    names the flight the photo is from when several are judged together; ``unplanned`` says
    a target of the file the plan was not made for ("extra") or put elsewhere ("moved")."""

    name: str
    photo: int | None
    offset_m: float | None
    reason: str = ""
    plan: str = ""
    unplanned: Unplanned = ""


@dataclass(frozen=True, slots=True)
class ReplayReport:
    """The verdict on one replayed flight."""

    plan: str
    flight: Flight
    targets: tuple[TargetSeen, ...]
    min_clearance_m: float | None
    required_clearance_m: float
    problems: tuple[str, ...]
    expected: Expected = _UNSTATED
    home_amsl_m: float = 0.0
    # A band plan's track against its band (None: a plan on one flight plane).
    band: BandTrack | None = None

    @property
    def ok(self) -> bool:
        """True when every target was seen and the clearance was kept."""
        return not self.problems


def _xy(transformer: pyproj.Transformer, lat: list[float], lon: list[float]) -> FloatArray:
    x, y = transformer.transform(lon, lat)
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y)]).astype(np.float64)


def _site(
    dem_path: Path, lat_lon: Sequence[tuple[float, float]]
) -> tuple[Any, pyproj.CRS, pyproj.Transformer]:
    """The DEM, and the CRS planning would use for these points."""
    info = open_dem(dem_path)
    lats, lons = [p[0] for p in lat_lon], [p[1] for p in lat_lon]
    crs = planning_crs(info, (min(lons), min(lats), max(lons), max(lats)))
    return info, crs, pyproj.Transformer.from_crs(WGS84, crs, always_xy=True)


def judge(
    flight: Flight,
    mission: Mission,
    dem_path: Path,
    targets_path: Path | TargetSet,
    expected: Expected,
    plan_name: str,
    every_target: bool = False,
) -> ReplayReport:
    """Check a flight's photos and track against the DEM; see the module docstring.

    With ``every_target``, a plan's only sortie is judged on every target of
    ``targets_path`` too (:func:`~urpt_gcs.replay.expected.chosen_targets`).
    """
    problems: list[str] = []
    targets, unplanned = chosen_targets(expected, targets_path, problems, every_target)
    home = (mission.home.lat_deg, mission.home.lon_deg)
    info, crs, to_xy = _site(dem_path, [*((t.lat_deg, t.lon_deg) for t in targets), home])
    target_xy = _xy(to_xy, [t.lat_deg for t in targets], [t.lon_deg for t in targets])
    photo_xy = _xy(to_xy, [p.lat_deg for p in flight.photos], [p.lon_deg for p in flight.photos])
    track_xy = _xy(to_xy, [p.lat_deg for p in flight.track], [p.lon_deg for p in flight.track])
    home_xy = _xy(to_xy, [home[0]], [home[1]])[0]
    ground0 = mission.home.amsl_m
    # Each photo at the altitude it was taken at, as reported: a band plan's differ.
    eye_z = ground0 + np.array([p.alt_rel_m for p in flight.photos], dtype=np.float64)
    track_z = ground0 + np.array([p.alt_rel_m for p in flight.track], dtype=np.float64)
    tan = math.tan(math.radians(expected.fov_deg))

    # Every line of sight and leg runs between these points, so their box is all it needs.
    points = np.vstack([target_xy.reshape(-1, 2), photo_xy.reshape(-1, 2), track_xy.reshape(-1, 2)])
    lo, hi = points.min(axis=0) - TERRAIN_MARGIN_M, points.max(axis=0) + TERRAIN_MARGIN_M
    terrain = read_terrain(info, crs, (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])))
    ground_t = terrain.sample(target_xy[:, 0], target_xy[:, 1])

    if not flight.photos:
        problems.append("no photo was taken: check the mission's DO_DIGICAM_CONTROL items")
    view = None
    if expected.frame is not None:
        headings = _photo_headings(flight, mission, crs, photo_xy, problems)
        view = _FrameView(expected.frame, expected.gsd_cm, headings)
    seen = _targets_seen(
        terrain, [t.name for t in targets], target_xy, ground_t, photo_xy, eye_z, tan, view
    )
    seen = tuple(replace(row, unplanned=unplanned.get(row.name, "")) for row in seen)
    plan_file = Path(plan_name).name
    named = targets_path.source if isinstance(targets_path, TargetSet) else str(targets_path)
    fix = "plan again with this target file, or give the one the plan was made from"
    for row in (r for r in seen if r.photo is None):
        if row.unplanned == "extra":
            problems.append(
                f"target {row.name} of '{named}' is not one {plan_file} was planned to "
                f"photograph, and no photo sees it: {fix}"
            )
        elif row.unplanned == "moved":
            problems.append(
                f"target {row.name} of '{named}' is not where {plan_file} was planned to "
                f"photograph it, and no photo sees it there: {fix}"
            )
        else:
            problems.append(f"target {row.name} was photographed from no position that sees it")
    if expected.band is None:
        cruise = np.array(
            [p.alt_rel_m >= mission.altitude_rel_m - CRUISE_BAND_M for p in flight.track],
            dtype=bool,
        )
        band = None
    else:
        # Following the terrain there is no one altitude: every fix away from home cruises.
        off = np.hypot(track_xy[:, 0] - home_xy[0], track_xy[:, 1] - home_xy[1])
        cruise = off > HOME_RADIUS_M
        band = band_track(terrain, track_xy, track_z, home_xy, expected.band)
        problems.extend(band.problems())
    clearance = _min_clearance(terrain, track_xy, track_z, cruise)
    if clearance is None:
        problems.append("no position at the flight altitude was received: the flight is unchecked")
    elif clearance < expected.min_clearance_m:
        problems.append(
            f"the track passed {clearance:.1f} m above the terrain, under the required "
            f"{expected.min_clearance_m:g} m"
        )
    return ReplayReport(
        plan_name,
        flight,
        seen,
        clearance,
        expected.min_clearance_m,
        tuple(problems),
        expected,
        ground0,
        band,
    )


@dataclass(frozen=True, slots=True)
class _FrameView:
    """A frame camera's photos: each holds what lies inside its frame turned by its heading
    (grid degrees), within the GSD distance."""

    frame: Frame
    gsd_cm: float | None
    heading_deg: FloatArray

    def holds(
        self, photo: npt.NDArray[np.intp], dx: FloatArray, dy: FloatArray, height: FloatArray
    ) -> BoolArray:
        ok = in_frame(self.frame, dx, dy, height, self.heading_deg[photo], CONE_TOLERANCE_M)
        if self.gsd_cm is not None:
            slant = np.hypot(np.hypot(dx, dy), height)
            ok &= slant <= self.frame.distance_for_gsd_m(self.gsd_cm) + CONE_TOLERANCE_M
        return ok


def _photo_headings(
    flight: Flight, mission: Mission, crs: pyproj.CRS, photo_xy: FloatArray, problems: list[str]
) -> FloatArray:
    """Each photo's heading in the grid judged on: the one its CAMERA_FEEDBACK reported,
    which must be within HEADING_TOLERANCE_DEG of the mission's for that photo; the
    mission's where none was reported."""
    planned = photo_headings(mission) or []
    reported = np.array([p.heading_deg for p in flight.photos], dtype=np.float64)
    used: FloatArray = reported.copy()
    for k, heading in enumerate(reported.tolist()):
        want = planned[k] if k < len(planned) else math.nan
        if not math.isfinite(heading):
            used[k] = want
            continue
        if math.isfinite(want):
            off = abs((heading - want + 180.0) % 360.0 - 180.0)
            if off > HEADING_TOLERANCE_DEG:
                problems.append(
                    f"photo {k + 1} was taken at heading {heading:.1f} deg, {off:.1f} deg off "
                    f"the {want:.1f} deg its waypoint turns to (more than "
                    f"{HEADING_TOLERANCE_DEG:g} deg)"
                )
    unknown = ~np.isfinite(used)
    if unknown.any():
        problems.append(
            f"{int(unknown.sum())} photos have no heading, reported or planned: a frame camera's "
            "photos cannot be judged without one"
        )
    if photo_xy.size == 0:
        return used
    return grid_bearing_deg(crs, photo_xy, np.where(unknown, 0.0, used))


@dataclass(frozen=True, slots=True)
class SetReport:
    """Several sorties replayed: each judged on its own, and all their photos together on
    every target of the target file."""

    reports: tuple[ReplayReport, ...]
    targets: tuple[TargetSeen, ...]
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """True when every flight passed and together they saw every target."""
        return not self.problems and all(r.ok for r in self.reports)


def judge_set(
    reports: Sequence[ReplayReport], dem_path: Path, targets_path: Path | TargetSet
) -> SetReport:
    """Judge the photos of all ``reports`` together on every target of ``targets_path`` (a
    target file, or targets already read), each photo at its own flight's camera."""
    targets = list(target_set(targets_path).targets)
    photos = [(r, p) for r in reports for p in r.flight.photos]
    info, crs, to_xy = _site(
        dem_path,
        [*((t.lat_deg, t.lon_deg) for t in targets), *((p.lat_deg, p.lon_deg) for _, p in photos)],
    )
    target_xy = _xy(to_xy, [t.lat_deg for t in targets], [t.lon_deg for t in targets])
    photo_xy = _xy(to_xy, [p.lat_deg for _, p in photos], [p.lon_deg for _, p in photos])
    eye_z = np.array([r.home_amsl_m + p.alt_rel_m for r, p in photos], dtype=np.float64)
    tan = np.array([math.tan(math.radians(r.expected.fov_deg)) for r, _ in photos])
    points = np.vstack([target_xy, photo_xy.reshape(-1, 2)])
    lo, hi = points.min(axis=0) - TERRAIN_MARGIN_M, points.max(axis=0) + TERRAIN_MARGIN_M
    terrain = read_terrain(info, crs, (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])))
    ground_t = terrain.sample(target_xy[:, 0], target_xy[:, 1])
    view = None
    framed = [r.expected for r in reports if r.expected.frame is not None]
    if framed:
        # Each photo at the heading it reported (one without is held by none).
        reported = np.array([p.heading_deg for _, p in photos], dtype=np.float64)
        grid = grid_bearing_deg(crs, photo_xy, np.nan_to_num(reported)) if photos else reported
        assert framed[0].frame is not None
        view = _FrameView(
            framed[0].frame, framed[0].gsd_cm, np.where(np.isfinite(reported), grid, np.nan)
        )
    rows = _targets_seen(
        terrain, [t.name for t in targets], target_xy, ground_t, photo_xy, eye_z, tan, view
    )
    named = []
    for row in rows:
        if row.photo is None:
            named.append(row)
            continue
        report, photo = photos[row.photo - 1]
        named.append(TargetSeen(row.name, photo.index, row.offset_m, plan=report.plan))
    problems = tuple(
        f"target {row.name} was photographed by none of the {len(reports)} flights"
        for row in named
        if row.photo is None
    )
    return SetReport(tuple(reports), tuple(named), problems)


def _targets_seen(
    terrain: Terrain,
    names: list[str],
    target_xy: FloatArray,
    ground_t: FloatArray,
    photo_xy: FloatArray,
    eye_z: FloatArray,
    tan: float | FloatArray,
    view: _FrameView | None = None,
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
        held = offset <= cone + CONE_TOLERANCE_M
        if view is not None:
            every = np.arange(len(photo_xy))
            dx, dy = target_xy[i, 0] - photo_xy[:, 0], target_xy[i, 1] - photo_xy[:, 1]
            held = view.holds(every, dx, dy, eye_z - ground_t[i])
        inside = np.flatnonzero(held)
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
        if view is not None and not inside.size:
            reason = f"no photo holds it in its frame (nearest: photo {nearest + 1})"
        rows.append(TargetSeen(name, None, None, reason))
    return tuple(rows)


def _min_clearance(
    terrain: Terrain, track_xy: FloatArray, track_z: FloatArray, cruise: BoolArray
) -> float | None:
    """The least height above the terrain of the straight segments between consecutive
    cruise fixes (None: no such segment over known ground)."""
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
    lines = [f"replay of {report.plan} on {flight.vehicle.describe()}"]
    if upload is not None:
        lines.append(
            f"  upload    {upload.items} items verified in {upload.elapsed_s:.2f} s "
            f"({upload.attempts} attempt{'s' if upload.attempts != 1 else ''})"
        )
    lines += [
        f"  flight    {flight.sim_time_s:.1f} s simulated in {flight.wall_time_s:.1f} s wall "
        f"({ratio:.0f}x)",
        f"  checks    {_checks_line(report)}",
        *(f"  warning   {w}" for w in report.expected.warnings),
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
            why = _UNPLANNED[row.unplanned]
            lines.append(f"    {row.name:<{width}}  NOT SEEN: {why}{row.reason}")
    if report.min_clearance_m is not None:
        lines.append(
            f"  clearance {report.min_clearance_m:.1f} m least above the terrain on cruise legs "
            f"(required {report.required_clearance_m:g} m)"
        )
    if report.band is not None:
        lines.append(f"  {band_track_text(report.band)}")
    lines.append(f"  result    {'PASS' if report.ok else 'FAIL'}")
    lines.extend(f"  problem   {problem}" for problem in report.problems)
    return "\n".join(lines)


_UNPLANNED = {
    "": "",
    "extra": "not a target of the plan; ",
    "moved": "moved in --targets from where the plan put it; ",
}


def _checks_line(report: ReplayReport) -> str:
    expected = report.expected
    camera = f"camera ±{expected.fov_deg:g}°"
    if expected.frame is not None:
        f = expected.frame
        camera = (
            f"frame {f.sensor_w_mm:g}x{f.sensor_h_mm:g} mm / {f.focal_mm:g} mm at each "
            "photo's heading"
        )
        if expected.gsd_cm is not None:
            camera += f", GSD {expected.gsd_cm:g} cm"
    extra = sum(r.unplanned == "extra" for r in report.targets)
    moved = sum(r.unplanned == "moved" for r in report.targets)
    source = expected.source
    source += f", {extra} more of --targets" if extra else ""
    source += f", {moved} where --targets moved {'them' if moved > 1 else 'it'}" if moved else ""
    return (
        f"{len(report.targets)} targets at {camera}, clearance "
        f"{expected.min_clearance_m:g} m (from {source})"
    )


def set_report_text(report: SetReport) -> str:
    """Several replays' reports, then the verdict on all their photos together."""
    parts = [report_text(r) for r in report.reports]
    seen = sum(r.photo is not None for r in report.targets)
    lines = [
        f"together: {len(report.reports)} flights, "
        f"{sum(len(r.flight.photos) for r in report.reports)} photos",
        f"  targets   {seen} of {len(report.targets)} seen",
    ]
    width = max((len(r.name) for r in report.targets), default=0)
    for row in report.targets:
        if row.photo is not None:
            lines.append(f"    {row.name:<{width}}  {row.plan} photo {row.photo}")
        else:
            lines.append(f"    {row.name:<{width}}  NOT SEEN by any flight")
    failed = [r.plan for r in report.reports if not r.ok]
    lines.append(f"  result    {'PASS' if report.ok else 'FAIL'}")
    lines.extend(f"  problem   {p}" for p in report.problems)
    lines.extend(f"  problem   {plan} failed on its own" for plan in failed)
    return "\n\n".join([*parts, "\n".join(lines)])
