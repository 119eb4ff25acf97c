"""Upload with read-back: the real MAVSDK on one side, the simulated vehicle on the other.

Every test here goes over loopback UDP through MAVSDK 4.x's ``mission_raw`` to a
:class:`~urpt_gcs.sim.SitlServer`; what the vehicle then holds is read from the simulator
itself, so a success reported by the uploader is checked against the vehicle's real state.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import replace
from typing import Any

import pytest
from click.testing import CliRunner
from conftest import DEMO
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.simulated import DEMO_PLAN, demo_mission, simulated

from urpt_gcs.cli import main
from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.flight.mission import (
    GeoPoint,
    Mission,
    MissionItem,
    MissionSettings,
    build_mission,
    upload_problem,
)
from urpt_gcs.flight.wire import WireItem, wire_items
from urpt_gcs.sim.server import SitlServer
from urpt_gcs.sim.store import Item, ardupilot_stored, px4_stored
from urpt_gcs.vehicle import mavsdk_link
from urpt_gcs.vehicle.link import UploadReport, UploadSettings, upload, upload_verified
from urpt_gcs.vehicle.protocol import (
    AutopilotKind,
    LinkTimeout,
    MissionRejected,
    UploadUnconfirmed,
)
from urpt_gcs.vehicle.readback import compare

WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT


def held(server: SitlServer) -> list[WireItem]:
    """What the simulated vehicle holds, as a download returns it."""
    return [
        WireItem(seq, i.frame, i.command, 0, i.autocontinue, *i.params, i.x, i.y, i.z)
        for seq, i in enumerate(server.vehicle.store.items())
    ]


def assert_holds(server: SitlServer, mission: Mission) -> None:
    sent = wire_items(mission)
    got = held(server)
    assert compare(sent, got, mission.firmware).equal
    waypoints = [(w.x, w.y) for w in sent if w.command == WAYPOINT]
    assert [(w.x, w.y) for w in got if w.command == WAYPOINT][-len(waypoints) :] == waypoints


# --- the demo mission ------------------------------------------------------------------------


def test_demo_mission_uploads_and_reads_back_identical() -> None:
    mission = demo_mission()
    with simulated(mission) as (server, url):
        started = time.monotonic()
        report = upload(mission, url)
        total = time.monotonic() - started
        print(f"\ndemo upload, no loss: {report.elapsed_s:.3f} s ({total:.2f} s with connect)")
        assert_holds(server, mission)
    assert report.attempts == 1
    assert report.items == len(mission.items) + 1
    assert report.autopilot == report.firmware == "ardupilot"
    assert report.vehicle_home is not None
    assert report.vehicle_home.lat_deg == pytest.approx(mission.home.lat_deg, abs=1e-7)
    assert report.warnings == ()


def test_plan_then_upload_from_the_command_line(tmp_path) -> None:
    with simulated(demo_mission()) as (server, url):
        result = CliRunner().invoke(
            main,
            [
                "plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml"),
                "--out", str(tmp_path / "out"), "--time-limit", "1", "--no-map", "--quiet",
                "--upload", "--connect", url,
            ],
        )  # fmt: skip
        assert result.exit_code == 0, result.output + result.stderr
        assert "read back identical" not in result.output  # --quiet
        planned = (tmp_path / "out" / "mission.plan").read_text()
        from urpt_gcs.files.formats import read_plan

        assert_holds(server, read_plan(planned, "mission.plan"))


def test_upload_command_prints_one_line() -> None:
    with simulated(demo_mission()) as (_server, url):
        result = CliRunner().invoke(main, ["upload", str(DEMO_PLAN), "--connect", url])
    assert result.exit_code == 0, result.stderr
    assert result.stdout.startswith("uploaded 29 items to ")
    assert "read back identical" in result.stdout
    # The simulated copter keeps no fences: the mission goes up alone, with a warning.
    assert result.stderr == (
        "urpt-gcs: warning: the vehicle refused the geofence (MAV_MISSION_UNSUPPORTED): it "
        "flies the mission without the plan's fence; set one on the vehicle if it needs one\n"
    )


def test_no_vehicle_is_one_clear_line() -> None:
    result = CliRunner().invoke(
        main, ["upload", str(DEMO_PLAN), "--connect", "udpin://127.0.0.1:9", "--timeout", "1"]
    )
    assert result.exit_code == 1
    assert result.stderr.startswith("urpt-gcs: error: no autopilot heard on udpin://127.0.0.1:9")
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("firmware", "suffix"),
    [("ardupilot", ".plan"), ("ardupilot", ".waypoints"), ("px4", ".plan")],
)
def test_what_the_planner_writes_passes_the_checks_and_reads_back(
    firmware: str, suffix: str, tmp_path
) -> None:
    """The checks before upload refuse nothing the planner writes, for either firmware."""
    from urpt_gcs.files.formats import plan_json, waypoints_text

    demo = demo_mission()
    waypoints = [(i.params[4], i.params[5]) for i in demo.items if i.command == WAYPOINT]
    settings_ = MissionSettings(firmware=firmware, hold_s=2.5)  # type: ignore[arg-type]
    mission = build_mission(demo.home, waypoints, demo.altitude_rel_m, settings_)
    assert upload_problem(mission) is None
    path = tmp_path / f"mission{suffix}"
    path.write_text(plan_json(mission) if suffix == ".plan" else waypoints_text(mission))
    with simulated(mission, px4=firmware == "px4") as (server, url):
        result = CliRunner().invoke(main, ["upload", str(path), "--connect", url])
        assert result.exit_code == 0, result.stderr
        assert_holds(server, mission)
    assert "read back identical" in result.output


# --- firmware conventions --------------------------------------------------------------------


def test_px4_vehicle_gets_no_home_item() -> None:
    ardupilot = demo_mission()
    waypoints = [(i.params[4], i.params[5]) for i in ardupilot.items if i.command == WAYPOINT]
    mission = build_mission(
        ardupilot.home, waypoints, ardupilot.altitude_rel_m, MissionSettings(firmware="px4")
    )
    with simulated(mission, px4=True) as (server, url):
        report = upload(mission, url)
        store = server.vehicle.store
        assert len(store) == len(mission.items)
        assert store.read(0).command == mavlink.MAV_CMD_NAV_TAKEOFF
        assert_holds(server, mission)
    assert report.autopilot == "px4"
    assert report.items == len(mission.items)
    assert report.vehicle_home is None


def test_mission_for_the_other_firmware_is_refused() -> None:
    with simulated(px4=True) as (_server, url), pytest.raises(LinkError) as raised:
        upload(demo_mission(), url)
    assert "planned for ArduPilot but the vehicle" in str(raised.value)
    assert "--firmware px4" in str(raised.value)


# --- a bad link ------------------------------------------------------------------------------


def test_twenty_percent_loss_each_way_verifies() -> None:
    """Part of the demo mission (13 items, to keep the test short: every lost packet costs
    about a second) through 20 % loss each way, with the default retries.

    The seed fixes the simulator's loss draws, but which packet meets which draw can still
    shift with timing, so the test rests on margin: 30 runs of exactly this case
    (``benchmarks/upload_loss.py --items 12 --seed 3 --same-seed --loss 0.2``) all verified on
    the first attempt, in at most 13 s; with the whole demo mission 2 of 80 runs needed a
    second attempt, and failing needs all four to fail.
    """
    demo = demo_mission()
    mission = replace(demo, items=demo.items[:12])
    with simulated(mission, loss=0.2, seed=3) as (server, url):
        report = upload(mission, url)
        assert_holds(server, mission)
    print(f"\n20 % loss, 13 items: {report.elapsed_s:.1f} s, {report.attempts} attempt(s)")
    assert report.items == 13


def _drop_first_acceptance(server: SitlServer) -> list[Any]:
    """Make the simulator lose its first MISSION_ACK ACCEPTED; returns what it dropped."""
    link = server._link
    send = link.send
    dropped: list[Any] = []

    def lossy_send(msg: Any, now: float) -> None:
        accepted = msg.get_type() == "MISSION_ACK" and msg.type == mavlink.MAV_MISSION_ACCEPTED
        if accepted and not dropped:
            dropped.append(msg)
            return
        send(msg, now)

    link.send = lossy_send  # type: ignore[method-assign]
    return dropped


def test_lost_acceptance_is_settled_by_the_read_back(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """The vehicle stores every item but its MISSION_ACK is lost: the read-back, not a second
    upload, decides; MAVSDK's longer upload timeout shows in its own log."""
    monkeypatch.setenv("MAVSDK_MISSION_TRANSFER_DEBUGGING", "1")
    caplog.set_level(logging.DEBUG, logger="urpt_gcs.mavsdk")
    mission = demo_mission()
    messages: list[str] = []
    with simulated(mission) as (server, url):
        dropped = _drop_first_acceptance(server)
        report = upload(mission, url, retries=0, progress=messages.append)
        assert_holds(server, mission)
    assert dropped
    assert report.attempts == 1
    assert any("acceptance did not come: reading the mission back" in m for m in messages)
    # Waiting for the lost acceptance, MAVSDK at its default 0.5 s would time out five times and
    # give up by itself after 2.5 s; at 2 s it times out once before the 3.5 s wait ends.
    timeouts = [r for r in caplog.records if r.getMessage().startswith("Timeout triggered")]
    assert 1 <= len(timeouts) <= 2


def test_lost_acceptance_and_a_wrong_read_back_is_never_success() -> None:
    mission = demo_mission()
    with (
        simulated(mission, corrupt_seq=6) as (server, url),
        pytest.raises(LinkError) as raised,
    ):
        dropped = _drop_first_acceptance(server)
        upload(mission, url, retries=0)
    assert dropped
    assert "seq 6 (NAV_WAYPOINT): x (param5)" in str(raised.value)
    assert "do not fly it" in str(raised.value)


def test_corrupted_read_back_is_never_success() -> None:
    mission = demo_mission()
    with simulated(mission, corrupt_seq=6) as (_server, url), pytest.raises(LinkError) as raised:
        upload(mission, url, retries=1)
    message = str(raised.value)
    assert "after 2 attempts" in message
    assert "seq 6 (NAV_WAYPOINT): x (param5)" in message
    assert "do not fly it" in message


def test_a_short_link_drop_mid_upload_is_ridden_out() -> None:
    """Silent for 3 s after item 10: MAVSDK (2 s timeout) answers the vehicle's next request."""
    mission = demo_mission()
    with simulated(mission, drop_after=10, drop_s=3.0) as (server, url):
        report = upload(mission, url)
        assert_holds(server, mission)
    assert report.attempts == 1


@pytest.fixture
def impatient_mavsdk(monkeypatch: pytest.MonkeyPatch) -> None:
    """MAVSDK's default upload timeout (0.5 s: it gives up after 2.5 s of silence), so that a
    3 s drop outlasts it and the tests of what follows stay short."""
    monkeypatch.setattr(mavsdk_link, "UPLOAD_TIMEOUT_S", mavsdk_link.DOWNLOAD_TIMEOUT_S)


@pytest.mark.usefixtures("impatient_mavsdk")
def test_link_dropped_mid_upload_is_retried() -> None:
    mission = demo_mission()
    messages: list[str] = []
    with simulated(mission, drop_after=10, drop_s=3.0) as (server, url):
        report = upload(mission, url, progress=messages.append)
        assert_holds(server, mission)
    assert report.attempts >= 2
    assert any(m.startswith("retrying (") for m in messages)


@pytest.mark.usefixtures("impatient_mavsdk")
def test_link_dropped_without_retries_is_a_clear_error() -> None:
    mission = demo_mission()
    with (
        simulated(mission, drop_after=10, drop_s=3.0) as (_server, url),
        pytest.raises(LinkError) as raised,
    ):
        upload(mission, url, retries=0)
    assert "not verified" in str(raised.value)
    assert "partial mission" in str(raised.value)


def test_latency_still_verifies() -> None:
    mission = demo_mission()
    with simulated(mission, latency_ms=40.0) as (server, url):
        upload(mission, url)
        assert_holds(server, mission)


# --- retries inside one attempt (a scripted link, no MAVSDK) ---------------------------------


class ScriptedLink:
    """A VehicleLink that plays a script: how the upload ends and what each read-back gives."""

    url = "scripted://"

    def __init__(
        self,
        upload: Callable[[Callable[[float], None]], Awaitable[None]],
        reads: list[list[WireItem] | LinkError],
    ) -> None:
        self._upload = upload
        self.reads = reads
        self.cancels = 0

    async def autopilot(self) -> AutopilotKind:
        return "ardupilot"

    async def wait_connected(self, timeout_s: float) -> None:
        return None

    async def upload(self, items: Sequence[WireItem], progress: Callable[[float], None]) -> None:
        await self._upload(progress)

    async def download(self) -> list[WireItem]:
        read = self.reads.pop(0)
        if isinstance(read, LinkError):
            raise read
        return read

    async def cancel(self) -> None:
        self.cancels += 1


async def _sent(progress: Callable[[float], None]) -> None:
    progress(1.0)


async def _unconfirmed(progress: Callable[[float], None]) -> None:
    progress(0.9)
    raise UploadUnconfirmed("the vehicle asked for all items but its acceptance did not come")


def _run(link: ScriptedLink, mission: Mission, **settings: Any) -> UploadReport:
    return asyncio.run(upload_verified(link, mission, UploadSettings(**settings)))


def test_a_read_back_that_times_out_is_read_again_not_uploaded_again() -> None:
    mission = demo_mission()
    good = list(wire_items(mission))
    link = ScriptedLink(_sent, [LinkTimeout("no answer"), LinkTimeout("no answer"), good])
    report = _run(link, mission)
    assert report.attempts == 1
    assert link.reads == []


def test_unconfirmed_upload_counts_only_with_an_equal_read_back() -> None:
    mission = demo_mission()
    good = list(wire_items(mission))
    assert _run(ScriptedLink(_unconfirmed, [good]), mission).attempts == 1
    moved = [*good[:3], replace(good[3], x=good[3].x + 10), *good[4:]]
    with pytest.raises(LinkError) as raised:
        _run(ScriptedLink(_unconfirmed, [moved, good[:5]]), mission, retries=1)
    assert "not verified" in str(raised.value)
    assert "read-back differs" in str(raised.value)


def test_a_slow_upload_that_progresses_is_not_cut_off_but_a_stalled_one_is() -> None:
    mission = demo_mission()
    good = list(wire_items(mission))

    async def slow(progress: Callable[[float], None]) -> None:
        for tenth in range(6):
            progress(tenth / 10)
            await asyncio.sleep(0.1)

    async def stalled(progress: Callable[[float], None]) -> None:
        progress(0.1)
        await asyncio.sleep(5.0)

    assert _run(ScriptedLink(slow, [good]), mission, transfer_timeout_s=0.3).attempts == 1
    link = ScriptedLink(stalled, [])
    started = time.monotonic()
    with pytest.raises(LinkError) as raised:
        _run(link, mission, transfer_timeout_s=0.3, retries=0)
    assert time.monotonic() - started < 2.0
    assert "the upload made no progress for 0.3 s" in str(raised.value)
    assert link.cancels == 1


# --- the vehicle says no ---------------------------------------------------------------------


def test_over_capacity_names_no_space() -> None:
    mission = demo_mission()
    with simulated(mission, capacity=10) as (server, url):
        started = time.monotonic()
        with pytest.raises(MissionRejected) as raised:
            upload(mission, url)
        assert time.monotonic() - started < 5.0, "a capacity refusal must not be retried"
        assert len(server.vehicle.store) == 1  # nothing stored but home
    assert raised.value.result == "MAV_MISSION_NO_SPACE"
    assert raised.value.capacity == 10
    assert "holds at most 10 items and the mission has 29" in str(raised.value)


def test_refusal_after_boot_is_waited_out() -> None:
    """ArduPilot's "Only 0 items are supported" while it boots is no capacity: it is waited
    out, and costs no attempt."""
    mission = demo_mission()
    messages: list[str] = []
    with simulated(mission, boot_s=2.5) as (server, url):
        report = upload(mission, url, retries=0, progress=messages.append)
        assert_holds(server, mission)
    assert report.attempts == 1
    assert "the vehicle is still starting: trying again in 0.5 s" in messages


def test_a_vehicle_that_keeps_starting_is_named_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("urpt_gcs.vehicle.transfer.STARTING_WAIT_S", 1.0)
    mission = demo_mission()
    with simulated(mission, boot_s=30.0) as (_server, url), pytest.raises(LinkError) as raised:
        upload(mission, url)
    message = str(raised.value)
    assert "is still starting after 1 s" in message and "'ArduPilot Ready'" in message
    assert "holds at most" not in message


def _one_item_mission(item: MissionItem) -> Mission:
    home = GeoPoint(47.3977420, 8.5455940, 488.0)
    return Mission(home, (item,), "ardupilot", 20.0, 5.0, 5.0)


@pytest.mark.parametrize(
    ("command", "frame", "expected"),
    [
        (WAYPOINT, mavlink.MAV_FRAME_LOCAL_NED, "MAV_MISSION_UNSUPPORTED_FRAME"),
        (mavlink.MAV_CMD_NAV_LOITER_TURNS, RELATIVE, "MAV_MISSION_UNSUPPORTED"),
    ],
)
def test_refusal_names_the_mission_ack(command: int, frame: int, expected: str) -> None:
    item = MissionItem(command, frame, (0, 0, 0, 0, 47.3978, 8.5456, 20.0))
    with simulated() as (_server, url), pytest.raises(MissionRejected) as raised:
        upload(_one_item_mission(item), url)
    assert raised.value.result == expected
    assert raised.value.seq == 1
    assert str(raised.value).startswith(f"{expected}: the vehicle on {url} refused mission")
    name = mavlink.enums["MAV_CMD"][command].name.removeprefix("MAV_CMD_")
    assert f"item seq 1 ({name}): correct it in the plan" in str(raised.value)


@pytest.mark.parametrize(
    ("params", "expected"),
    [
        ((math.nan, 0, 0, 0, 47.3978, 8.5456, 20.0), "param1 (hold) is NaN"),
        ((-5, 0, 0, 0, 47.3978, 8.5456, 20.0), "param1 (hold) -5 s is out of range"),
        ((2, 0, 0, 1e20, 47.3978, 8.5456, 20.0), "param4 (yaw) 1e+20 deg is out of range"),
        ((2, 0, 0, 0, 47.3978, 8.5456, -1000.0), "-512 m AMSL, below the lowest ground"),
        ((2, 0, 0, 0, 91.0, 8.5456, 20.0), "latitude (param5) 91 is not in [-90, 90]"),
    ],
)
def test_unfit_item_is_refused_before_any_transfer(params: tuple, expected: str) -> None:
    mission = _one_item_mission(MissionItem(WAYPOINT, RELATIVE, params))
    with simulated() as (server, url):
        started = time.monotonic()
        with pytest.raises(SettingsError) as raised:
            upload(mission, url)
        assert time.monotonic() - started < 0.5, "refused before connecting"
        assert len(server.vehicle.store) == 1  # nothing stored but home
    assert str(raised.value).startswith("not uploaded: mission item seq 1 (NAV_WAYPOINT): ")
    assert expected in str(raised.value)


def test_a_waypoint_below_home_uploads_with_a_warning() -> None:
    item = MissionItem(WAYPOINT, RELATIVE, (2, 0, 0, 0, 47.3978, 8.5456, -5.0))
    mission = _one_item_mission(item)
    with simulated(mission) as (_server, url):
        report = upload(mission, url)
    assert report.warnings == (
        "mission item seq 1 (NAV_WAYPOINT) flies 5 m below home: make sure the ground there "
        "is lower still, or correct the altitude",
    )


def test_more_items_than_mavlink_counts_is_refused_before_any_transfer() -> None:
    item = MissionItem(WAYPOINT, RELATIVE, (0, 0, 0, 0, 47.3978, 8.5456, 20.0))
    home = GeoPoint(47.3977420, 8.5455940, 488.0)
    fits = Mission(home, (item,) * 65_534, "ardupilot", 20.0, 5.0, 5.0)
    assert upload_problem(fits) is None
    with pytest.raises(SettingsError) as raised:
        upload(replace(fits, items=(item,) * 65_535), "udpin://127.0.0.1:14999")
    assert str(raised.value) == (
        "not uploaded: 65536 mission items (65535 and ArduPilot's home item) are more than the "
        "65535 a MAVLink mission can hold: plan fewer targets or split the mission into sorties"
    )
    assert upload_problem(replace(fits, items=(item,) * 65_535, firmware="px4")) is None


def test_nan_param4_of_a_waypoint_reads_back_as_zero_and_counts_as_equal() -> None:
    item = MissionItem(WAYPOINT, RELATIVE, (2.0, 0, 0, math.nan, 47.3978, 8.5456, 20.0))
    mission = _one_item_mission(item)
    with simulated() as (server, url):
        upload(mission, url)
        assert server.vehicle.store.read(1).param4 == 0.0


# --- the comparison itself -------------------------------------------------------------------


def _item(**changes: object) -> WireItem:
    base = WireItem(1, RELATIVE, WAYPOINT, 0, 1, 2.0, 0.0, 0.0, 0.0, 476888434, 94238428, 68.87)
    return replace(base, **changes)  # type: ignore[arg-type]


HOME = WireItem(0, 0, WAYPOINT, 1, 1, 0.0, 0.0, 0.0, 0.0, 476887616, 94230907, 411.92)


@pytest.mark.parametrize(
    "changes",
    [
        {"x": 476888435},
        {"y": 94238427},
        {"z": 68.85},
        {"param1": 3.0},
        {"command": mavlink.MAV_CMD_NAV_LOITER_UNLIM},
        {"frame": mavlink.MAV_FRAME_GLOBAL},
        {"autocontinue": 0},
    ],
)
def test_every_field_that_matters_is_compared(changes: dict[str, object]) -> None:
    check = compare([HOME, _item()], [HOME, _item(**changes)], "ardupilot")
    assert not check.equal
    assert check.mismatches[0].startswith("seq 1 (NAV_WAYPOINT)")


def test_what_ardupilot_normalises_is_equal() -> None:
    sent = [HOME, _item(frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, param4=math.nan)]
    vehicle_home = replace(HOME, current=0, x=476887000, z=410.0)
    got = [vehicle_home, _item(param4=0.0, z=68.86999)]
    assert compare(sent, got, "ardupilot").equal
    assert not compare(sent, got, "px4").equal
    assert not compare(sent, got[:1], "ardupilot").equal


def test_a_truncated_hold_is_accepted_with_a_warning() -> None:
    check = compare([HOME, _item(param1=2.5)], [HOME, _item(param1=2.0)], "ardupilot")
    assert check.equal
    assert check.warnings == ("seq 1 (NAV_WAYPOINT): the vehicle keeps param1 2.5 as 2",)


coordinates = st.tuples(
    st.integers(-900_000_000, 900_000_000), st.integers(-1_800_000_000, 1_800_000_000)
)


@settings(max_examples=200, deadline=None)
@given(
    xy=coordinates,
    z=st.floats(-500.0, 8000.0),
    hold=st.floats(0.0, 3600.0),
    frame=st.sampled_from([RELATIVE, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 5]),
    nudge=st.sampled_from(["x", "y", "z", None]),
)
def test_simulator_storage_passes_and_any_nudge_fails(
    xy: tuple[int, int], z: float, hold: float, frame: int, nudge: str | None
) -> None:
    """The simulator's model of ArduPilot's storage and the comparison agree; a moved
    waypoint never passes."""
    sent = _item(x=xy[0], y=xy[1], z=z, param1=hold, frame=frame)
    stored = ardupilot_stored(Item(WAYPOINT, frame, hold, 0.0, 0.0, 0.0, xy[0], xy[1], z))
    got = WireItem(1, stored.frame, WAYPOINT, 0, 1, *stored.params, stored.x, stored.y, stored.z)
    if nudge == "x":
        got = replace(got, x=got.x + 1)
    elif nudge == "y":
        got = replace(got, y=got.y - 1)
    elif nudge == "z":
        got = replace(got, z=got.z + 0.05)  # beyond the 1 cm tolerance of either form
    check = compare([HOME, sent], [HOME, got], "ardupilot")
    assert check.equal == (nudge is None)


# --- PX4's read-back (as PX4 v1.16 SITL returned the demo, see urpt_gcs/vehicle/readback.py) ---

RELATIVE_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
CAPTURE = mavlink.MAV_CMD_IMAGE_START_CAPTURE
PX4_SENT = [
    WireItem(0, RELATIVE, TAKEOFF, 1, 1, 0.0, 0.0, 0.0, 0.0, 476887616, 94230907, 68.87),
    WireItem(1, 2, CAPTURE, 0, 1, 0.0, 0.0, 1.0, 0.0, 0, 0, 0.0),
    WireItem(2, RELATIVE, WAYPOINT, 0, 1, 2.0, 0.0, 0.0, math.nan, 476888434, 94238428, 68.87),
]
# Seen: frame 3 as 6, the altitude as float32, ``current`` 1 on the item PX4 is at.
PX4_GOT = [
    replace(PX4_SENT[0], frame=RELATIVE_INT, z=68.87000274658203),
    PX4_SENT[1],
    replace(PX4_SENT[2], frame=RELATIVE_INT, z=68.87000274658203),
]


def test_what_px4_normalises_is_equal() -> None:
    assert compare(PX4_SENT, PX4_GOT, "px4").equal
    assert compare(PX4_SENT, PX4_GOT, "px4").warnings == ()
    # ArduPilot returns frame 3 as sent and replaces seq 0 with home: PX4's form differs.
    assert not compare(PX4_SENT, PX4_GOT, "ardupilot").equal


@pytest.mark.parametrize(
    ("seq", "changes"),
    [
        (0, {"frame": mavlink.MAV_FRAME_GLOBAL_INT}),  # 3 comes back as 6, never 5
        (0, {"frame": mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT}),  # nor as sent
        (0, {"z": 68.85}),
        (0, {"x": 476887617}),
        (1, {"param3": 2.0}),  # a command without a location comes back verbatim
        (1, {"frame": mavlink.MAV_FRAME_GLOBAL}),
        (2, {"param1": 3.0}),  # PX4 keeps the hold as sent (ArduPilot: whole seconds)
        (2, {"param4": 0.0}),  # NaN yaw stays NaN on PX4 (ArduPilot: 0)
        (2, {"y": 94238427}),
        (2, {"autocontinue": 0}),
        (2, {"command": mavlink.MAV_CMD_NAV_LOITER_UNLIM}),
    ],
)
def test_every_change_px4_does_not_make_is_a_mismatch(seq: int, changes: dict[str, Any]) -> None:
    got = list(PX4_GOT)
    got[seq] = replace(got[seq], **changes)
    check = compare(PX4_SENT, got, "px4")
    assert not check.equal
    assert check.mismatches[0].startswith(f"seq {seq} ")


def test_px4_drops_and_wraps_are_equal_and_nothing_else() -> None:
    """Seen on PX4 SITL: NAV_WAYPOINT's param3 as 0, a yaw of -90 as 270, 400 as 39.99999."""
    sent = [replace(PX4_SENT[2], seq=0, param3=2.0, param4=-90.0, frame=0, z=480.8)]
    got = [replace(sent[0], param3=0.0, param4=270.0, frame=mavlink.MAV_FRAME_GLOBAL_INT)]
    assert compare(sent, got, "px4").equal
    wrapped = [replace(sent[0], param4=400.0)], [replace(got[0], param4=39.9999885559082)]
    assert compare(*wrapped, "px4").equal
    assert not compare(sent, [replace(got[0], param4=271.0)], "px4").equal
    assert not compare(sent, [replace(got[0], param2=1.0)], "px4").equal


@settings(max_examples=200, deadline=None)
@given(
    xy=coordinates,
    z=st.floats(-500.0, 8000.0),
    hold=st.floats(0.0, 3600.0),
    yaw=st.one_of(st.just(math.nan), st.floats(-720.0, 720.0)),
    frame=st.sampled_from([RELATIVE, RELATIVE_INT, 0, 5]),
    nudge=st.sampled_from(["x", "y", "z", "hold", None]),
)
def test_simulated_px4_storage_passes_and_any_nudge_fails(
    xy: tuple[int, int], z: float, hold: float, yaw: float, frame: int, nudge: str | None
) -> None:
    """The simulator's model of PX4's storage and the comparison agree."""
    sent = _item(seq=0, x=xy[0], y=xy[1], z=z, param1=hold, param4=yaw, frame=frame)
    stored = px4_stored(Item(WAYPOINT, frame, hold, 0.0, 0.0, yaw, xy[0], xy[1], z))
    got = WireItem(0, stored.frame, WAYPOINT, 0, 1, *stored.params, stored.x, stored.y, stored.z)
    if nudge == "x":
        got = replace(got, x=got.x + 1)
    elif nudge == "y":
        got = replace(got, y=got.y - 1)
    elif nudge == "z":
        got = replace(got, z=got.z + 0.05)
    elif nudge == "hold":
        got = replace(got, param1=got.param1 + 0.5)
    assert compare([sent], [got], "px4").equal == (nudge is None)
