"""Flights on ArduPilot's own ArduCopter SITL (``../shared/ardupilot/arducopter``).

One SITL serves most tests in turn (launched once for the module); the demo replay goes
through ``urpt-gcs sitl replay --ardupilot``, which starts and stops its own. Each test that
flies prints what it measured. The launcher's failures are tested with stand-in binaries and
need no SITL.
"""

from __future__ import annotations

import json
import math
import os
import random
import socket
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO, DEMO_OUT, SHARED
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.mavlink_peer import split_frames

from urpt_gcs.cli import main
from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.files.formats import read_plan
from urpt_gcs.flight.geofence import read_plan_geofence
from urpt_gcs.flight.mission import Mission, photo_headings
from urpt_gcs.replay.ardupilot import launch, resolve_binary
from urpt_gcs.replay.fly import ReplaySettings, replay
from urpt_gcs.replay.launcher import RunningSitl
from urpt_gcs.replay.record import Flight
from urpt_gcs.site.targets import read_targets
from urpt_gcs.vehicle.link import upload

ARDUPILOT = SHARED / "ardupilot"
BINARY = ARDUPILOT / "arducopter"
DEMO_PLAN = DEMO_OUT / "mission.plan"
SITE, TARGETS = DEMO / "site.tif", DEMO / "targets.kml"
# The README saw 10x; 20x keeps the file within its budget and flies as well.
SPEEDUP = 20.0
# How close the plan's flight-time estimate must come to a flight on the real firmware.
ESTIMATE_TOLERANCE = 0.10
needs_sitl = pytest.mark.skipif(
    not os.access(BINARY, os.X_OK), reason=f"no ArduCopter SITL at {BINARY}"
)
pytestmark = pytest.mark.sitl_real


def _mission(path: Path) -> Mission:
    return read_plan(path.read_text(), str(path))


@pytest.fixture(scope="module")
def sitl() -> Iterator[RunningSitl]:
    with launch(BINARY, _mission(DEMO_PLAN).home, SPEEDUP) as running:
        yield running


@pytest.fixture(scope="module")
def plans(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The demo planned at --fov 40 and with a short --endurance (three sorties)."""
    out = tmp_path_factory.mktemp("plans")
    runs = {"fov40": ["--fov", "40"], "sorties": ["--endurance", "4"]}
    for name, flags in runs.items():
        args = ["plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(out / name)]
        result = CliRunner().invoke(main, [*args, *flags, "--no-map", "--quiet"])
        assert result.exit_code == 0, result.output
    return {
        "fov40": out / "fov40" / "mission.plan",
        "sortie1": out / "sorties" / "mission_1.plan",
        "sortie3": out / "sorties" / "mission_3.plan",
        "summary": out / "sorties" / "summary.json",
    }


def _sortie_targets(summary: Path, sortie: int, folder: Path) -> Path:
    """A CSV of the targets the stops of one sortie see (the judge checks the whole file)."""
    data = json.loads(summary.read_text())
    names = {n for stop in data["stops"] if stop["sortie"] == sortie for n in stop["sees"]}
    rows = [
        f"{t.name},{t.lat_deg!r},{t.lon_deg!r}"
        for t in read_targets(TARGETS).targets
        if t.name in names
    ]
    assert len(rows) == len(names)
    path = folder / f"sortie_{sortie}.csv"
    path.write_text("name,lat,lon\n" + "\n".join(rows) + "\n")
    return path


def _photo_offsets(flight: Flight, mission: Mission) -> tuple[list[float], list[float]]:
    """Horizontal and vertical distance of each photo from its planned waypoint."""
    stops = [
        item
        for item, after in zip(mission.items, mission.items[1:], strict=False)
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT
        and after.command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL
    ]
    assert len(flight.photos) == len(stops)
    horizontal, vertical = [], []
    for photo, stop in zip(flight.photos, stops, strict=True):
        north = math.radians(photo.lat_deg - stop.params[4]) * 6_378_137.0
        east = (
            math.radians(photo.lon_deg - stop.params[5])
            * 6_378_137.0
            * math.cos(math.radians(stop.params[4]))
        )
        horizontal.append(math.hypot(east, north))
        vertical.append(abs(photo.alt_rel_m - stop.params[6]))
    return horizontal, vertical


def _fly_and_judge(
    plan: Path, sitl: RunningSitl, targets: Path = TARGETS, **settings: float
) -> Flight:
    started = time.monotonic()
    report = replay(
        SITE, targets, plan, ReplaySettings(speedup=SPEEDUP, connect=sitl.url, **settings)
    )
    assert report.ok, report.problems
    flight = report.flight
    horizontal, vertical = _photo_offsets(flight, _mission(plan))
    print(
        f"\n{plan.name}: {flight.sim_time_s:.1f} s flown (arming to landing) in "
        f"{flight.wall_time_s:.1f} s wall, {time.monotonic() - started:.1f} s with upload; "
        f"{len(flight.photos)} photos {min(horizontal):.2f}-{max(horizontal):.2f} m from "
        f"plan horizontally, at most {max(vertical):.2f} m vertically"
    )
    assert max(horizontal) < 1.0 and max(vertical) < 0.5
    return flight


def _estimate_s(summary: Path, sortie: int) -> float:
    """The plan's estimate of one sortie's flight time, arming to the disarm after landing."""
    return float(json.loads(summary.read_text())["sorties"][sortie - 1]["flight_time_s"])


def _check_estimate(name: str, flight: Flight, estimate_s: float) -> None:
    off = flight.sim_time_s / estimate_s - 1.0
    print(f"{name}: estimate {estimate_s:.1f} s, flown {flight.sim_time_s:.1f} s ({off:+.1%})")
    assert abs(off) <= ESTIMATE_TOLERANCE


# --- flights ---------------------------------------------------------------------------------


@needs_sitl
def test_demo_replayed_on_arducopter_via_the_cli() -> None:
    """``--ardupilot`` alone takes the SITL from $URPT_ARDUPILOT, starts, flies and stops it."""
    started = time.monotonic()
    result = CliRunner(env={"URPT_ARDUPILOT": str(ARDUPILOT)}).invoke(
        main,
        [
            *("sitl", "replay", "--dem", str(SITE), "--targets", str(TARGETS)),
            *("--plan", str(DEMO_PLAN), "--speedup", f"{SPEEDUP:g}", "--ardupilot"),
        ],
    )
    wall = time.monotonic() - started
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f"replay of {DEMO_PLAN} on ArduPilot 4.7.0-dev (ArduCopter SITL")
    assert "  targets   16 of 16 seen" in lines
    assert "  photos    12" in lines
    assert "  result    PASS" in lines
    print(f"\ndemo via --ardupilot in {wall:.1f} s wall:\n{result.stdout}")


@needs_sitl
def test_a_sortie_split_and_two_replays_in_a_row(
    sitl: RunningSitl, plans: dict[str, Path], tmp_path: Path
) -> None:
    """Two sorties of a split plan, one after the other on one SITL, each judged on the
    targets its stops see. The second arms although the first left the copter in AUTO."""
    for sortie, plan in ((3, plans["sortie3"]), (1, plans["sortie1"])):
        targets = _sortie_targets(plans["summary"], sortie, tmp_path)
        flight = _fly_and_judge(plan, sitl, targets)
        assert flight.vehicle.describe() == f"ArduPilot 4.7.0-dev ({sitl.url})"
        _check_estimate(f"sortie {sortie}", flight, _estimate_s(plans["summary"], sortie))


@needs_sitl
def test_the_demo_flies_the_estimated_flight_time(sitl: RunningSitl) -> None:
    """ArduCopter's own take-off, S-curve legs, RTL at WPNAV_SPEED, loiter and landing take
    what the plan's flight model says (summary.json), within 10 %."""
    flight = _fly_and_judge(DEMO_PLAN, sitl)
    _check_estimate("demo", flight, _estimate_s(DEMO_OUT / "summary.json", 1))


@needs_sitl
def test_a_plan_at_fov_40(sitl: RunningSitl, plans: dict[str, Path]) -> None:
    _fly_and_judge(plans["fov40"], sitl, fov_deg=40.0)


@needs_sitl
def test_a_frame_camera_plan_turns_to_each_photos_heading(
    sitl: RunningSitl, tmp_path: Path
) -> None:
    """A Phantom 4 RTK plan at 3 cm/px: ArduCopter turns at each CONDITION_YAW, the heading
    in each CAMERA_FEEDBACK is the plan's within 5 degrees (the judge checks it), and every
    target lies inside the turned frame of a photo."""
    args = ["plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(tmp_path)]
    args += ["--camera", "phantom4rtk", "--gsd", "3", "--no-map", "--quiet"]
    made = CliRunner().invoke(main, args)
    assert made.exit_code == 0, made.output
    plan = tmp_path / "mission.plan"
    flight = _fly_and_judge(plan, sitl)
    planned = photo_headings(_mission(plan))
    assert planned is not None and len(planned) == len(flight.photos)
    off = [
        abs((p.heading_deg - want + 180.0) % 360.0 - 180.0)
        for p, want in zip(flight.photos, planned, strict=True)
    ]
    print(f"headings at CAMERA_FEEDBACK: at most {max(off):.2f} deg off the plan's")
    assert max(off) <= 5.0


@needs_sitl
def test_a_sabotaged_plan_fails_the_judge(
    sitl: RunningSitl, plans: dict[str, Path], tmp_path: Path
) -> None:
    plan = json.loads(plans["sortie3"].read_text())
    stops = [i for i in plan["mission"]["items"] if i["command"] == mavlink.MAV_CMD_NAV_WAYPOINT]
    stops[-1]["params"][4] += 200.0 / 111_320.0  # the last stop, 200 m north
    moved = tmp_path / "moved.plan"
    moved.write_text(json.dumps(plan))
    targets = _sortie_targets(plans["summary"], 3, tmp_path)
    report = replay(SITE, targets, moved, ReplaySettings(speedup=SPEEDUP, connect=sitl.url))
    assert not report.ok
    assert any("was photographed from no position that sees it" in p for p in report.problems)
    print(f"\nsabotaged plan: {report.problems}")


# --- upload, geofence, a lossy link ------------------------------------------------------------


@needs_sitl
def test_upload_sends_the_geofence_and_it_reads_back(sitl: RunningSitl) -> None:
    result = CliRunner().invoke(main, ["upload", str(DEMO_PLAN), "--connect", sitl.url])
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    mission_line, fence_line = result.stdout.splitlines()
    assert mission_line.startswith(f"uploaded 29 items to {sitl.url} (ardupilot)")
    assert fence_line.startswith(
        "uploaded the geofence, inclusion polygon (23 vertices): 23 fence items read back identical"
    )
    print(f"\n{result.stdout}")
    # A second ground station (pymavlink on SERIAL1) reads the same fence off the vehicle.
    fence = read_plan_geofence(DEMO_PLAN.read_text(), str(DEMO_PLAN))
    expected = [(round(a * 1e7), round(b * 1e7)) for a, b in fence.polygons[0].vertices]
    assert _pymavlink_fence(sitl.second_url) == expected


def _pymavlink_fence(url: str) -> list[tuple[int, int]]:
    link = mavutil.mavlink_connection(url, source_system=254, source_component=190)
    try:
        link.wait_heartbeat(timeout=10)
        fence = mavlink.MAV_MISSION_TYPE_FENCE
        link.mav.mission_request_list_send(link.target_system, link.target_component, fence)
        count = link.recv_match(type="MISSION_COUNT", blocking=True, timeout=5)
        assert count is not None and count.mission_type == fence
        vertices = []
        for seq in range(count.count):
            link.mav.mission_request_int_send(link.target_system, link.target_component, seq, fence)
            item = link.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=5)
            assert item is not None and item.seq == seq
            assert item.command == mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
            vertices.append((item.x, item.y))
        link.mav.mission_ack_send(
            link.target_system, link.target_component, mavlink.MAV_MISSION_ACCEPTED, fence
        )
        return vertices
    finally:
        link.close()


class LossyRelay:
    """A loopback TCP relay that drops a fraction of whole MAVLink frames each way (seeded)."""

    def __init__(self, target_port: int, loss: float, seed: int) -> None:
        self.target_port = target_port
        self.loss = loss
        self.rngs = (random.Random(seed), random.Random(seed + 1))
        self.dropped = [0, 0]
        self.passed = [0, 0]
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.server.getsockname()[1]
        self.stopping = threading.Event()
        self.threads: list[threading.Thread] = []
        self.threads.append(threading.Thread(target=self._accept, daemon=True))
        self.threads[0].start()

    def _accept(self) -> None:
        client, _ = self.server.accept()
        vehicle = socket.create_connection(("127.0.0.1", self.target_port))
        for direction, (src, dst) in enumerate(((client, vehicle), (vehicle, client))):
            thread = threading.Thread(target=self._pump, args=(src, dst, direction), daemon=True)
            self.threads.append(thread)
            thread.start()
        self.sockets = (client, vehicle)

    def _pump(self, src: socket.socket, dst: socket.socket, direction: int) -> None:
        buffer = b""
        while not self.stopping.is_set():
            try:
                chunk = src.recv(65536)
            except OSError:
                return
            if not chunk:
                return
            buffer += chunk
            frames, buffer = split_frames(buffer)
            for frame in frames:
                if self.rngs[direction].random() < self.loss:
                    self.dropped[direction] += 1
                    continue
                self.passed[direction] += 1
                try:
                    dst.sendall(frame)
                except OSError:
                    return

    def close(self) -> None:
        self.stopping.set()
        for sock in (self.server, *getattr(self, "sockets", ())):
            sock.close()


@needs_sitl
def test_upload_through_a_relay_dropping_20_percent_each_way(sitl: RunningSitl) -> None:
    mission = _mission(DEMO_PLAN)
    port = int(sitl.url.rsplit(":", 1)[1])
    relay = LossyRelay(port, 0.2, seed=9)
    try:
        report = upload(mission, f"tcpout://127.0.0.1:{relay.port}", timeout_s=20.0)
    finally:
        relay.close()
    assert report.items == 29
    dropped = sum(relay.dropped) / max(sum(relay.dropped) + sum(relay.passed), 1)
    print(
        f"\nupload at 20 % loss each way: verified in {report.elapsed_s:.1f} s, "
        f"{report.attempts} attempt(s); {dropped:.0%} of {sum(relay.passed) + sum(relay.dropped)} "
        "frames dropped"
    )
    assert 0.15 < dropped < 0.25


# --- the launcher's failures (stand-in binaries, no SITL needed) ------------------------------


def _stand_in(folder: Path, body: str, executable: bool = True) -> Path:
    binary = folder / "arducopter"
    binary.write_text(f"#!{sys.executable}\n{body}\n")
    binary.chmod(0o755 if executable else 0o644)
    (folder / "copter.parm").write_text("FRAME_CLASS 1\n")
    return binary


def test_a_missing_binary_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(SettingsError) as raised:
        resolve_binary(tmp_path)
    assert str(raised.value).startswith(f"--ardupilot '{tmp_path}': no arducopter there")
    with pytest.raises(SettingsError, match="pass --ardupilot PATH"):
        resolve_binary(None)


def test_a_binary_that_is_not_executable_is_one_line(tmp_path: Path) -> None:
    binary = _stand_in(tmp_path, "", executable=False)
    with pytest.raises(SettingsError, match="is not an executable file"):
        resolve_binary(binary)


def test_a_sitl_that_dies_at_start_shows_its_last_words(tmp_path: Path) -> None:
    binary = _stand_in(tmp_path, "print('bad option --frobnicate'); raise SystemExit(3)")
    with pytest.raises(LinkError) as raised, launch(binary, _mission(DEMO_PLAN).home, 10.0):
        pass
    assert str(raised.value) == (
        "ArduCopter SITL exited with status 3 at start: bad option --frobnicate"
    )


def test_a_sitl_that_never_comes_up_is_stopped(tmp_path: Path) -> None:
    binary = _stand_in(
        tmp_path, "import time; print('Waiting forever', flush=True); time.sleep(60)"
    )
    started = time.monotonic()
    with (
        pytest.raises(LinkError, match=r"did not open TCP port \d+ within 1 s: Waiting forever"),
        launch(binary, _mission(DEMO_PLAN).home, 10.0, start_timeout_s=1.0),
    ):
        pass
    assert time.monotonic() - started < 10.0


LISTENER = """
import socket, sys, time
instance = int(sys.argv[sys.argv.index("-I") + 1])
server = socket.create_server(("127.0.0.1", 5760 + 10 * instance))
print("listening", flush=True)
time.sleep(60)
"""


def test_ctrl_c_stops_the_sitl_and_removes_its_folder(tmp_path: Path) -> None:
    binary = _stand_in(tmp_path, LISTENER)
    seen: list[RunningSitl] = []
    with (
        pytest.raises(KeyboardInterrupt),
        launch(binary, _mission(DEMO_PLAN).home, 10.0) as running,
    ):
        seen.append(running)
        assert (running.folder / f"instance-{running.instance}" / "urpt-gcs.parm").read_text() == (
            "CAM1_TYPE 1\nSERVO9_FUNCTION 10\n"
        )
        raise KeyboardInterrupt
    (running,) = seen
    with pytest.raises(ProcessLookupError):
        os.kill(running.pid, 0)
    assert not running.folder.exists()
