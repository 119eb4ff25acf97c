"""Frame cameras: the frame's footprint turned by the heading, the GSD cap, the mission's
turns, and plans checked independently (tests/support/independent.py) against the written
mission."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pyproj
import pytest
from click.testing import CliRunner
from conftest import DEMO, REAL_DEMS, needs_shared
from pymavlink import mavutil
from support.independent import (
    FrameCamera,
    check_mission,
    load_raster,
    read_waypoints_file,
    sees_in_frame,
)
from support.targets import kml_targets, valid_targets

from urpt_gcs.cli import main
from urpt_gcs.errors import SettingsError
from urpt_gcs.files.products import write_products
from urpt_gcs.flight.mission import (
    GeoPoint,
    MissionSettings,
    build_mission,
    photo_headings,
    upload_problem,
)
from urpt_gcs.flight.wire import WireItem, wire_items
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.sim.store import Item, ardupilot_stored
from urpt_gcs.site.camera import CAMERAS, Frame, frame_from_flags
from urpt_gcs.solvers import SolveSettings
from urpt_gcs.vehicle.readback import compare
from urpt_gcs.visibility.regions import Camera

MAV = mavutil.mavlink
FAST = SolveSettings(time_limit_s=1.0)
# The Phantom 4 RTK as its maker states it, typed here rather than read from the presets.
P4RTK = FrameCamera(13.2, 8.8, 8.8, 5472, 3648)


def test_presets_match_the_makers_ground_resolution() -> None:
    """DJI states the Phantom 4 RTK's GSD as H/36.5 cm (H in metres), within 1 %; the
    Mavic 3 Enterprise's pixel counts by its coarser side, 13.0 mm over 3956 px."""
    p4 = CAMERAS["phantom4rtk"].frame
    m3e = CAMERAS["mavic3e"].frame
    assert float(p4.gsd_cm(100.0)) == pytest.approx(100.0 / 36.5, rel=0.01)
    assert float(m3e.gsd_cm(100.0)) == pytest.approx(100.0 * 13.0 / 3956 / 12.29 * 100.0)
    # The lens's 84 degree field of view is the frame's diagonal.
    for frame in (p4, m3e):
        assert 2.0 * math.degrees(math.atan(frame.diagonal_tan)) == pytest.approx(84.0, abs=1.5)


def test_the_frame_turns_with_the_heading() -> None:
    """10 m above a target, the 13.2 x 8.8 mm sensor behind 8.8 mm sees 7.5 m to each side
    across the vehicle and 5 m along it: a target 6 m east is in the frame flying north and
    south, out of it flying east; a target 9 m east is out either way."""
    camera = Camera.framed(10.0, Frame(13.2, 8.8, 8.8, 5472, 3648), headings=4)
    eye = np.zeros((4, 2))
    target = np.array([[6.0, 0.0], [6.0, 0.0], [6.0, 0.0], [9.0, 0.0]])
    heading = np.array([0.0, 180.0, 90.0, 0.0])
    assert camera.in_view(eye, target, np.zeros(4), heading).tolist() == [
        True,
        True,
        False,
        False,
    ]
    # Diagonal: 7.0 m across and 4.8 m along at heading 0 is inside; turned 45 degrees out.
    corner = np.array([[7.0, 4.8], [7.0, 4.8]])
    inside = camera.in_view(np.zeros((2, 2)), corner, np.zeros(2), np.array([0.0, 45.0]))
    assert inside.tolist() == [True, False]
    assert camera.heading_choices_deg.tolist() == [0.0, 45.0, 90.0, 135.0]


def test_gsd_caps_the_distance_to_the_target() -> None:
    """1 cm/px with 2.41 um pixels behind 8.8 mm: at most 36.5 m from the lens. From 30 m up
    the cap allows sqrt(36.5^2 - 30^2) = 20.8 m sideways, less than the frame's corner."""
    frame = Frame(13.2, 8.8, 8.8, 5472, 3648)
    camera = Camera.framed(30.0, frame, gsd_cm=1.0)
    far = 0.01 * 8.8 / (13.2 / 5472)
    assert camera.max_distance_m == pytest.approx(far)
    assert float(camera.cone_radius_m(0.0)) == pytest.approx(math.sqrt(far**2 - 30.0**2))
    # Across the vehicle (east at heading 0) the frame reaches 22.5 m; the cap stops it.
    ok = camera.in_view(np.zeros((2, 2)), np.array([[20.5, 0.0], [21.5, 0.0]]), np.zeros(2), [0, 0])
    assert ok.tolist() == [True, False]


@pytest.mark.parametrize("framed", [False, True])
def test_the_whole_disc_around_the_eye_is_held_not_samples_of_it(framed: bool) -> None:
    """``in_view(..., within_m=r)`` says whether the target is in the picture from every point
    within r of the eye: against 3600 points of the disc's rim (the footprint is convex, so
    the rim decides) for random eyes, targets and headings, with a GSD cap on the frame."""
    frame = Frame(13.2, 8.8, 8.8, 5472, 3648)
    camera = Camera.framed(30.0, frame, gsd_cm=1.0) if framed else Camera(30.0, 30.0)
    rng = np.random.default_rng(11)
    n, r = 400, 1.5
    eye = rng.uniform(-25.0, 25.0, (n, 2))
    target = rng.uniform(-25.0, 25.0, (n, 2))
    ground = rng.uniform(0.0, 5.0, n)
    heading = rng.uniform(0.0, 360.0, n)
    held = camera.in_view(eye, target, ground, heading, within_m=r)
    a = np.linspace(0.0, 2.0 * math.pi, 3600, endpoint=False)
    rim = r * np.column_stack([np.cos(a), np.sin(a)])
    every = np.array(
        [
            camera.in_view(
                eye[k] + rim,
                np.tile(target[k], (len(a), 1)),
                ground[[k] * len(a)],
                np.full(len(a), heading[k]),
            ).all()
            for k in range(n)
        ]
    )
    margin = camera.view_margin_m(eye, target, ground, heading)
    # Held: every rim point sees. Seen from every sample of the rim: held, or short of it by
    # no more than the samples' spacing leaves unseen, (1 - cos(0.05 deg)) r.
    assert not np.any(held & ~every)
    assert np.all(margin[every & ~held] >= r - 1e-6)
    assert np.array_equal(held, margin >= r)
    assert 0 < int(held.sum()) < n


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (("nope", None, None, None), "^camera 'nope' is not known"),
        (("phantom4rtk", "13x8", None, None), "both describe the camera"),
        ((None, "13.2x8.8", 8.8, None), "without image"),
        ((None, "13.2by8.8", 8.8, "10x10"), "is not WIDTHxHEIGHT"),
        ((None, "13.2x8.8", 0.0, "10x10"), "^focal 0.0 mm is out of range"),
    ],
)
def test_bad_camera_flags_name_the_flag(flags: tuple, needle: str) -> None:
    with pytest.raises(SettingsError, match=needle):
        frame_from_flags(*flags)


def test_gsd_needs_a_frame_and_approx_needs_the_cone() -> None:
    with pytest.raises(SettingsError, match=r"^gsd_cm needs the camera's pixels"):
        PlanSettings(gsd_cm=2.0)
    with pytest.raises(SettingsError, match="solver approx"):
        PlanSettings(frame=CAMERAS["mavic3e"].frame, solver="approx")


def test_cli_refuses_a_gsd_the_plane_cannot_reach(tmp_path: Path) -> None:
    args = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    args += ["--out", str(tmp_path / "out"), "--camera", "phantom4rtk", "--gsd", "1"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1
    assert "--gsd 1 cm needs the camera within" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()


def _mission(firmware: str, headings: list[float] | None):  # type: ignore[no-untyped-def]
    home = GeoPoint(47.0, 9.0, 400.0)
    stops = [(47.0001, 9.0001), (47.0002, 9.0), (47.0, 9.0002)]
    return build_mission(home, stops, 50.0, MissionSettings(firmware=firmware), headings)  # type: ignore[arg-type]


def test_arducopter_turns_by_condition_yaw_before_each_waypoint() -> None:
    mission = _mission("ardupilot", [10.0, 100.0, 359.99])
    commands = [item.command for item in mission.items]
    for k, seq in enumerate(i for i, c in enumerate(commands) if c == MAV.MAV_CMD_NAV_WAYPOINT):
        yaw = mission.items[seq - 1]
        assert yaw.command == MAV.MAV_CMD_CONDITION_YAW
        # Absolute heading, default rate, the shorter way.
        assert yaw.params[:4] == ([10.0, 100.0, 359.99][k], 0.0, 0.0, 0.0)
        assert mission.items[seq + 1].command == MAV.MAV_CMD_DO_DIGICAM_CONTROL
    assert upload_problem(mission) is None
    assert photo_headings(mission) == [10.0, 100.0, 359.99]
    # ArduPilot's storage keeps the item: the read-back comparison accepts it.
    sent = wire_items(mission)
    got = [
        ardupilot_stored(Item(w.command, w.frame, *w.params, w.x, w.y, w.z, 1))  # type: ignore[arg-type]
        for w in sent
    ]
    assert compare(sent, [_wire(w, g) for w, g in zip(sent, got, strict=True)], "ardupilot").equal


def _wire(sent: WireItem, got: Item) -> WireItem:
    return dataclasses.replace(
        sent,
        frame=got.frame,
        current=0,
        param1=got.param1,
        param2=got.param2,
        param3=got.param3,
        param4=got.param4,
        x=got.x,
        y=got.y,
        z=got.z,
    )


def test_px4_turns_by_the_waypoints_yaw_and_the_cone_mission_is_unchanged() -> None:
    px4 = _mission("px4", [10.0, 100.0, 200.0])
    assert not any(i.command == MAV.MAV_CMD_CONDITION_YAW for i in px4.items)
    wps = [i for i in px4.items if i.command == MAV.MAV_CMD_NAV_WAYPOINT]
    assert [w.params[3] for w in wps] == [10.0, 100.0, 200.0]
    assert photo_headings(px4) == [10.0, 100.0, 200.0]
    for firmware in ("ardupilot", "px4"):
        cone = _mission(firmware, None)
        assert not any(i.command == MAV.MAV_CMD_CONDITION_YAW for i in cone.items)
        assert photo_headings(cone) is None


def _framed_plan_checked(dem: Path, targets_file: Path, targets, out: Path, settings):  # type: ignore[no-untyped-def]
    result = plan(dem, targets_file, settings)
    write_products(result, out, with_map=False)
    files = sorted(out.glob("mission*.waypoints"))
    frame = FrameCamera(
        P4RTK.sensor_w_mm,
        P4RTK.sensor_h_mm,
        P4RTK.focal_mm,
        P4RTK.image_w_px,
        P4RTK.image_h_px,
        settings.gsd_cm,
    )
    return result, files, check_mission(dem, files, targets, 89.0, 10.0, frame=frame)


def test_demo_every_target_inside_the_turned_frame_of_a_photo(tmp_path: Path) -> None:
    """Phantom 4 RTK at 3 cm/px on the demo: every target lies inside the frame of a photo at
    the heading the mission commands, in sight and within the GSD distance, checked from the
    written .waypoints on the ellipsoid; and each stop holds its own targets from anywhere
    within the position tolerance, at its heading."""
    settings = PlanSettings(solve=FAST, frame=CAMERAS["phantom4rtk"].frame, gsd_cm=3.0)
    targets = kml_targets(DEMO / "targets.kml")
    _, files, problems = _framed_plan_checked(
        DEMO / "site.tif", DEMO / "targets.kml", targets, tmp_path, settings
    )
    assert problems == []
    summary = json.loads((tmp_path / "summary.json").read_text())
    camera = summary["camera"]
    assert camera["worst_gsd_cm"] <= 3.0
    assert set(camera["gsd_cm_per_target"]) == {name for name, _, _ in targets}
    # Headings are offered over 0-180 and more than one is used.
    assert len({round(h % 180.0) for h in camera["photo_headings_deg"]}) >= 2
    raster = load_raster(DEMO / "site.tif")
    flown = read_waypoints_file(files[0])
    by_name = {name: (lat, lon) for name, lat, lon in targets}
    missed = []
    geod = pyproj.Geod(ellps="WGS84")
    assert flown.headings is not None
    for stop, eye, heading in zip(summary["stops"], flown.waypoints, flown.headings, strict=True):
        assert heading is not None
        for azimuth in range(0, 360, 90):
            x, y, _ = geod.fwd(eye[1], eye[0], azimuth, 0.95 * settings.position_tolerance_m)
            for name in stop["sees"]:
                ok, why = sees_in_frame(raster, by_name[name], (y, x, eye[2]), heading, P4RTK)
                if not ok:
                    missed.append((stop["order"], name, azimuth, why))
    assert missed == []


def test_the_independent_check_catches_a_wrong_heading(tmp_path: Path) -> None:
    """The same written mission turned by 90 degrees at every photo misses targets: the
    check reads the frame at the commanded heading, not any heading."""
    settings = PlanSettings(solve=FAST, frame=CAMERAS["phantom4rtk"].frame, gsd_cm=3.0)
    targets = kml_targets(DEMO / "targets.kml")
    _, files, problems = _framed_plan_checked(
        DEMO / "site.tif", DEMO / "targets.kml", targets, tmp_path, settings
    )
    assert problems == []
    lines = files[0].read_text().splitlines()
    turned = []
    for line in lines:
        fields = line.split("\t")
        if len(fields) == 12 and int(fields[3]) == MAV.MAV_CMD_CONDITION_YAW:
            fields[4] = f"{(float(fields[4]) + 90.0) % 360.0:.2f}"
        turned.append("\t".join(fields))
    files[0].write_text("\n".join(turned) + "\n")
    frame = FrameCamera(13.2, 8.8, 8.8, 5472, 3648, 3.0)
    assert check_mission(DEMO / "site.tif", files, targets, 89.0, 10.0, frame=frame) != []


@needs_shared(REAL_DEMS)
@pytest.mark.parametrize("name", ["odm_dsm_utm51n.tif", "codem_aoi_dsm_utm16n_egm2008.tif"])
def test_real_rasters_every_target_inside_the_turned_frame(tmp_path: Path, name: str) -> None:
    dem = REAL_DEMS / name
    targets = valid_targets(dem, 8, seed=5)
    csv = tmp_path / "targets.csv"
    csv.write_text(
        "name,lat,lon\n" + "".join(f"{n},{lat:.9f},{lon:.9f}\n" for n, lat, lon in targets)
    )
    settings = PlanSettings(
        solve=FAST, frame=CAMERAS["phantom4rtk"].frame, gsd_cm=3.0, clearance_m=20.0
    )
    _, _, problems = _framed_plan_checked(dem, csv, targets, tmp_path / "out", settings)
    assert problems == []


def _framed_demo_plan(out: Path) -> Path:
    args = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    args += ["--out", str(out), "--camera", "phantom4rtk", "--gsd", "3", "--no-map", "--quiet"]
    args += ["--time-limit", "1"]
    made = CliRunner().invoke(main, args)
    assert made.exit_code == 0, made.output
    return out / "mission.plan"


def test_replay_on_the_simulated_copter_judges_frame_and_heading(tmp_path: Path) -> None:
    """The simulated copter turns at each CONDITION_YAW; its CAMERA_FEEDBACK headings are the
    plan's, and the judge passes every target inside a turned frame. The same mission with
    every turn 90 degrees off is flown as written, and then targets fall outside the frames."""
    plan_file = _framed_demo_plan(tmp_path / "out")
    replay = ["sitl", "replay", "--dem", str(DEMO / "site.tif")]
    replay += ["--targets", str(DEMO / "targets.kml"), "--speedup", "200"]
    result = CliRunner().invoke(main, [*replay, "--plan", str(plan_file)])
    assert result.exit_code == 0, result.output
    assert "targets   16 of 16 seen" in result.output
    assert "frame 13.2x8.8 mm / 8.8 mm at each photo's heading, GSD 3 cm" in result.output
    data = json.loads(plan_file.read_text())
    for item in data["mission"]["items"]:
        if item["command"] == MAV.MAV_CMD_CONDITION_YAW:
            item["params"][0] = (item["params"][0] + 90.0) % 360.0
    turned = tmp_path / "turned.plan"
    turned.write_text(json.dumps(data))
    result = CliRunner().invoke(main, [*replay, "--plan", str(turned)])
    assert result.exit_code == 1
    assert "no photo holds it in its frame" in result.output
    assert "result    FAIL" in result.output


def test_a_photo_off_its_heading_is_a_problem() -> None:
    """A CAMERA_FEEDBACK heading more than 5 degrees off its waypoint's is reported."""
    import pyproj as _pyproj

    from urpt_gcs.replay.judge import _photo_headings
    from urpt_gcs.replay.record import PhotoFix

    mission = _mission("ardupilot", [10.0, 100.0, 200.0])
    photos = [PhotoFix(k + 1, 47.0, 9.0, 50.0, k, h) for k, h in enumerate([12.0, 94.0, 200.0])]

    class _Flight:
        pass

    flight = _Flight()
    flight.photos = photos  # type: ignore[attr-defined]
    problems: list[str] = []
    crs = _pyproj.CRS.from_epsg(32632)
    xy = np.array([[500_000.0, 5_200_000.0]] * 3)
    grid = _photo_headings(flight, mission, crs, xy, problems)  # type: ignore[arg-type]
    assert len(problems) == 1 and problems[0].startswith("photo 2 was taken at heading 94.0")
    # On the central meridian grid and true north agree.
    assert grid.tolist() == pytest.approx([12.0, 94.0, 200.0], abs=1e-6)


def test_altitude_auto_keeps_the_shortest_flight_of_its_range(tmp_path: Path) -> None:
    """Three altitudes from the --clearance plane up to what --gsd allows, planned in two
    processes: the kept plan flies the least time of the curve, at its altitude, and every
    altitude lies in the range computed here from the terrain and the camera."""
    args = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    args += ["--out", str(tmp_path), "--camera", "phantom4rtk", "--gsd", "3", "--quiet"]
    args += ["--altitude", "auto", "--altitude-steps", "3", "--time-limit", "1", "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    curve = data["altitude_curve"]
    assert len(curve) == 3
    times = {p["altitude_amsl_m"]: p["flight_time_s"] for p in curve}
    best = min(times, key=lambda a: times[a])
    assert data["altitude_best_amsl_m"] == best == pytest.approx(data["altitude_amsl_m"], abs=0.01)
    assert data["flight_time_s"] == pytest.approx(times[best], abs=0.2)
    # The range: 30 m over the highest terrain up to the GSD distance over the lowest target.
    raster = load_raster(DEMO / "site.tif")
    lowest = min(
        float(raster.height(np.array([lon]), np.array([lat]))[0])
        for _, lat, lon in kml_targets(DEMO / "targets.kml")
    )
    far = 0.03 * 8.8 / max(13.2 / 5472, 8.8 / 3648)
    altitudes = sorted(times)
    assert altitudes[0] == pytest.approx(data["terrain_max_m"] + 30.0, abs=0.01)
    assert altitudes[-1] <= lowest + far
    assert altitudes[-1] > altitudes[0] + 10.0
    assert (tmp_path / "map.png").stat().st_size > 0
    # The mission flies the kept altitude.
    flown = read_waypoints_file(tmp_path / "mission.waypoints")
    for _, _, amsl in flown.waypoints:
        assert amsl == pytest.approx(best, abs=0.05)


def test_altitude_must_be_a_number_or_auto(tmp_path: Path) -> None:
    args = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    result = CliRunner().invoke(main, [*args, "--out", str(tmp_path), "--altitude", "high"])
    assert result.exit_code == 1
    assert "--altitude 'high' is not a number of metres: give one, or auto" in result.output
