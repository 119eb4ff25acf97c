"""A fleet on the link: upload --fleet and sitl replay --fleet.

Fleet folders are built by tests/support/fleet_helpers.py from single-vehicle plans of the demo.
What the vehicles hold is read back by pymavlink (or from the simulated copter's store) and
compared with the .waypoints parsed by pymavlink's mavwp; the closest approach is recomputed
from the raw tracks with a flat-earth distance of its own.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import DEMO_OUT, SHARED
from pymavlink import mavutil, mavwp
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from scipy.ndimage import minimum_filter1d
from support.fleet_helpers import HOME_EAST, SITE, TARGETS, Vehicle, build_fleet, plan_fleet_of_two

from urpt_gcs.cli import main
from urpt_gcs.files.fleet_folder import read_fleet
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.replay.fleet import FleetReport, replay_fleet
from urpt_gcs.replay.fly import ReplaySettings, free_udp_port
from urpt_gcs.replay.record import Flight
from urpt_gcs.sim import SitlServer, VehicleSettings
from urpt_gcs.site.targets import read_targets
from urpt_gcs.vehicle.fleet_upload import upload_fleet
from urpt_gcs.vehicle.link import UploadSettings

BINARY = SHARED / "ardupilot" / "arducopter"
FIRST = ("T01", "T02", "T03", "T04", "T05", "T06", "T07", "T08")
SECOND = ("T09", "T10", "T11", "T12", "T13", "T14", "T15", "T16")
T12 = (47.688994373, 9.420960468)  # west field
T14 = (47.689698197, 9.425297066)  # east plateau


@pytest.fixture(scope="module")
def fleet3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three vehicles, layers 10 m apart."""
    return build_fleet(
        tmp_path_factory.mktemp("fleet3"),
        [
            Vehicle(("T01", "T02", "T03", "T04", "T05"), 481.0),
            Vehicle(("T06", "T07", "T08", "T09", "T10"), 491.0, HOME_EAST),
            Vehicle(("T11", "T12", "T13", "T14", "T15", "T16"), 501.0),
        ],
    )


@pytest.fixture(scope="module")
def fleet2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two vehicles, 20 m apart at home, layers 10 m apart."""
    out = tmp_path_factory.mktemp("fleet2")
    return build_fleet(out, [Vehicle(FIRST, 481.0), Vehicle(SECOND, 491.0, HOME_EAST)])


@pytest.fixture(scope="module")
def crossing(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two vehicles in one layer, each flying to the other's home and back."""
    out = tmp_path_factory.mktemp("crossing")
    return build_fleet(
        out, [Vehicle(("T14",), 481.0, T12), Vehicle(("T12",), 481.0, T14)], mode="time"
    )


@contextmanager
def copters(fleet: Path, **faults: dict[str, Any]) -> Iterator[list[tuple[SitlServer, str]]]:
    """One simulated copter per vehicle at its home; ``faults`` by vehicle ("v2": {...})."""
    with ExitStack() as stack:
        running = []
        for vehicle in read_fleet(fleet).vehicles:
            home = read_mission(vehicle.missions[0]).home
            port = free_udp_port()
            settings = VehicleSettings(home=home, **faults.get(f"v{vehicle.number}", {}))
            server = stack.enter_context(SitlServer(settings, f"udpout://127.0.0.1:{port}"))
            running.append((server, f"udpin://127.0.0.1:{port}"))
        yield running


def _wait(conn: Any, kind: str, timeout_s: float = 5.0) -> Any:
    msg = conn.recv_match(type=kind, blocking=True, timeout=timeout_s)
    assert msg is not None, f"no {kind} within {timeout_s} s"
    return msg


def pymavlink_download(url: str) -> list[Any]:
    """The vehicle's mission as MISSION_ITEM_INT messages, read by pymavlink alone."""
    conn = mavutil.mavlink_connection(url.replace("://", ":"), source_system=254)
    conn.mav = mavlink.MAVLink(conn, srcSystem=254, srcComponent=190)
    conn.WIRE_PROTOCOL_VERSION = "2.0"
    try:
        _wait(conn, "HEARTBEAT")
        conn.mav.mission_request_list_send(1, 1, 0)
        count = _wait(conn, "MISSION_COUNT").count
        items = []
        for seq in range(count):
            conn.mav.mission_request_int_send(1, 1, seq, 0)
            items.append(_wait(conn, "MISSION_ITEM_INT"))
            assert items[-1].seq == seq
        conn.mav.mission_ack_send(1, 1, mavlink.MAV_MISSION_ACCEPTED, 0)
        return items
    finally:
        conn.close()


def mavwp_items(path: Path) -> list[Any]:
    loader = mavwp.MAVWPLoader(target_system=1, target_component=1)
    loader.load(str(path))
    return [loader.wp(i) for i in range(loader.count())]


def assert_holds(got: list[tuple[int, int, int, float]], waypoints: Path) -> None:
    """(command, x, y, z) per item equal to the .waypoints as mavwp reads it; home's
    altitude (seq 0) is the vehicle's own."""
    want = mavwp_items(waypoints)
    assert len(got) == len(want), f"{waypoints}: {len(got)} items held, {len(want)} planned"
    for seq, (held, planned) in enumerate(zip(got, want, strict=True)):
        command, x, y, z = held
        assert command == planned.command, seq
        if planned.frame in (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            assert abs(x - round(planned.x * 1e7)) <= 1, seq
            assert abs(y - round(planned.y * 1e7)) <= 1, seq
            assert seq == 0 or abs(z - planned.z) <= 0.01, seq


def _upload(fleet: Path, *args: str) -> Any:
    return CliRunner().invoke(main, ["upload", "--fleet", str(fleet), *args])


# --- upload --fleet ---------------------------------------------------------------------------


def test_fleet_upload_puts_each_mission_on_its_vehicle(fleet3: Path) -> None:
    with copters(fleet3) as running:
        result = _upload(fleet3, *(a for _s, url in running for a in ("--connect", url)))
        assert result.exit_code == 0, result.output
        for number, (_server, url) in enumerate(running, start=1):
            got = [(m.command, m.x, m.y, m.z) for m in pymavlink_download(url)]
            assert_holds(got, fleet3 / f"vehicle_{number}" / "mission.waypoints")
    lines = result.stdout.splitlines()
    assert [line.split(" on ")[0] for line in lines[:3]] == ["vehicle 1", "vehicle 2", "vehicle 3"]
    for number, line in enumerate(lines[:3], start=1):
        count = len(mavwp_items(fleet3 / f"vehicle_{number}" / "mission.waypoints"))
        assert f"{count} items sent, read back identical" in line
    assert lines[3] == "fleet: 3 of 3 vehicles hold their mission, verified"


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("--connect", "udpin://127.0.0.1:1", "--connect", "udpin://127.0.0.1:2"),
         "3 vehicles in"),
        (("--connect", "udpin://127.0.0.1:1", "--sysid", "1,2"), "2 system ids in --sysid"),
        (("--connect", "udpin://127.0.0.1:1", "--sysid", "1,x,3"), "--sysid '1,x,3'"),
        (("--connect", "a", "--connect", "b", "--sysid", "1,2,3"), "give one --connect with"),
    ],
)  # fmt: skip
def test_fleet_upload_refuses_connections_that_do_not_match(
    fleet3: Path, args: tuple[str, ...], words: str
) -> None:
    result = _upload(fleet3, *args)
    assert result.exit_code == 1
    assert result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and words in result.stderr, result.stderr


def test_a_fleet_folder_without_a_fleet_is_one_line(tmp_path: Path) -> None:
    result = _upload(DEMO_OUT, "--connect", "udpin://127.0.0.1:1")
    assert result.exit_code == 1
    assert "single-vehicle plan" in result.stderr and len(result.stderr.splitlines()) == 1
    result = _upload(tmp_path, "--connect", "udpin://127.0.0.1:1")
    assert result.exit_code == 1 and "holds no summary.json" in result.stderr


def test_a_link_drop_on_one_vehicle_is_retried_while_the_others_verify(fleet3: Path) -> None:
    fleet = read_fleet(fleet3)
    with copters(fleet3, v2={"drop_after": 5, "drop_s": 3.0}) as running:
        report = upload_fleet(
            fleet, [url for _s, url in running], settings=UploadSettings(timeout_s=10.0)
        )
        stores = [server.vehicle.store.items() for server, _url in running]
    assert report.ok
    first, second, third = (v.report for v in report.vehicles)
    assert first is not None and second is not None and third is not None
    print(f"vehicle 2: {second.attempts} attempts, {second.elapsed_s:.1f} s")
    assert (first.attempts, third.attempts) == (1, 1)
    # The silence was lived through: in a second attempt, or waited out within the first.
    assert second.attempts >= 2 or second.elapsed_s >= 3.0
    for number, items in enumerate(stores, start=1):
        got = [(i.command, i.x, i.y, i.z) for i in items]
        assert_holds(got, fleet3 / f"vehicle_{number}" / "mission.waypoints")


def test_a_vehicle_that_refuses_fails_alone(fleet3: Path) -> None:
    """Vehicle 2 holds 5 items: it is reported not verified, with the fix; the others hold
    their whole missions and the exit status is 1."""
    with copters(fleet3, v2={"capacity": 5}) as running:
        result = _upload(fleet3, *(a for _s, url in running for a in ("--connect", url)))
        stores = [server.vehicle.store.items() for server, _url in running]
    assert result.exit_code == 1
    lines = result.stdout.splitlines()
    assert "items sent, read back identical" in lines[0]
    assert "NOT VERIFIED" in lines[1] and "holds at most 5 items" in lines[1]
    assert "urpt-gcs upload" in lines[1]  # the fix: upload it again alone
    assert "items sent, read back identical" in lines[2]
    assert lines[3] == "fleet: 2 of 3 vehicles hold their mission, verified"
    assert result.stderr.strip().splitlines()[-1].startswith("urpt-gcs: error: vehicle 2 ")
    for number in (1, 3):
        got = [(i.command, i.x, i.y, i.z) for i in stores[number - 1]]
        assert_holds(got, fleet3 / f"vehicle_{number}" / "mission.waypoints")
    assert len(stores[1]) <= 1  # nothing but home: a refusal stores no item


def test_several_system_ids_on_one_link(fleet2: Path) -> None:
    port = free_udp_port()
    fleet = read_fleet(fleet2)
    with ExitStack() as stack:
        servers = []
        for vehicle, sysid in zip(fleet.vehicles, (7, 3), strict=True):
            home = read_mission(vehicle.missions[0]).home
            settings = VehicleSettings(home=home, system_id=sysid)
            servers.append(stack.enter_context(SitlServer(settings, f"udpout://127.0.0.1:{port}")))
        result = _upload(fleet2, "--connect", f"udpin://127.0.0.1:{port}", "--sysid", "7,3")
        stores = [server.vehicle.store.items() for server in servers]
    assert result.exit_code == 0, result.output
    assert "(system 7)" in result.stdout.splitlines()[0]
    for number, items in enumerate(stores, start=1):
        got = [(i.command, i.x, i.y, i.z) for i in items]
        assert_holds(got, fleet2 / f"vehicle_{number}" / "mission.waypoints")


# --- sitl replay --fleet ----------------------------------------------------------------------


def independent_closest(
    flights: list[Flight], homes_amsl: list[float], speedup: float, one_pad: bool = False
) -> float:
    """Closest 3-D approach at equal times, by a computation of its own: each position at
    the time it arrived less its delivery delay, the delay read off the earliest arrival,
    against the vehicle's own clock at its nominal speed-up, among the positions of the
    two seconds around it (a busy ground station takes positions in bursts, and a busy
    simulator falls behind its speed-up now and then); on a local flat earth, the other
    track interpolated at each sample time; with ``one_pad`` (the fleet shares one home)
    two vehicles are compared only while both fly, since they use its pad in turn."""
    lat0 = flights[0].track[0].lat_deg
    metres_lat = 111_132.954 - 559.822 * math.cos(2 * math.radians(lat0))
    metres_lon = 111_412.84 * math.cos(math.radians(lat0))
    tracks = []
    for flight, ground in zip(flights, homes_amsl, strict=True):
        wall = np.array([p.wall_s for p in flight.track])
        own = np.array([p.time_s for p in flight.track])
        late = wall - own / speedup
        half = max(1, round(len(wall) / (wall[-1] - wall[0])))  # samples in a second
        t = own / speedup + minimum_filter1d(late, 2 * half + 1, mode="nearest")
        xyz = np.array(
            [
                (p.lon_deg * metres_lon, p.lat_deg * metres_lat, ground + p.alt_rel_m)
                for p in flight.track
            ]
        )
        rel = np.array([p.alt_rel_m for p in flight.track])
        tracks.append((t, xyz, rel))
    best = math.inf
    for i in range(len(tracks)):
        for j in range(len(tracks)):
            if i == j:
                continue
            (ta, pa, ra), (tb, pb, rb) = tracks[i], tracks[j]
            inside = (ta >= tb[0]) & (ta <= tb[-1])
            other = np.column_stack([np.interp(ta[inside], tb, pb[:, k]) for k in range(3)])
            up_a, up_b = ra[inside] > 1.0, np.interp(ta[inside], tb, rb) > 1.0
            flying = (up_a & up_b) if one_pad else (up_a | up_b)
            gaps = np.linalg.norm(pa[inside] - other, axis=1)[flying]
            if gaps.size:
                best = min(best, float(gaps.min()))
    return best


def _check_targets_independently(report: FleetReport) -> None:
    """Every target, each from the photo the judge names, also for tests/support/independent.py."""
    from support.independent import load_raster, sees

    raster = load_raster(SITE)
    targets = {t.name: t for t in read_targets(TARGETS).targets}
    by_plan = {r.plan: r for r in report.together.reports}
    assert {row.name for row in report.together.targets} == set(targets)
    for row in report.together.targets:
        assert row.photo is not None and row.plan is not None, row.name
        flight_report = by_plan[row.plan]
        photo = {p.index: p for p in flight_report.flight.photos}[row.photo]
        eye = (photo.lat_deg, photo.lon_deg, flight_report.home_amsl_m + photo.alt_rel_m)
        target = targets[row.name]
        ok, why = sees(raster, (target.lat_deg, target.lon_deg), eye, 30.0)
        assert ok, f"{row.name}: {why}"


def test_a_fleet_replays_on_simulated_copters(fleet2: Path) -> None:
    report = replay_fleet(SITE, TARGETS, read_fleet(fleet2), ReplaySettings(speedup=50.0))
    assert report.ok, (report.problems, report.together.problems)
    _check_targets_independently(report)
    flights = [r.flight for r in report.together.reports]
    homes = [r.home_amsl_m for r in report.together.reports]
    assert report.approach is not None
    assert report.approach.distance_m >= 8.0
    assert report.approach.distance_m == pytest.approx(
        independent_closest(flights, homes, 50.0), abs=1.0
    )
    assert max(report.takeoff_wall_s) < 0.1  # they took off together
    for r in report.together.reports:
        assert r.min_clearance_m is not None and r.min_clearance_m >= 10.0


def test_crossing_tracks_in_one_layer_fail_the_separation(crossing: Path) -> None:
    targets = crossing / "targets.csv"
    report = replay_fleet(SITE, targets, read_fleet(crossing), ReplaySettings(speedup=50.0))
    assert report.together.ok  # each flight and the targets are fine ...
    assert not report.ok  # ... but the vehicles met
    assert report.approach is not None and report.approach.distance_m < 10.0
    flights = [r.flight for r in report.together.reports]
    homes = [r.home_amsl_m for r in report.together.reports]
    assert report.approach.distance_m == pytest.approx(
        independent_closest(flights, homes, 50.0), abs=1.0
    )
    assert any("came within" in p and "required 10 m" in p for p in report.problems)


def test_the_replay_command_fails_on_crossing_tracks(crossing: Path) -> None:
    targets = crossing / "targets.csv"
    args = ["sitl", "replay", "--dem", str(SITE), "--targets", str(targets), "--fleet"]
    result = CliRunner().invoke(main, [*args, str(crossing), "--speedup", "100"])
    assert result.exit_code == 1
    assert "closest" in result.stdout and "result    FAIL" in result.stdout
    assert result.stderr.startswith("urpt-gcs: error: fleet replay failed: vehicles 1 and 2")


@pytest.fixture(scope="module")
def planned2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return plan_fleet_of_two(tmp_path_factory.mktemp("planned2") / "out")


def _replay_planned(fleet: Path, settings: ReplaySettings, within_m: float = 1.5) -> list[Flight]:
    report = replay_fleet(SITE, TARGETS, read_fleet(fleet), settings)
    from urpt_gcs.replay.fleet import fleet_report_text

    print(fleet_report_text(report).split("\n\nfleet: ")[-1])
    assert report.ok, (report.problems, report.together.problems)
    _check_targets_independently(report)
    flights = [r.flight for r in report.together.reports]
    homes = [r.home_amsl_m for r in report.together.reports]
    assert report.approach is not None and report.approach.distance_m >= 8.0
    closest_m = independent_closest(flights, homes, settings.speedup, one_pad=True)
    assert report.approach.distance_m == pytest.approx(closest_m, abs=within_m)
    delays = [v.start_delay_s for v in read_fleet(fleet).vehicles]
    assert max(delays) > 0.0  # one home: the plan staggers the take-offs, the replay keeps them
    return flights


def test_the_planners_fleet_replays_on_simulated_copters(planned2: Path) -> None:
    _replay_planned(planned2, ReplaySettings(speedup=50.0))


def _takeoff_wall_s(flight: Flight) -> float:
    return next(p.wall_s for p in flight.track if p.alt_rel_m > 1.0)


def test_a_vehicle_slow_to_arm_keeps_the_planned_stagger(planned2: Path) -> None:
    """The vehicle planned to go first refuses to arm for about 2 s of wall time (100 s of
    flight at 50x, far more than the stagger): the one planned after it still takes off
    after it, by the planned delay, rather than into the gap the plan left."""
    import asyncio

    from urpt_gcs.replay.fleet import _fly_all

    fleet = read_fleet(planned2)
    missions = [read_mission(v.missions[0]) for v in fleet.vehicles]
    delays = [v.start_delay_s for v in fleet.vehicles]
    first, later = int(np.argmin(delays)), int(np.argmax(delays))
    assert delays[later] - delays[first] >= 10.0
    speed = {"speedup": 50.0}
    faults = {f"v{k + 1}": dict(speed) for k in range(len(missions))}
    faults[f"v{first + 1}"]["arm_refusals"] = 20  # asked again every 0.1 s
    with copters(planned2, **faults) as running:
        places = [(url, "simulated") for _server, url in running]
        settings = ReplaySettings(speedup=50.0)
        flights = asyncio.run(_fly_all(places, missions, settings, 120.0, print, delays))
    gap_s = (_takeoff_wall_s(flights[later]) - _takeoff_wall_s(flights[first])) * 50.0
    assert gap_s == pytest.approx(delays[later] - delays[first], abs=5.0)


@pytest.mark.sitl_real
@pytest.mark.skipif(not os.access(BINARY, os.X_OK), reason=f"no ArduCopter SITL at {BINARY}")
def test_the_planners_fleet_replays_on_arducopter_sitl(planned2: Path) -> None:
    """``plan --vehicles 2`` flown on two ArduCopter SITL instances; prints what it measured."""
    # Two clock models of a simulator that stalls now and then: at 20x a twentieth of a wall
    # second is a second of flight, metres apart in a climb (they came within 2.1 m with
    # both cores loaded besides).
    settings = ReplaySettings(speedup=20.0, ardupilot=BINARY)
    flights = _replay_planned(planned2, settings, within_m=2.5)
    assert all("ArduCopter SITL" in f.vehicle.where for f in flights)
    assert len({f.vehicle.where for f in flights}) == 2
    for flight in flights:  # every SITL we started has stopped
        pid = int(flight.vehicle.where.split("pid ")[1].split(",")[0])
        assert not Path(f"/proc/{pid}").exists() or _zombie(pid)


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except OSError:
        return True


def test_fleet_replay_refusals_are_one_line(fleet2: Path, tmp_path: Path) -> None:
    base = ["sitl", "replay", "--dem", str(SITE), "--targets", str(TARGETS)]
    cases = {
        "give --plan or --fleet, not both": ["--fleet", str(fleet2), "--plan", str(fleet2)],
        "not --connect or --px4": ["--fleet", str(fleet2), "--connect", "udpin://127.0.0.1:1"],
        "no mission given": [],
    }
    # A vehicle with two sorties: a fleet replay flies one mission per vehicle.
    sorties = tmp_path / "sorties"
    shutil.copytree(fleet2, sorties)
    vehicle = sorties / "vehicle_2"
    for suffix in (".plan", ".waypoints"):
        shutil.copy(vehicle / f"mission{suffix}", vehicle / f"mission_2{suffix}")
        (vehicle / f"mission{suffix}").rename(vehicle / f"mission_1{suffix}")
    cases["vehicle 2 has 2 sorties"] = ["--fleet", str(sorties)]
    for words, args in cases.items():
        result = CliRunner().invoke(main, [*base, *args])
        assert result.exit_code == 1, (words, result.output)
        assert len(result.stderr.splitlines()) == 1 and words in result.stderr, result.stderr


@pytest.mark.sitl_real
@pytest.mark.skipif(not os.access(BINARY, os.X_OK), reason=f"no ArduCopter SITL at {BINARY}")
def test_ctrl_c_during_a_fleet_replay_stops_every_sitl(
    fleet2: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both SITLs are up when Ctrl-C comes; both processes are gone after it."""
    import urpt_gcs.replay.fleet as fleet_module

    def interrupted(*_args: Any) -> Any:
        raise KeyboardInterrupt

    monkeypatch.setattr(fleet_module, "_fly_all", interrupted)
    said: list[str] = []
    settings = ReplaySettings(speedup=20.0, ardupilot=BINARY)
    with pytest.raises(KeyboardInterrupt):
        replay_fleet(SITE, TARGETS, read_fleet(fleet2), settings, said.append)
    pids = [int(m.split("(pid ")[1].rstrip(")")) for m in said if "(pid " in m]
    assert len(pids) == 2
    for pid in pids:
        assert not Path(f"/proc/{pid}").exists() or _zombie(pid)


def _synthetic_flight(
    east_m_s: float, north_m: float, boot_s: float, rate: float, seed: int
) -> Flight:
    """A vehicle crossing the origin's meridian at 100 m, 5 m/s east or west, its clock
    ``boot_s`` ahead, running ``rate`` simulated seconds per wall second; each position
    arrives 0-20 ms late."""
    from urpt_gcs.replay.record import TrackPoint, VehicleIdentity
    from urpt_gcs.vehicle.link import UploadReport

    rng = np.random.default_rng(seed)
    lat0, lon0 = 47.0, 9.0
    metres_lon = 111_412.84 * math.cos(math.radians(lat0)) - 93.5 * math.cos(3 * math.radians(lat0))
    metres_lat = 111_132.954 - 559.822 * math.cos(2 * math.radians(lat0))
    points = []
    for k in range(1000):
        wall = k * 0.1 / rate  # 10 positions per simulated second
        sim = wall * rate
        east = east_m_s * (sim - 50.0)
        points.append(
            TrackPoint(
                boot_s + sim,
                lat0 + north_m / metres_lat,
                lon0 + east / metres_lon,
                100.0,
                wall + float(rng.uniform(0.0, 0.02)),
            )
        )
    upload = UploadReport("udpin://x", "ardupilot", "ardupilot", 0, 1, 0.0, None)
    identity = VehicleIdentity("ArduPilot", "", "synthetic")
    return Flight(upload, (), tuple(points), 100.0, 100.0 / rate, identity)


def test_the_closest_approach_is_measured_at_equal_instants() -> None:
    """Two vehicles pass 3 m apart at t = 50 s; their clocks differ by 123 s and one runs at
    8x; arrival jitter of up to 20 ms (0.16 s simulated, 1.6 m at their closing speed) is
    taken off."""
    from urpt_gcs.replay.fleet import _send_times, closest_approach

    east = _synthetic_flight(5.0, 0.0, 0.0, 8.0, seed=1)
    west = _synthetic_flight(-5.0, 3.0, 123.0, 8.0, seed=2)
    sent = np.arange(1000) * 0.1 / 8.0
    for flight in (east, west):  # each position's time, its jitter taken off
        assert np.abs(_send_times(flight) - sent).max() < 0.003
    approach, takeoff = closest_approach([east, west], [400.0, 400.0])
    assert approach is not None
    assert approach.distance_m == pytest.approx(3.0, abs=0.1)
    assert approach.vertical_m == pytest.approx(0.0, abs=0.01)
    assert approach.time_s == pytest.approx(50.0, abs=0.2)
    assert takeoff[0] == pytest.approx(takeoff[1], abs=0.03)
