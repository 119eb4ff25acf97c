"""The simulated vehicle: its ArduPilot rules without sockets, a second MAVLink client
(pymavlink) against it, and the replay of the demo mission against the terrain."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from conftest import DEMO, DEMO_OUT
from pymavlink import mavutil, mavwp
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.simulated import DEMO_PLAN, demo_mission, simulated

from urpt_gcs.cli import main
from urpt_gcs.files.formats import waypoints_text
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.flight.mission import Mission
from urpt_gcs.flight.wire import WireItem, wire_items
from urpt_gcs.replay.fly import ReplaySettings, fly, replay
from urpt_gcs.sim import VehicleSettings
from urpt_gcs.sim.events import Reached, Text
from urpt_gcs.sim.model import Vehicle
from urpt_gcs.sim.store import Home, Item, MissionStore
from urpt_gcs.sim.transfer import REREQUEST_S, UPLOAD_TIMEOUT_S, MissionTransfer
from urpt_gcs.vehicle.link import upload
from urpt_gcs.vehicle.readback import compare

MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
GCS = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
COPTER_AUTO = mavlink.COPTER_MODE_AUTO


def _item(seq: int, command: int = WAYPOINT, frame: int = 6, **fields: float) -> Any:
    values = {"param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": 0.0, "x": 0, "y": 0, "z": 0.0}
    values.update(fields)
    msg = GCS.mission_item_int_encode(
        1, 1, seq, frame, command, 0, 1, values["param1"], values["param2"], values["param3"],
        values["param4"], int(values["x"]), int(values["y"]), values["z"], 0,
    )  # fmt: skip
    return _received(msg)


def _received(msg: Any) -> Any:
    """A message as the vehicle receives it (packed and parsed, with its sender's ids)."""
    return MAV.parse_char(msg.pack(GCS))


def _types(messages: list[Any]) -> list[str]:
    return [m.get_type() for m in messages]


# --- storage and the mission protocol, without sockets ---------------------------------------


def test_store_reads_back_as_ardupilot_does() -> None:
    store = MissionStore(Home(476887616, 94230907, 411.92), capacity=10)
    transfer = MissionTransfer(store, MAV)
    out = transfer.handle(_received(GCS.mission_count_encode(1, 1, 4, 0)), 0.0)
    assert _types(out) == ["MISSION_REQUEST"]
    transfer.handle(_item(0, frame=0, x=1, y=1, z=5.0), 0.1)
    transfer.handle(_item(1, x=476888434, y=94238428, z=68.87, param1=2.5, param4=math.nan), 0.2)
    transfer.handle(_item(2, mavlink.MAV_CMD_DO_MOUNT_CONTROL, frame=2, param1=-90, z=2.0), 0.3)
    out = transfer.handle(_item(3, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=2), 0.4)
    assert [m.get_type() for m in out] == ["STATUSTEXT", "MISSION_ACK"]
    assert out[1].type == mavlink.MAV_MISSION_ACCEPTED
    home, waypoint, mount, rtl = store.items()
    assert (home.x, home.y, home.frame) == (476887616, 94230907, 0)  # the vehicle's, not ours
    assert (waypoint.frame, waypoint.param1, waypoint.param4) == (3, 2.0, 0.0)
    assert (waypoint.x, waypoint.y) == (476888434, 94238428)
    assert waypoint.z == pytest.approx(68.87, abs=0.01)
    assert (mount.frame, mount.param1, mount.z) == (0, -90.0, 0.0)
    assert rtl.frame == 0


@pytest.mark.parametrize(
    ("item", "result"),
    [
        (_item(0, param1=math.nan), mavlink.MAV_MISSION_INVALID_PARAM1),
        (_item(0, mavlink.MAV_CMD_DO_MOUNT_CONTROL, param4=math.nan), 9),
        (_item(0, frame=mavlink.MAV_FRAME_LOCAL_NED), mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        (_item(0, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW), mavlink.MAV_MISSION_UNSUPPORTED),
        (_item(0, x=91 * 10**7), mavlink.MAV_MISSION_INVALID_PARAM5_X),
    ],
)
def test_items_ardupilot_refuses(item: Any, result: int) -> None:
    transfer = MissionTransfer(MissionStore(Home(0, 0, 0.0), 10), MAV)
    transfer.handle(_received(GCS.mission_count_encode(1, 1, 2, 0)), 0.0)
    (ack,) = transfer.handle(item, 0.1)
    assert (ack.get_type(), ack.type) == ("MISSION_ACK", result)
    assert transfer.upload is None


def test_capacity_wrong_seq_rerequest_and_timeout() -> None:
    store = MissionStore(Home(0, 0, 0.0), capacity=3)
    transfer = MissionTransfer(store, MAV)
    out = transfer.handle(_received(GCS.mission_count_encode(1, 1, 4, 0)), 0.0)
    assert [(m.get_type(), getattr(m, "type", None)) for m in out] == [
        ("MISSION_ACK", mavlink.MAV_MISSION_NO_SPACE),
        ("STATUSTEXT", None),
    ]
    assert out[1].text == "Only 3 items are supported"
    transfer.handle(_received(GCS.mission_count_encode(1, 1, 3, 0)), 0.0)
    (ack,) = transfer.handle(_item(1), 0.1)
    assert ack.type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    assert transfer.upload is not None, "a wrong seq does not end the upload"
    assert transfer.tick(REREQUEST_S / 2) == []
    assert _types(transfer.tick(REREQUEST_S + 0.01)) == ["MISSION_REQUEST"]
    out = transfer.tick(UPLOAD_TIMEOUT_S + 0.01)
    assert out[-1].type == mavlink.MAV_MISSION_OPERATION_CANCELLED


def test_an_interrupted_upload_leaves_a_mixed_mission() -> None:
    store = MissionStore(Home(0, 0, 0.0), capacity=10)
    transfer = MissionTransfer(store, MAV)
    transfer.handle(_received(GCS.mission_count_encode(1, 1, 3, 0)), 0.0)
    for seq in range(3):
        transfer.handle(_item(seq, x=100, y=100, z=10.0), 0.1)
    transfer.handle(_received(GCS.mission_count_encode(1, 1, 3, 0)), 1.0)
    transfer.handle(_item(0), 1.1)
    transfer.handle(_item(1, x=200, y=200, z=10.0), 1.2)  # then the link goes
    assert [i.x for i in store.items()] == [0, 200, 100], "as ArduPilot, item by item"


def test_px4_store_keeps_items_as_px4_does() -> None:
    """What PX4 v1.16 SITL was seen to return (see urpt_gcs/sim/store.py)."""
    store = MissionStore(Home(0, 0, 0.0), capacity=10, px4=True)
    transfer = MissionTransfer(store, MAV)
    (request,) = transfer.handle(_received(GCS.mission_count_encode(1, 1, 4, 0)), 0.0)
    assert request.get_type() == "MISSION_REQUEST_INT"
    takeoff = mavlink.MAV_CMD_NAV_TAKEOFF
    capture = mavlink.MAV_CMD_IMAGE_START_CAPTURE
    transfer.handle(_item(0, takeoff, 3, param1=15.0, param4=-90.0, z=30.0), 0.1)
    transfer.handle(_item(1, WAYPOINT, 0, param1=2.5, param3=2.0, param4=math.nan, z=7.25), 0.2)
    transfer.handle(_item(2, WAYPOINT, 6, param4=400.0, x=5, y=6, z=30.004), 0.3)
    transfer.handle(_item(3, capture, 2, param3=1.0, param4=math.nan, x=3, y=4, z=2.0), 0.4)
    a, b, c, d = store.items()
    assert (a.frame, a.param1, a.param4, a.z) == (6, 0.0, 270.0, 30.0)
    assert (b.frame, b.param1, b.param3, b.z) == (5, 2.5, 0.0, 7.25) and math.isnan(b.param4)
    assert c.frame == 6 and c.param4 == pytest.approx(40.0, abs=1e-4) and (c.x, c.y) == (5, 6)
    assert abs(c.z - 30.004) < 1e-5
    assert (d.frame, d.param3, d.x, d.y, d.z) == (2, 1.0, 3, 4, 2.0) and math.isnan(d.param4)


@pytest.mark.parametrize(
    ("command", "frame", "result"),
    [
        (WAYPOINT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, "MAV_MISSION_UNSUPPORTED_FRAME"),
        (WAYPOINT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, "MAV_MISSION_UNSUPPORTED_FRAME"),
        (WAYPOINT, mavlink.MAV_FRAME_LOCAL_ENU, "MAV_MISSION_UNSUPPORTED_FRAME"),
        (WAYPOINT, mavlink.MAV_FRAME_MISSION, "MAV_MISSION_UNSUPPORTED"),
        (mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_FRAME_GLOBAL, "MAV_MISSION_UNSUPPORTED"),
        (
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            "MAV_MISSION_UNSUPPORTED",
        ),
    ],
)
def test_px4_store_refuses_what_px4_refuses(command: int, frame: int, result: str) -> None:
    store = MissionStore(Home(0, 0, 0.0), capacity=10, px4=True)
    transfer = MissionTransfer(store, MAV)
    transfer.handle(_received(GCS.mission_count_encode(1, 1, 1, 0)), 0.0)
    (ack,) = transfer.handle(_item(0, command, frame, z=30.0), 0.1)
    assert ack.get_type() == "MISSION_ACK"
    assert mavlink.enums["MAV_MISSION_RESULT"][ack.type].name == result
    assert len(store) == 0


# --- the copter, without sockets --------------------------------------------------------------


def _loaded(mission: Mission, **settings: Any) -> Vehicle:
    vehicle = Vehicle(VehicleSettings(home=mission.home, **settings))
    for w in wire_items(mission):
        vehicle.store.write(w.seq, Item(w.command, w.frame, *w.params, w.x, w.y, w.z))
    return vehicle


def _run(vehicle: Vehicle, limit_s: float = 1200.0, dt_s: float = 0.1) -> None:
    while vehicle.armed and vehicle.time_s < limit_s:
        vehicle.step(dt_s)


def test_auto_on_the_ground_does_not_take_off_without_auto_options() -> None:
    vehicle = _loaded(demo_mission())
    assert vehicle.arm(0.0) == mavlink.MAV_RESULT_ACCEPTED
    assert vehicle.set_mode(COPTER_AUTO)
    _run(vehicle, limit_s=60.0)
    assert not vehicle.armed, "ArduCopter disarms after DISARM_DELAY on the ground"
    assert 9.0 < vehicle.time_s < 11.0
    assert vehicle.alt_m == 0.0 and vehicle.photos == []


def test_arming_in_auto_needs_auto_options_bit_0() -> None:
    vehicle = _loaded(demo_mission())
    assert vehicle.set_mode(COPTER_AUTO)
    assert vehicle.arm(0.0) == mavlink.MAV_RESULT_FAILED
    assert Text(mavlink.MAV_SEVERITY_CRITICAL, "Arm: AUTO mode not armable") in vehicle.events


@pytest.mark.parametrize("start", ["auto-options", "guided", "mission-start"])
def test_the_demo_mission_is_flown(start: str) -> None:
    mission = demo_mission()
    vehicle = _loaded(mission)
    assert vehicle.arm(0.0) == mavlink.MAV_RESULT_ACCEPTED
    if start == "auto-options":
        vehicle.params.set("AUTO_OPTIONS", 2)
        assert vehicle.set_mode(COPTER_AUTO)
    elif start == "guided":
        assert vehicle.set_mode(mavlink.COPTER_MODE_GUIDED)
        assert vehicle.takeoff(10.0) == mavlink.MAV_RESULT_ACCEPTED
        while vehicle.alt_m < 10.0:
            vehicle.step(0.1)
        assert vehicle.set_mode(COPTER_AUTO)
    else:
        assert vehicle.mission_start(0.0, 0.0) == mavlink.MAV_RESULT_ACCEPTED
    _run(vehicle)
    assert not vehicle.armed and vehicle.landed
    assert (vehicle.east_m, vehicle.north_m) == (0.0, 0.0)
    flown = wire_items(mission)[1:]  # after the home placeholder
    waypoints = [(w.x, w.y) for w in flown if w.command == WAYPOINT]
    assert [(p.lat_e7, p.lon_e7) for p in vehicle.photos] == waypoints
    assert {round(p.alt_rel_m, 2) for p in vehicle.photos} == {mission.altitude_rel_m}
    nav_commands = (WAYPOINT, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_TAKEOFF)
    nav = [w.seq for w in flown if w.command in nav_commands]
    assert [e.seq for e in vehicle.events if isinstance(e, Reached)] == nav
    assert 250.0 < vehicle.time_s < 400.0


def test_the_mission_sets_the_speed_and_rtl_does_not_keep_it() -> None:
    """Cruise at the mission's DO_CHANGE_SPEED, not WPNAV_SPEED (10 m/s here); accelerate and
    brake at WPNAV_ACCEL; RTL at WPNAV_SPEED, as ArduCopter's ModeRTL::init sets it."""
    mission = demo_mission()
    assert mission.cruise_speed_m_s == 5.0
    vehicle = _loaded(mission)
    vehicle.params.set("AUTO_OPTIONS", 2)
    vehicle.arm(0.0)
    assert vehicle.set_mode(COPTER_AUTO)
    rtl = len(vehicle.store) - 1
    assert vehicle.store.read(rtl).command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
    mission_speeds, rtl_speeds, accels = [], [], []
    previous = 0.0
    while vehicle.armed and vehicle.time_s < 1200.0:
        vehicle.step(0.05)
        speed = vehicle.ground_speed_m_s
        (rtl_speeds if vehicle.current_seq == rtl else mission_speeds).append(speed)
        accels.append(abs(speed - previous) / 0.05)
        previous = speed
    assert max(mission_speeds) == pytest.approx(5.0)
    assert max(rtl_speeds) == pytest.approx(10.0)
    assert sorted(accels)[len(accels) // 2] <= 2.5 + 1e-6


@pytest.mark.parametrize("east_m", [100.0, 6.0])
def test_a_leg_takes_what_the_estimate_charges(east_m: float) -> None:
    """Climb, one leg from rest to rest (long enough to cruise, or not) and the hold, on the
    simulator and in the plan's flight model. The simulator arms and starts at once and
    holds on arrival, so the estimate's start and its settling at a stop are left out."""
    from urpt_gcs.flight.mission import GeoPoint, MissionSettings, build_mission
    from urpt_gcs.pipeline.missions import flight_model
    from urpt_gcs.pipeline.settings import PlanSettings

    home = GeoPoint(47.3977420, 8.5455940, 488.0)
    lon = home.lon_deg + math.degrees(east_m / (6_378_137.0 * math.cos(math.radians(47.397742))))
    mission = build_mission(home, [(home.lat_deg, lon)], 20.0, MissionSettings())
    vehicle = _loaded(mission)
    vehicle.params.set("AUTO_OPTIONS", 2)
    vehicle.arm(0.0)
    assert vehicle.set_mode(COPTER_AUTO)
    while not vehicle.photos:
        vehicle.step(0.01)
    model = flight_model(PlanSettings())
    expected = model.takeoff_s(20.0) - model.start_s + float(model.leg_s(east_m)) + model.hold_s
    assert vehicle.photos[0].time_s == pytest.approx(expected, abs=0.1)


def test_a_second_auto_forgets_the_first_missions_speed() -> None:
    vehicle = _loaded(demo_mission())
    vehicle.speed_m_s = 3.0
    vehicle.arm(0.0)
    assert vehicle.set_mode(COPTER_AUTO)
    assert vehicle.cruise_m_s() == 10.0  # WPNAV_SPEED until the DO_CHANGE_SPEED runs


def test_rtl_climbs_to_rtl_alt_flies_home_and_lands() -> None:
    from urpt_gcs.flight.mission import GeoPoint, MissionSettings, build_mission

    home = GeoPoint(47.3977420, 8.5455940, 488.0)
    mission = build_mission(home, [(47.3977420, 8.5469240)], 5.0, MissionSettings())  # 100 m E
    vehicle = _loaded(mission)
    vehicle.params.set("AUTO_OPTIONS", 2)
    vehicle.arm(0.0)
    assert vehicle.set_mode(COPTER_AUTO)
    while not vehicle.photos:
        vehicle.step(0.1)
    assert vehicle.east_m == pytest.approx(100.0, abs=0.5)
    assert vehicle.set_mode(mavlink.COPTER_MODE_RTL)
    highest = 0.0
    while vehicle.armed and vehicle.time_s < 300.0:
        vehicle.step(0.1)
        highest = max(highest, vehicle.alt_m)
    assert highest == pytest.approx(15.0)  # RTL_ALT 1500 cm
    assert (vehicle.east_m, vehicle.north_m, vehicle.alt_m) == (0.0, 0.0, 0.0)
    assert not vehicle.armed


# --- on a socket: telemetry, and a second client ---------------------------------------------


@contextmanager
def pymavlink_client(url: str) -> Iterator[Any]:
    """A pymavlink connection speaking MAVLink 2 from the first packet."""
    conn = mavutil.mavlink_connection(url.replace("://", ":"), source_system=254)
    conn.mav = mavlink.MAVLink(conn, srcSystem=254, srcComponent=190)
    conn.first_byte = False
    conn.WIRE_PROTOCOL_VERSION = "2.0"
    try:
        yield conn
    finally:
        conn.close()


def _wait(conn: Any, kind: str | list[str], timeout_s: float = 5.0) -> Any:
    msg = conn.recv_match(type=kind, blocking=True, timeout=timeout_s)
    assert msg is not None, f"no {kind} within {timeout_s} s"
    return msg


def test_no_streams_until_a_gcs_asks() -> None:
    with simulated(speedup=5.0) as (_server, url), pymavlink_client(url) as conn:
        _wait(conn, "HEARTBEAT")
        seen = set()
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:
            msg = conn.recv_match(blocking=True, timeout=0.2)
            if msg is not None:
                seen.add(msg.get_type())
        assert seen <= {"HEARTBEAT", "STATUSTEXT"}
        conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 4, 1)
        position = _wait(conn, "GLOBAL_POSITION_INT")
        assert position.lat == round(VehicleSettings().home.lat_deg * 1e7)
        conn.mav.command_long_send(
            1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS, 200_000, 0, 0, 0, 0, 0,
        )  # fmt: skip
        ack = _wait(conn, "COMMAND_ACK")
        assert (ack.command, ack.result) == (
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
            mavlink.MAV_RESULT_ACCEPTED,
        )
        _wait(conn, "SYS_STATUS")


def _pymavlink_download(conn: Any) -> list[WireItem]:
    conn.mav.mission_request_list_send(1, 1, 0)
    count = _wait(conn, "MISSION_COUNT").count
    items = []
    for seq in range(count):
        conn.mav.mission_request_int_send(1, 1, seq, 0)
        m = _wait(conn, "MISSION_ITEM_INT")
        assert m.seq == seq
        items.append(
            WireItem(m.seq, m.frame, m.command, m.current, m.autocontinue,
                     m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z)
        )  # fmt: skip
    conn.mav.mission_ack_send(1, 1, mavlink.MAV_MISSION_ACCEPTED, 0)
    return items


def test_pymavlink_reads_back_what_mavsdk_uploaded() -> None:
    mission = demo_mission()
    with simulated(mission) as (_server, url):
        upload(mission, url)
        # MAVSDK has let the port go: a second ground station listens there now.
        with pymavlink_client(url) as conn:
            _wait(conn, "HEARTBEAT")
            items = _pymavlink_download(conn)
    assert compare(wire_items(mission), items, "ardupilot").equal
    assert (items[0].x, items[0].y) == (
        round(mission.home.lat_deg * 1e7),
        round(mission.home.lon_deg * 1e7),
    )


@pytest.mark.parametrize("message", ["MISSION_ITEM_INT", "MISSION_ITEM"])
def test_pymavlink_upload_as_mavwp_loads_it(tmp_path: Path, message: str) -> None:
    """mavwp's items in over pymavlink; the comparison on what the vehicle holds.

    MISSION_ITEM carries latitude and longitude as float32 (about 0.4 m here), so its upload
    does not hold the planned positions exactly: the read-back comparison must say so.
    """
    mission = demo_mission()
    path = tmp_path / "m.waypoints"
    path.write_text(waypoints_text(mission))
    loader = mavwp.MAVWPLoader(target_system=1, target_component=1)
    loader.load(str(path))
    with simulated(mission) as (server, url), pymavlink_client(url) as conn:
        _wait(conn, "HEARTBEAT")
        conn.mav.mission_count_send(1, 1, loader.count(), 0)
        for _ in range(loader.count()):
            wp = loader.wp(_wait(conn, ["MISSION_REQUEST", "MISSION_REQUEST_INT"]).seq)
            if message == "MISSION_ITEM":
                conn.mav.send(wp)
            else:
                conn.mav.mission_item_int_send(
                    1, 1, wp.seq, wp.frame, wp.command, wp.current, wp.autocontinue,
                    wp.param1, wp.param2, wp.param3, wp.param4,
                    round(wp.x * 1e7) if wp.frame != 2 else int(wp.x),
                    round(wp.y * 1e7) if wp.frame != 2 else int(wp.y), wp.z, 0,
                )  # fmt: skip
        assert _wait(conn, "MISSION_ACK").type == mavlink.MAV_MISSION_ACCEPTED
        held = [
            WireItem(seq, i.frame, i.command, 0, 1, *i.params, i.x, i.y, i.z)
            for seq, i in enumerate(server.vehicle.store.items())
        ]
    check = compare(wire_items(mission), held, "ardupilot")
    if message == "MISSION_ITEM_INT":
        assert check.equal, check.mismatches
    else:
        assert not check.equal
        assert all(": x (param5)" in m or ": y (param6)" in m for m in check.mismatches)


# --- replay -----------------------------------------------------------------------------------

REPLAY = ["sitl", "replay", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]


def test_replay_of_the_demo_mission_passes() -> None:
    started = time.monotonic()
    result = CliRunner().invoke(main, [*REPLAY, "--plan", str(DEMO_PLAN), "--speedup", "100"])
    wall = time.monotonic() - started
    assert result.exit_code == 0, result.output + result.stderr
    assert "result    PASS" in result.output
    assert "targets   16 of 16 seen" in result.output
    assert "photos    12" in result.output
    print(f"\nreplay at 100x: {wall:.1f} s wall\n{result.output}")


@pytest.mark.parametrize("name", ["mission.plan", "mission.waypoints"])
def test_replay_flies_the_estimated_flight_time(name: str) -> None:
    """The vehicle flies the planned speed from either file, without replay setting a
    parameter, and the flight takes what the plan's estimate says, within 10 %."""
    estimate = json.loads((DEMO_OUT / "summary.json").read_text())["flight_time_s"]
    flight = fly(read_mission(DEMO_OUT / name), ReplaySettings(speedup=200.0))
    print(f"\n{name}: estimate {estimate:.1f} s, simulated flight {flight.sim_time_s:.1f} s")
    assert len(flight.photos) == 12
    assert abs(flight.sim_time_s - estimate) <= 0.1 * estimate


def test_replay_verdict_agrees_with_the_independent_checker() -> None:
    """Each photo the replay names as seeing a target also sees it for tests/support/independent.py
    (its own raster reading, interpolation and geodesy)."""
    from support.independent import load_raster, sees

    from urpt_gcs.site.targets import read_targets

    targets = {t.name: t for t in read_targets(DEMO / "targets.kml").targets}
    report = replay(
        DEMO / "site.tif", DEMO / "targets.kml", DEMO_PLAN, ReplaySettings(speedup=200.0)
    )
    assert report.ok, report.problems
    raster = load_raster(DEMO / "site.tif")
    home_amsl = demo_mission().home.amsl_m
    photos = {p.index: p for p in report.flight.photos}
    for row in report.targets:
        assert row.photo is not None
        photo = photos[row.photo]
        target = targets[row.name]
        eye = (photo.lat_deg, photo.lon_deg, home_amsl + photo.alt_rel_m)
        ok, why = sees(raster, (target.lat_deg, target.lon_deg), eye, 30.0)
        assert ok, f"{row.name} from photo {row.photo}: {why}"


def test_replay_fails_when_a_viewpoint_cannot_see_its_target(tmp_path: Path) -> None:
    plan = json.loads(DEMO_PLAN.read_text())
    waypoints = [i for i in plan["mission"]["items"] if i["command"] == WAYPOINT]
    east_plateau = waypoints[3]  # stop 4: the only one that sees T14 (summary.json)
    east_plateau["params"][5] += 0.0015  # about 110 m further east
    moved = tmp_path / "moved.plan"
    moved.write_text(json.dumps(plan))
    result = CliRunner().invoke(main, [*REPLAY, "--plan", str(moved), "--speedup", "100"])
    assert result.exit_code == 1
    (line,) = [x for x in result.output.splitlines() if x.startswith("    T14 east plateau")]
    assert "NOT SEEN: nearest photo" in line and "outside its camera cone" in line
    assert "16 of 16" not in result.output
    assert "result    FAIL" in result.output
    assert result.stderr.startswith("urpt-gcs: error: replay failed: target T14 east plateau")


def test_guided_take_off_then_auto() -> None:
    flight = fly(demo_mission(), ReplaySettings(speedup=200.0, takeoff="guided"))
    assert len(flight.photos) == 12
    assert max(p.alt_rel_m for p in flight.track) == pytest.approx(68.87, abs=0.02)


def test_bad_simulator_flags_are_one_line() -> None:
    result = CliRunner().invoke(main, ["sitl", "--loss", "1.5"])
    assert result.exit_code == 1
    assert result.stderr == "urpt-gcs: error: --loss 1.5 is out of range; use 0 to below 1\n"
    result = CliRunner().invoke(main, ["sitl", "--listen", "serial:///dev/null"])
    assert result.exit_code == 1
    assert "--listen 'serial:///dev/null' is not udpout://" in result.stderr


def test_replay_on_an_external_vehicle_over_tcp() -> None:
    """--connect: the vehicle runs elsewhere and listens on TCP, as ArduPilot's SITL on 5760."""
    from urpt_gcs.sim.server import SitlServer

    mission = demo_mission()
    port = free_tcp_port()
    vehicle = VehicleSettings(home=mission.home, speedup=100.0)
    with SitlServer(vehicle, f"tcpin://127.0.0.1:{port}"):
        flight = fly(mission, ReplaySettings(speedup=100.0, connect=f"tcpout://127.0.0.1:{port}"))
    assert len(flight.photos) == 12
    assert flight.upload.url == f"tcpout://127.0.0.1:{port}"


def free_tcp_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


# --- replay any plan: the camera and targets travel with it -----------------------------------

PLAN = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
# At the default 5 m/s the demo needs 3 sorties at 4 min.
SORTIE_ENDURANCE = "4"


@pytest.fixture(scope="module")
def sorties(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sorties")
    args = [*PLAN, "--endurance", SORTIE_ENDURANCE, "--no-map", "--quiet", "--out", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.stderr
    assert (out / "mission_2.plan").is_file()
    return out


def _replay(*args: str) -> Any:
    return CliRunner().invoke(main, [*REPLAY, *args, "--speedup", "200"])


def test_a_plan_at_another_camera_replays_without_fov(tmp_path: Path) -> None:
    out = tmp_path / "fov40"
    made = CliRunner().invoke(
        main, [*PLAN, "--fov", "40", "--no-map", "--quiet", "--out", str(out)]
    )
    assert made.exit_code == 0, made.stderr
    result = _replay("--plan", str(out / "mission.plan"))
    assert result.exit_code == 0, result.output + result.stderr
    assert "16 targets at camera ±40°, clearance 10 m (from mission.plan, sortie 1 of 1)" in (
        result.output
    )
    assert "result    PASS" in result.output and result.stderr == ""


def test_a_sortie_is_checked_on_its_own_targets(sorties: Path) -> None:
    check = json.loads((sorties / "mission_2.plan").read_text())["urptGcs"]
    names = {t["name"] for t in check["targets"]}
    summary = json.loads((sorties / "summary.json").read_text())
    assert names == {n for s in summary["stops"] if s["sortie"] == 2 for n in s["sees"]}
    assert 0 < len(names) < summary["targets"]
    result = _replay("--plan", str(sorties / "mission_2.plan"))
    assert result.exit_code == 0, result.output + result.stderr
    assert f"targets   {len(names)} of {len(names)} seen" in result.output
    assert "(from mission_2.plan, sortie 2 of 3)" in result.output


def test_a_waypoints_file_is_checked_from_the_summary_beside_it(
    sorties: Path, tmp_path: Path
) -> None:
    result = _replay("--plan", str(sorties / "mission_3.waypoints"), "--fov", "35")
    assert result.exit_code == 0, result.output + result.stderr
    assert "(from summary.json for mission_3.waypoints, sortie 3 of 3)" in result.output
    assert "camera ±35°" in result.output
    assert result.stderr == (
        "urpt-gcs: warning: --fov 35 deg overrides the 30 deg mission_3.waypoints was planned for\n"
    )
    # A summary of another plan does not describe the file: every target, and a warning.
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / "mission_3.waypoints").write_bytes((sorties / "mission_3.waypoints").read_bytes())
    (alone / "summary.json").write_bytes((DEMO_OUT / "summary.json").read_bytes())
    result = _replay("--plan", str(alone / "mission_3.waypoints"))
    assert result.exit_code == 1
    assert "does not describe mission_3.waypoints" in result.stderr
    assert "from --fov and --min-clearance, every target of --targets" in result.output


def test_sorties_replayed_together_see_every_target(sorties: Path) -> None:
    result = _replay("--plan", str(sorties))
    assert result.exit_code == 0, result.output + result.stderr
    assert result.output.count("result    PASS") == 4  # three sorties and all together
    # A photo at every stop the plan lists, across the three flights.
    stops = len(json.loads((sorties / "summary.json").read_text())["stops"])
    assert f"together: 3 flights, {stops} photos\n  targets   16 of 16 seen" in result.output
    # Two of the three pass on their own, and together miss the third's targets.
    result = _replay(
        "--plan", str(sorties / "mission_1.plan"), "--plan", str(sorties / "mission_2.plan")
    )
    assert result.exit_code == 1
    assert result.output.count("result    PASS") == 2
    assert "photographed by none of the 2 flights" in result.stderr


def test_a_bad_replay_key_is_one_line(sorties: Path, tmp_path: Path) -> None:
    plan = json.loads((sorties / "mission_1.plan").read_text())
    plan["urptGcs"]["targets"][0] = {"name": "T01", "lat": 95.0, "lon": 9.4}
    bad = tmp_path / "bad.plan"
    bad.write_text(json.dumps(plan))
    result = _replay("--plan", str(bad))
    assert result.exit_code == 1
    assert result.stderr == (
        f"urpt-gcs: error: {bad}: urptGcs: target 'T01' is not a WGS84 position: remove the "
        "urptGcs key (replay then uses its flags) or plan again\n"
    )


def test_brake_is_not_armable_as_on_arducopter() -> None:
    vehicle = _loaded(demo_mission())
    assert vehicle.set_mode(mavlink.COPTER_MODE_BRAKE)
    assert vehicle.arm(0.0) == mavlink.MAV_RESULT_FAILED
    assert Text(mavlink.MAV_SEVERITY_CRITICAL, "Arm: BRAKE mode not armable") in vehicle.events


def test_two_replays_in_a_row_on_one_vehicle() -> None:
    """After the first flight the copter is left in AUTO; the second must still arm (MAVSDK's
    arm() would switch AUTO to BRAKE, where ArduCopter refuses)."""
    from urpt_gcs.sim.server import SitlServer

    mission = demo_mission()
    port = free_tcp_port()
    vehicle = VehicleSettings(home=mission.home, speedup=200.0)
    settings = ReplaySettings(speedup=200.0, connect=f"tcpout://127.0.0.1:{port}")
    with SitlServer(vehicle, f"tcpin://127.0.0.1:{port}") as server:
        flights = [fly(mission, settings), fly(mission, settings)]
        assert server.vehicle.mode == COPTER_AUTO
    for flight in flights:
        assert len(flight.photos) == 12
        # Arming to landing on the vehicle's clock; the demo flies about 310 s.
        assert 250.0 < flight.sim_time_s < 400.0
        assert flight.vehicle.describe() == (f"ArduPilot 4.6.0 (tcpout://127.0.0.1:{port})")


def test_the_report_names_the_simulated_copter() -> None:
    from urpt_gcs.replay.judge import report_text

    report = replay(
        DEMO / "site.tif", DEMO / "targets.kml", DEMO_PLAN, ReplaySettings(speedup=200.0)
    )
    first = report_text(report).splitlines()[0]
    assert first.endswith(
        "on the simulated ArduCopter (urpt-gcs), which reports itself as ArduPilot 4.6.0"
    )


@pytest.mark.parametrize(("denials", "ok"), [(2, True), (99, False)])
def test_px4_start_is_asked_again_while_denied(
    denials: int, ok: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """PX4 denies MISSION_START until its navigator holds the mission as valid: the start is
    asked again (armed again first) a bounded number of times, and a vehicle that keeps
    denying it is named with how often it was asked."""
    import asyncio
    from types import SimpleNamespace

    from pymavlink.dialects.v20 import ardupilotmega as mav

    from urpt_gcs.errors import LinkError
    from urpt_gcs.replay import fly as r

    sent: list[int] = []
    arms = [0]

    async def send(_link: object, _sysid: int, command: int, *_p: float) -> int:
        sent.append(command)
        denied = len(sent) <= denials
        return int(mav.MAV_RESULT_DENIED if denied else mav.MAV_RESULT_ACCEPTED)

    async def arm(_action: object, _wait_s: float) -> None:
        arms[0] += 1

    async def no_param(*_a: object) -> None:
        return None

    monkeypatch.setattr(r, "_send_command", send)
    monkeypatch.setattr(r, "_arm_retrying", arm)
    monkeypatch.setattr(r, "MISSION_START_RETRY_S", 0.0)
    param = SimpleNamespace(set_param_float=no_param)
    mission = SimpleNamespace(cruise_speed_m_s=5.0)
    run = r._start_px4(None, 1, param, None, mission, lambda _m: None)  # type: ignore[arg-type]
    if ok:
        asyncio.run(run)
        assert sent == [mav.MAV_CMD_MISSION_START] * 3 and arms[0] == 3
    else:
        with pytest.raises(LinkError, match=r"MAV_RESULT_DENIED \(asked 10 times\)"):
            asyncio.run(run)
        assert len(sent) == r.MISSION_START_TRIES
