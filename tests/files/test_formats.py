"""Mission files, checked by the programs that read them: MAVSDK's importers, pymavlink's loader.

What MAVSDK 4.1.0's importers do with our files (asserted below):

* ``.plan`` on ArduPilot: ``plannedHomePosition`` becomes seq 0 (NAV_WAYPOINT, frame
  GLOBAL_INT, AMSL altitude), then our items: exactly ``Mission.upload_items()`` but for the
  home frame (5 instead of 0; ArduPilot treats both as AMSL). On PX4: our items only, no home.
* ``.waypoints`` on ArduPilot: the importer puts a copy of line 0 in front, so home appears
  twice (seq 0 frame 5 and seq 1 frame 0). On PX4 it keeps line 0 as an ordinary item, so home
  becomes a waypoint at ground level. Either way the importer's list is not what to upload.
* NaN survives both importers (``null`` in a ``.plan``, ``NaN`` in a ``.waypoints``);
  latitude and longitude arrive exactly on the 1e-7 degree grid; params and z as float32.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.autopilot import Autopilot
from pymavlink import mavwp
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.mavlink_peer import mavsdk_autopilot

import urpt_gcs.files.formats as formats
from urpt_gcs.errors import MissionFileError
from urpt_gcs.files.formats import plan_json, read_plan, read_waypoints, waypoints_text
from urpt_gcs.files.formats.qgc_plan import ReplayCheck, read_replay_check
from urpt_gcs.flight.mission import (
    AUTOPILOT_OF,
    DEFAULT_SPEED_M_S,
    FIRMWARES,
    Firmware,
    GeoPoint,
    Mission,
    MissionItem,
    MissionSettings,
    build_mission,
)
from urpt_gcs.site.targets import Target

HOME = GeoPoint(47.397742, 8.545594, 488.5)
# Seven decimals, so a lost digit shows.
WAYPOINTS = [
    (47.3981234, 8.5461234),
    (47.3984568, 8.5467891),
    (47.3979001, 8.5449999),
    (47.3976543, 8.5453219),
]
ALTITUDE_M = 40.0
FENCE = [(47.3960, 8.5430), (47.3995, 8.5430), (47.3995, 8.5480), (47.3960, 8.5480)]
MAVSDK_AUTOPILOT = {"ardupilot": Autopilot.ARDUPILOT, "px4": Autopilot.PX4}


def make_mission(firmware: Firmware) -> Mission:
    return build_mission(HOME, WAYPOINTS, ALTITUDE_M, MissionSettings(firmware=firmware))


@pytest.fixture(params=FIRMWARES)
def mission(request: pytest.FixtureRequest) -> Mission:
    firmware: Firmware = request.param
    return make_mission(firmware)


# --- comparing items -------------------------------------------------------------------------

Row = tuple[Any, ...]


def f32(value: float) -> float | str:
    """A value as MISSION_ITEM_INT carries it (float32), NaN made comparable."""
    return "nan" if math.isnan(value) else float(np.float32(value))


def expected_row(item: MissionItem) -> Row:
    return (
        item.command,
        item.frame,
        int(item.autocontinue),
        *(f32(p) for p in item.params[:4]),
        item.x_int,
        item.y_int,
        f32(item.z),
    )


def imported_row(raw: Any) -> Row:
    return (
        raw.command,
        raw.frame,
        raw.autocontinue,
        f32(raw.param1),
        f32(raw.param2),
        f32(raw.param3),
        f32(raw.param4),
        raw.x,
        raw.y,
        f32(raw.z),
    )


def mission_key(mission: Mission) -> Row:
    """Everything in a mission, with NaN made comparable."""
    items = tuple(
        (
            item.command,
            item.frame,
            tuple("nan" if math.isnan(p) else p for p in item.params),
            item.autocontinue,
        )
        for item in mission.items
    )
    return (
        mission.home,
        mission.firmware,
        mission.altitude_rel_m,
        mission.cruise_speed_m_s,
        mission.hover_speed_m_s,
        items,
    )


def mavsdk_import(firmware: Firmware, importer: str, text: str) -> Any:
    """Run one of MAVSDK's importers against a heartbeat-only autopilot of that firmware."""

    async def run() -> Any:
        async with mavsdk_autopilot(AUTOPILOT_OF[firmware]) as system:
            assert await system.autopilot_type() == MAVSDK_AUTOPILOT[firmware]
            plugin = MissionRawAsync(system)
            try:
                return await getattr(plugin, importer)(text)
            finally:
                plugin.destroy()

    return asyncio.run(run())


# --- the public API --------------------------------------------------------------------------


def test_exported_names() -> None:
    assert sorted(formats.__all__) == ["plan_json", "read_plan", "read_waypoints", "waypoints_text"]


# --- .plan -----------------------------------------------------------------------------------


def _strict_json(text: str) -> Any:
    def reject(name: str) -> None:
        raise AssertionError(f"{name} is not JSON")

    return json.loads(text, parse_constant=reject)


def test_plan_structure(mission: Mission) -> None:
    plan = _strict_json(plan_json(mission))

    assert plan["fileType"] == "Plan"
    assert plan["version"] == 1
    assert plan["groundStation"] == "urpt-gcs"
    assert plan["geoFence"] == {"version": 2, "polygons": [], "circles": []}
    assert plan["rallyPoints"] == {"version": 2, "points": []}
    body = plan["mission"]
    assert body["version"] == 2
    assert body["firmwareType"] == {"ardupilot": 3, "px4": 12}[mission.firmware]
    assert body["vehicleType"] == mavlink.MAV_TYPE_QUADROTOR == 2
    assert body["cruiseSpeed"] == mission.cruise_speed_m_s
    assert body["hoverSpeed"] == mission.hover_speed_m_s
    assert body["plannedHomePosition"] == [HOME.lat_deg, HOME.lon_deg, HOME.amsl_m]
    # Home is not an item: QGroundControl and MAVSDK add it from plannedHomePosition.
    assert len(body["items"]) == len(mission.items)
    for index, (json_item, item) in enumerate(zip(body["items"], mission.items, strict=True)):
        assert json_item["type"] == "SimpleItem"
        assert json_item["command"] == item.command
        assert json_item["frame"] == item.frame
        assert json_item["autoContinue"] is True
        assert json_item["doJumpId"] == index + 1
        params = json_item["params"]
        assert len(params) == 7
        for written, param in zip(params, item.params, strict=True):
            assert written is None if math.isnan(param) else written == param
        if item.frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT:
            assert json_item["AltitudeMode"] == 1
            assert json_item["Altitude"] == item.z
            assert json_item["AMSLAltAboveTerrain"] is None
        else:
            assert "AltitudeMode" not in json_item


def test_plan_nan_is_null_for_px4_only() -> None:
    nulls = {
        firmware: sum(
            p is None
            for item in _strict_json(plan_json(make_mission(firmware)))["mission"]["items"]
            for p in item["params"]
        )
        for firmware in FIRMWARES
    }
    assert nulls["ardupilot"] == 0
    # Gimbal pitch/yaw rates (2) and the yaw of each of the four waypoints.
    assert nulls["px4"] == 2 + len(WAYPOINTS)


def test_plan_geofence_polygon() -> None:
    plan = _strict_json(plan_json(make_mission("ardupilot"), FENCE))
    assert plan["geoFence"]["polygons"] == [
        {"inclusion": True, "polygon": [list(v) for v in FENCE], "version": 1}
    ]


def test_mavsdk_imports_plan(mission: Mission) -> None:
    text = plan_json(mission, FENCE)
    data = mavsdk_import(mission.firmware, "import_qgroundcontrol_mission_from_string", text)

    rows = [imported_row(raw) for raw in data.mission_items]
    assert [raw.seq for raw in data.mission_items] == list(range(len(rows)))
    assert {raw.mission_type for raw in data.mission_items} == {mavlink.MAV_MISSION_TYPE_MISSION}
    if mission.firmware == "ardupilot":
        # plannedHomePosition becomes seq 0 as GLOBAL_INT; ours (upload_items) uses GLOBAL.
        home = replace(mission.home_item, frame=mavlink.MAV_FRAME_GLOBAL_INT)
        assert rows == [expected_row(home)] + [expected_row(i) for i in mission.items]
        assert rows[1:] == [expected_row(i) for i in mission.upload_items()[1:]]
        assert rows[0][7:] == (round(HOME.lat_deg * 1e7), round(HOME.lon_deg * 1e7), 488.5)
    else:
        # PX4 keeps home apart: the items are exactly ours.
        assert rows == [expected_row(i) for i in mission.upload_items()]
        assert sum(row.count("nan") for row in rows) == 2 + len(WAYPOINTS)

    fence = data.geofence_items
    assert [(raw.command, raw.frame, raw.param1, raw.x, raw.y) for raw in fence] == [
        (
            mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            mavlink.MAV_FRAME_GLOBAL,
            float(len(FENCE)),
            round(lat * 1e7),
            round(lon * 1e7),
        )
        for lat, lon in FENCE
    ]
    assert {raw.mission_type for raw in fence} == {mavlink.MAV_MISSION_TYPE_FENCE}
    assert data.rally_items == []


def test_the_replay_check_is_ignored_by_mavsdk_and_read_back(mission: Mission) -> None:
    """The urptGcs key: MAVSDK's importer (like QGroundControl, which validates only the keys
    it knows) takes the plan as without it; read_replay_check reads it back exactly."""
    check = ReplayCheck(40.0, 12.5, (Target("T1", 47.3981234, 8.5461234),), 2, 3)
    with_check = plan_json(mission, geofence=FENCE, check=check)
    assert json.loads(with_check)["urptGcs"]["fovDeg"] == 40.0
    plain = mavsdk_import(mission.firmware, "import_qgroundcontrol_mission_from_string",
                          plan_json(mission, geofence=FENCE))  # fmt: skip
    checked = mavsdk_import(
        mission.firmware, "import_qgroundcontrol_mission_from_string", with_check
    )
    assert [imported_row(r) for r in checked.mission_items] == [
        imported_row(r) for r in plain.mission_items
    ]
    assert mission_key(read_plan(with_check, "m.plan")) == mission_key(mission)
    assert read_replay_check(with_check, "m.plan") == check
    assert read_replay_check(plan_json(mission), "m.plan") is None


def test_plan_round_trip(mission: Mission) -> None:
    assert mission_key(read_plan(plan_json(mission), "m.plan")) == mission_key(mission)


# --- .waypoints ------------------------------------------------------------------------------


def test_waypoints_layout(mission: Mission) -> None:
    text = waypoints_text(mission)
    assert "\r" not in text
    assert text.endswith("\n")
    lines = text.split("\n")[:-1]
    assert lines[0] == "QGC WPL 110"
    assert len(lines) == 2 + len(mission.items)
    for seq, line in enumerate(lines[1:]):
        fields = line.split("\t")
        assert len(fields) == 12
        assert fields[0] == str(seq)
        assert fields[1] == ("1" if seq == 0 else "0")
        for number in fields[4:11]:
            assert number == "NaN" or re.fullmatch(r"-?[0-9]+\.[0-9]{8,}", number), number
    assert lines[1].split("\t")[2:4] == ["0", "16"]
    assert lines[1].split("\t")[8:11] == ["47.39774200", "8.54559400", "488.50000000"]


def test_pymavlink_loads_waypoints(mission: Mission, tmp_path: Path) -> None:
    path = tmp_path / "m.waypoints"
    path.write_text(waypoints_text(mission))
    loader = mavwp.MAVWPLoader()

    assert loader.load(str(path)) == 1 + len(mission.items)
    home = loader.wp(0)
    assert (home.seq, home.current, home.frame, home.command) == (0, 1, 0, 16)
    assert home.x == pytest.approx(HOME.lat_deg, abs=1e-7)
    assert home.y == pytest.approx(HOME.lon_deg, abs=1e-7)
    assert home.z == pytest.approx(HOME.amsl_m, abs=0.01)
    for seq, item in enumerate(mission.items, start=1):
        loaded = loader.wp(seq)
        assert (loaded.seq, loaded.current) == (seq, 0)
        assert (loaded.command, loaded.frame, loaded.autocontinue) == (
            item.command,
            item.frame,
            1,
        )
        for got, want in zip(
            (loaded.param1, loaded.param2, loaded.param3, loaded.param4),
            item.params[:4],
            strict=True,
        ):
            assert math.isnan(got) if math.isnan(want) else got == want
        assert loaded.x == pytest.approx(item.params[4], abs=1e-7)
        assert loaded.y == pytest.approx(item.params[5], abs=1e-7)
        assert loaded.z == pytest.approx(item.z, abs=0.01)


def test_we_read_what_pymavlink_writes(mission: Mission, tmp_path: Path) -> None:
    path = tmp_path / "m.waypoints"
    path.write_text(waypoints_text(mission))
    loader = mavwp.MAVWPLoader()
    loader.load(str(path))
    resaved = tmp_path / "resaved.waypoints"
    loader.save(str(resaved))

    back = read_waypoints(resaved.read_text(), str(resaved), mission.firmware)
    # pymavlink writes %f: 6 decimals, so positions come back to 1e-6 degrees.
    assert back.home.lat_deg == pytest.approx(HOME.lat_deg, abs=1e-6)
    assert len(back.items) == len(mission.items)
    for got, want in zip(back.items, mission.items, strict=True):
        assert (got.command, got.frame) == (want.command, want.frame)
        assert np.allclose(got.params, want.params, atol=1e-6, equal_nan=True)


def test_mavsdk_imports_waypoints(mission: Mission) -> None:
    text = waypoints_text(mission)
    data = mavsdk_import(mission.firmware, "import_mission_planner_mission_from_string", text)

    rows = [imported_row(raw) for raw in data.mission_items]
    assert [raw.seq for raw in data.mission_items] == list(range(len(rows)))
    assert [raw.current for raw in data.mission_items] == [1] + [0] * (len(rows) - 1)
    line_0 = expected_row(mission.home_item)
    items = [expected_row(i) for i in mission.items]
    if mission.firmware == "ardupilot":
        # The importer copies line 0 in front of it: home twice. Its list is the upload list
        # with an extra home at seq 0, which would shift every item by one on the vehicle.
        copy = expected_row(replace(mission.home_item, frame=mavlink.MAV_FRAME_GLOBAL_INT))
        assert rows == [copy, line_0, *items]
        assert rows[1:] == [expected_row(i) for i in mission.upload_items()]
    else:
        # Line 0 stays as the first item: PX4 would fly to home at its ground (AMSL) altitude.
        assert rows == [line_0, *items]
        assert sum(row.count("nan") for row in rows) == 2 + len(WAYPOINTS)
    assert data.geofence_items == []


def test_waypoints_round_trip(mission: Mission) -> None:
    back = read_waypoints(waypoints_text(mission), "m.waypoints", mission.firmware)
    assert mission_key(back) == mission_key(mission)


# --- invariants ------------------------------------------------------------------------------

coordinates = st.tuples(
    st.floats(min_value=-89.9, max_value=89.9), st.floats(min_value=-179.9, max_value=179.9)
)


@settings(max_examples=50, deadline=None)
@given(
    home=coordinates,
    home_amsl_m=st.floats(min_value=-400.0, max_value=8000.0),
    waypoints=st.lists(coordinates, min_size=1, max_size=5),
    altitude_m=st.floats(min_value=0.5, max_value=500.0),
    hold_s=st.floats(min_value=0.0, max_value=3600.0),
    speed_m_s=st.floats(min_value=0.1, max_value=50.0),
    firmware=st.sampled_from(FIRMWARES),
)
def test_both_formats_round_trip_exactly(
    home: tuple[float, float],
    home_amsl_m: float,
    waypoints: list[tuple[float, float]],
    altitude_m: float,
    hold_s: float,
    speed_m_s: float,
    firmware: Firmware,
) -> None:
    settings_ = MissionSettings(
        firmware=firmware, hold_s=hold_s, cruise_speed_m_s=speed_m_s, hover_speed_m_s=speed_m_s
    )
    mission = build_mission(GeoPoint(*home, home_amsl_m), waypoints, altitude_m, settings_)
    assert mission_key(read_plan(plan_json(mission), "m.plan")) == mission_key(mission)
    back = read_waypoints(waypoints_text(mission), "m.waypoints", firmware)
    # .waypoints has no speed fields: the speed is read from the DO_CHANGE_SPEED item.
    assert mission_key(back) == mission_key(mission)


def test_the_speed_is_set_after_the_take_off(mission: Mission) -> None:
    """DO_CHANGE_SPEED right after NAV_TAKEOFF: both firmwares run it when the climb is done,
    before the first leg; ground speed, throttle unchanged (-1)."""
    first, speed = mission.items[:2]
    assert first.command == mavlink.MAV_CMD_NAV_TAKEOFF
    assert speed.command == mavlink.MAV_CMD_DO_CHANGE_SPEED
    assert speed.params[:4] == (mavlink.SPEED_TYPE_GROUNDSPEED, 5.0, -1.0, 0.0)
    assert mission.cruise_speed_m_s == 5.0 == MissionSettings().cruise_speed_m_s
    no_speed = replace(mission, items=(first, *mission.items[2:]))
    back = read_waypoints(waypoints_text(no_speed), "m.waypoints", mission.firmware)
    assert back.cruise_speed_m_s == DEFAULT_SPEED_M_S


# --- bad files -------------------------------------------------------------------------------


def _plan_with(change: str) -> str:
    plan = json.loads(plan_json(make_mission("ardupilot")))
    body = plan["mission"]
    if change == "wrong fileType":
        plan["fileType"] = "GeoFence"
    elif change == "ComplexItem":
        body["items"][2] = {"type": "ComplexItem", "complexItemType": "survey", "version": 5}
    elif change == "6 params":
        body["items"][0]["params"] = body["items"][0]["params"][:6]
    elif change == "no plannedHomePosition":
        del body["plannedHomePosition"]
    elif change == "no items":
        del body["items"]
    elif change == "no mission":
        del plan["mission"]
    elif change == "unknown firmwareType":
        body["firmwareType"] = 0
    elif change == "text param":
        body["items"][4]["params"][0] = "2"
    elif change == "null latitude":
        body["items"][3]["params"][4] = None
    elif change == "huge integer":
        body["items"][3]["params"][0] = 10**400
    elif change == "negative hold":
        body["items"][3]["params"][0] = -5
    elif change == "yaw 1e20":
        body["items"][3]["params"][3] = 1e20
    elif change == "below any ground":
        body["items"][3]["params"][6] = -1000.0
    elif change == "null hold":
        body["items"][3]["params"][0] = None
    elif change == "latitude 95":
        body["items"][3]["params"][4] = 95.0
    elif change == "zero speed":
        assert body["items"][1]["command"] == 178  # DO_CHANGE_SPEED after the take-off
        body["items"][1]["params"][1] = 0
    elif change == "65535 items":
        body["items"] += [body["items"][2]] * (65_535 - len(body["items"]))
    return json.dumps(plan)


BAD_PLANS = {
    "not JSON": ("QGC WPL 110\n", "not valid JSON"),
    "JSON NaN": ('{"fileType": NaN}', "not valid JSON"),
    "JSON list": ("[1, 2]", "not a plan"),
    "wrong fileType": (_plan_with("wrong fileType"), "fileType is 'GeoFence', not 'Plan'"),
    "ComplexItem": (
        _plan_with("ComplexItem"),
        "unsupported item type 'ComplexItem' ('survey') at index 2: flatten it in QGroundControl",
    ),
    "6 params": (_plan_with("6 params"), "index 0: params must be a list of 7 numbers"),
    "no plannedHomePosition": (_plan_with("no plannedHomePosition"), "plannedHomePosition"),
    "no items": (_plan_with("no items"), "mission.items is missing"),
    "no mission": (_plan_with("no mission"), "no mission section"),
    "unknown firmwareType": (_plan_with("unknown firmwareType"), "firmwareType 0 is not supp"),
    "text param": (_plan_with("text param"), "index 4: params must be a list of 7 numbers"),
    "null latitude": (_plan_with("null latitude"), "index 3: params 5-7 (x, y, z) must be numbers"),
    "huge integer": (_plan_with("huge integer"), "index 3: params must be a list"),
    "negative hold": (
        _plan_with("negative hold"),
        "index 3 (NAV_WAYPOINT): param1 (hold) -5 s is out of range (ArduPilot would keep "
        "65531 s): give a hold of 0 to 65535 seconds",
    ),
    "yaw 1e20": (
        _plan_with("yaw 1e20"),
        "index 3 (NAV_WAYPOINT): param4 (yaw) 1e+20 deg is out of range: give a yaw of -360",
    ),
    "below any ground": (
        _plan_with("below any ground"),
        "index 3 (NAV_WAYPOINT): altitude (param7) -1000 m relative to home (488.5 m AMSL) is "
        "-511.5 m AMSL, below the lowest ground on Earth: give an altitude of -988.5 m or more",
    ),
    "null hold": (_plan_with("null hold"), "index 3 (NAV_WAYPOINT): param1 (hold) is NaN"),
    "latitude 95": (_plan_with("latitude 95"), "latitude (param5) 95 is not in [-90, 90]"),
    "zero speed": (
        _plan_with("zero speed"),
        "index 1 (DO_CHANGE_SPEED): param2 (speed) 0 m/s is out of range: give a speed above 0",
    ),
    "65535 items": (
        _plan_with("65535 items"),
        "65536 mission items (65535 and ArduPilot's home item) are more than the 65535",
    ),
}


@pytest.mark.parametrize("name", BAD_PLANS)
def test_bad_plan_is_a_mission_file_error(name: str) -> None:
    text, expected = BAD_PLANS[name]
    with pytest.raises(MissionFileError) as raised:
        read_plan(text, "survey.plan")
    message = str(raised.value)
    assert message.startswith("survey.plan: ")
    assert expected in message
    assert "\n" not in message


def _waypoints_with(line: int, fields: str) -> str:
    lines = waypoints_text(make_mission("ardupilot")).split("\n")
    lines[line] = fields
    return "\n".join(lines)


BAD_WAYPOINTS = {
    "wrong header": ("QGC WPL 100\n0\t1\t0\t16\n", "line 1 is 'QGC WPL 100', not 'QGC WPL 110'"),
    "only header": ("QGC WPL 110\n", "no home line"),
    "only home": ("".join(waypoints_text(make_mission("px4")).splitlines(True)[:2]), "no items"),
    "11 fields": (_waypoints_with(3, "2\t0\t3\t16\t0\t0\t0\t0\t47.1\t8.5\t40"), "line 4 has 11"),
    "text field": (
        _waypoints_with(3, "2\t0\t3\t16\tfast\t0\t0\t0\t47.1\t8.5\t40\t1"),
        "line 4: param1 'fast' is not a finite number",
    ),
    "float command": (
        _waypoints_with(3, "2\t0\t3\t16.0\t0\t0\t0\t0\t47.1\t8.5\t40\t1"),
        "line 4: command '16.0' is not an integer",
    ),
    "NaN latitude": (
        _waypoints_with(3, "2\t0\t3\t16\t0\t0\t0\t0\tNaN\t8.5\t40\t1"),
        "line 4: params 5-7 (x, y, z) must be numbers",
    ),
    "home off the globe": (
        _waypoints_with(1, "0\t1\t0\t16\t0\t0\t0\t0\t147.1\t8.5\t40\t1"),
        "line 2 (home) is not usable",
    ),
    "duplicated line": (
        _waypoints_with(3, "2\t0\t3\t16\t0\t0\t0\t0\t47.1\t8.5\t40\t1\n" * 2),
        "line 5: seq 2, expected 3: seq must count 0 (home), 1, 2, ... one line per item",
    ),
    "home seq 1": (
        _waypoints_with(1, "1\t1\t0\t16\t0\t0\t0\t0\t47.1\t8.5\t400\t1"),
        "line 2: seq 1, expected 0",
    ),
    "current 2": (
        _waypoints_with(3, "2\t2\t3\t16\t0\t0\t0\t0\t47.1\t8.5\t40\t1"),
        "line 4: current 2 is not 0 or 1",
    ),
    "negative hold": (
        _waypoints_with(3, "2\t0\t3\t16\t-5\t0\t0\t0\t47.1\t8.5\t40\t1"),
        "line 4 (NAV_WAYPOINT): param1 (hold) -5 s is out of range",
    ),
    "65536 lines": (
        "QGC WPL 110\n" + "0\t0\t3\t16\t0\t0\t0\t0\t47.1\t8.5\t40\t1\n" * 65_536,
        "65536 mission items (65535 and ArduPilot's home item) are more than the 65535",
    ),
}


@pytest.mark.parametrize("name", BAD_WAYPOINTS)
def test_bad_waypoints_is_a_mission_file_error(name: str) -> None:
    text, expected = BAD_WAYPOINTS[name]
    with pytest.raises(MissionFileError) as raised:
        read_waypoints(text, "survey.waypoints")
    message = str(raised.value)
    assert message.startswith("survey.waypoints: ")
    assert expected in message
    assert "\n" not in message


def _reads_or_refuses(read: Any, text: str) -> None:
    try:
        mission = read(text, "fuzz")
    except MissionFileError as exc:
        assert "\n" not in str(exc)
    else:
        assert isinstance(mission, Mission)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=8) | st.dictionaries(st.text(max_size=8), children)
    ),
    max_leaves=20,
)


@settings(max_examples=100, deadline=None)
@given(text=st.text(max_size=300))
def test_fuzz_arbitrary_text(text: str) -> None:
    _reads_or_refuses(read_plan, text)
    _reads_or_refuses(read_waypoints, text)


@settings(max_examples=100, deadline=None)
@given(
    path=st.lists(st.sampled_from(["mission", "items", 0, 2, "params", 4, "x"]), max_size=4),
    value=json_values,
)
def test_fuzz_plan_with_one_value_replaced(path: list[str | int], value: Any) -> None:
    plan: Any = json.loads(plan_json(make_mission("px4")))
    if not path:
        plan = value
    node = plan
    for key in path[:-1]:
        with contextlib.suppress(KeyError, IndexError, TypeError):
            node = node[key]
    if path:
        with contextlib.suppress(IndexError, TypeError):
            node[path[-1]] = value
    _reads_or_refuses(read_plan, json.dumps(plan))


@settings(max_examples=100, deadline=None)
@given(body=st.text(alphabet="0123456789.-+eEnaN\t\n #x", max_size=200))
def test_fuzz_waypoints_body(body: str) -> None:
    _reads_or_refuses(read_waypoints, "QGC WPL 110\n" + body)
