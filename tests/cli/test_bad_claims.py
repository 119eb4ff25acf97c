"""Claims checked as strongly as they are stated: inputs that once made a command claim more
than it had checked.

Each case: the command refuses (exit 1, exactly one line on stderr naming the input and the
fix, no traceback) before anything reaches a vehicle, or its verdict names what it could not
confirm. Uploads go to the project's simulated copter, a real MAVLink peer; what it holds
afterwards is read from its store.
"""

from __future__ import annotations

import csv
import json
import shutil
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from conftest import DEMO, DEMO_OUT
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.fleet_helpers import HOME_EAST, Vehicle, build_fleet, plan_fleet_of_two
from support.simulated import simulated

from urpt_gcs.cli import main
from urpt_gcs.files.fleet_folder import read_fleet
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.replay.fly import free_udp_port
from urpt_gcs.sim import SitlServer, VehicleSettings
from urpt_gcs.site.targets import Target, read_targets

WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
FIRST = ("T01", "T02", "T03", "T04", "T05", "T06", "T07", "T08")
SECOND = ("T09", "T10", "T11", "T12", "T13", "T14", "T15", "T16")


def _one_line(result: Any) -> str:
    """The refusal's line: exit 1, nothing on stdout, one line on stderr, no traceback."""
    assert result.exit_code == 1, result.output + result.stderr
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("urpt-gcs: error: ")
    return lines[0]


@contextmanager
def copters(fleet: Path) -> Iterator[list[tuple[SitlServer, str]]]:
    """One simulated copter per vehicle of ``fleet``, at its home."""
    with ExitStack() as stack:
        running = []
        for vehicle in read_fleet(fleet).vehicles:
            home = read_mission(vehicle.missions[0]).home
            port = free_udp_port()
            server = SitlServer(VehicleSettings(home=home), f"udpout://127.0.0.1:{port}")
            running.append((stack.enter_context(server), f"udpin://127.0.0.1:{port}"))
        yield running


def _upload(fleet: Path, running: list[tuple[SitlServer, str]], *args: str) -> Any:
    connects = [a for _server, url in running for a in ("--connect", url)]
    return CliRunner().invoke(main, ["upload", "--fleet", str(fleet), *connects, *args])


def _held(running: list[tuple[SitlServer, str]]) -> list[int]:
    """How many mission items each copter holds (home alone, or nothing: none uploaded)."""
    return [len(server.vehicle.store.items()) for server, _url in running]


@pytest.fixture(scope="module")
def sorties2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two vehicles: vehicle 1 flies 2 sorties (a 4 min battery), vehicle 2 one."""
    return build_fleet(
        tmp_path_factory.mktemp("sorties2"),
        [
            Vehicle(FIRST, 481.0, args=("--endurance", "4")),
            Vehicle(SECOND, 491.0, HOME_EAST),
        ],
    )


@pytest.fixture(scope="module")
def planned2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return plan_fleet_of_two(tmp_path_factory.mktemp("planned2") / "out")


# --- upload --fleet --sortie N: a sortie no vehicle flies -----------------------------------


@pytest.mark.parametrize("sortie", ["3", "99", "0", "-1"])
def test_a_sortie_no_vehicle_flies_is_refused_before_connecting(
    sorties2: Path, sortie: str
) -> None:
    assert [len(v.missions) for v in read_fleet(sorties2).vehicles] == [2, 1]
    with copters(sorties2) as running:
        result = _upload(sorties2, running, "--sortie", sortie)
        held = _held(running)
    line = _one_line(result)
    assert line == (
        f"urpt-gcs: error: --sortie {sortie}: the vehicles of '{sorties2}' fly at most 2 "
        "sorties: give --sortie 1 to 2"
    )
    assert all(count <= 1 for count in held)  # nothing but home


def test_a_fleet_of_single_sorties_names_the_only_sortie(planned2: Path) -> None:
    assert all(len(v.missions) == 1 for v in read_fleet(planned2).vehicles)
    with copters(planned2) as running:
        line = _one_line(_upload(planned2, running, "--sortie", "2"))
    assert line == (
        f"urpt-gcs: error: --sortie 2: every vehicle of '{planned2}' flies one sortie: give "
        "--sortie 1, or leave it out"
    )


def test_the_second_sortie_goes_to_the_vehicle_that_flies_it(sorties2: Path) -> None:
    with copters(sorties2) as running:
        result = _upload(sorties2, running, "--sortie", "2")
        held = _held(running)
    assert result.exit_code == 0, result.output + result.stderr
    lines = result.stdout.splitlines()
    assert "vehicle_1/mission_2.plan (sortie 2 of 2)" in lines[0]
    assert lines[1].endswith("skipped, it has 1 sortie, no sortie 2")
    assert lines[2] == "fleet: 1 of 1 vehicles hold their mission, verified"
    assert held[0] > 1 and held[1] <= 1


# --- upload --fleet: mission files that are not the ones the fleet summary records -----------


def _tampered(fleet: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "fleet"
    shutil.copytree(fleet, copy)
    return copy


def _forget_digests(fleet: Path) -> None:
    """The fleet summary as written before it recorded its missions' digests."""
    path = fleet / "summary.json"
    data = json.loads(path.read_text())
    for row in data["fleet"]["vehicles"]:
        row.pop("mission_sha256", None)
    path.write_text(json.dumps(data, indent=2))


@pytest.mark.parametrize("digests", [True, False], ids=["digests", "older-summary"])
@pytest.mark.parametrize("suffix", [".plan", ".waypoints"])
def test_vehicle_1s_mission_copied_over_vehicle_2s_is_refused(
    planned2: Path, tmp_path: Path, suffix: str, digests: bool
) -> None:
    fleet = _tampered(planned2, tmp_path)
    if not digests:
        _forget_digests(fleet)
    if suffix == ".waypoints":  # a fleet read from its .waypoints: no .plan beside them
        for plan in fleet.glob("vehicle_*/mission*.plan"):
            plan.unlink()
    name = f"mission{suffix}"
    shutil.copy(fleet / "vehicle_1" / name, fleet / "vehicle_2" / name)
    with copters(planned2) as running:
        result = _upload(fleet, running)
        held = _held(running)
    line = _one_line(result)
    assert f"'{fleet / 'vehicle_2' / name}'" in line
    assert "vehicle 1's" in line  # what it is instead
    assert line.endswith("restore the folder as urpt-gcs plan wrote it, or plan the fleet again"), (
        line
    )
    assert all(count <= 1 for count in held)


def test_vehicle_1s_folder_copied_over_vehicle_2s_is_refused(
    planned2: Path, tmp_path: Path
) -> None:
    """Mission and its own summary.json agree, but the fleet's summary gave vehicle 2 other
    targets: an older summary, without digests, still tells."""
    fleet = _tampered(planned2, tmp_path)
    _forget_digests(fleet)
    shutil.rmtree(fleet / "vehicle_2")
    shutil.copytree(fleet / "vehicle_1", fleet / "vehicle_2")
    with copters(planned2) as running:
        line = _one_line(_upload(fleet, running))
    assert f"'{fleet / 'vehicle_2' / 'summary.json'}'" in line
    assert "vehicle 2" in line and "other targets" in line
    assert line.endswith("restore the folder as urpt-gcs plan wrote it, or plan the fleet again")


def test_a_mission_edited_after_planning_is_refused(planned2: Path, tmp_path: Path) -> None:
    """Same stops, another altitude: only the digest the summary recorded tells."""
    fleet = _tampered(planned2, tmp_path)
    path = fleet / "vehicle_2" / "mission.plan"
    plan = json.loads(path.read_text())
    for item in plan["mission"]["items"]:
        if item.get("command") == WAYPOINT:
            item["params"][6] += 30.0
    path.write_text(json.dumps(plan, indent=4))
    with copters(planned2) as running:
        line = _one_line(_upload(fleet, running))
    assert f"'{path}'" in line and "changed after planning" in line


def test_a_sortie_added_to_a_vehicle_is_refused(sorties2: Path, tmp_path: Path) -> None:
    """vehicle 2 of an older summary (no digests) given a second sortie: a copy of its first."""
    fleet = _tampered(sorties2, tmp_path)
    vehicle = fleet / "vehicle_2"
    for suffix in (".plan", ".waypoints"):
        (vehicle / f"mission{suffix}").rename(vehicle / f"mission_1{suffix}")
        shutil.copy(vehicle / f"mission_1{suffix}", vehicle / f"mission_2{suffix}")
    with copters(sorties2) as running:
        line = _one_line(_upload(fleet, running))
    assert line == (
        f"urpt-gcs: error: vehicle 2's folder '{vehicle}' holds 2 mission files but "
        f"'{fleet / 'summary.json'}' plans 1 sortie for it: restore the folder as urpt-gcs plan "
        "wrote it, or plan the fleet again"
    )
    # Its own summary says so too, where the fleet's does not count the sorties.
    data = json.loads((fleet / "summary.json").read_text())
    del data["fleet"]["vehicles"][1]["sorties"]
    (fleet / "summary.json").write_text(json.dumps(data))
    with copters(sorties2) as running:
        line = _one_line(_upload(fleet, running))
    assert f"'{vehicle / 'mission_2.plan'}' does not fly the stops" in line
    assert "(it flies vehicle 2's sortie 1)" in line


def test_an_untouched_fleet_still_uploads(planned2: Path, tmp_path: Path) -> None:
    summary = json.loads((planned2 / "summary.json").read_text())
    for row in summary["fleet"]["vehicles"]:
        assert set(row["mission_sha256"]) == {"mission.plan", "mission.waypoints"}
    older = _tampered(planned2, tmp_path)
    _forget_digests(older)
    for fleet in (planned2, older):
        with copters(fleet) as running:
            result = _upload(fleet, running)
        assert result.exit_code == 0, result.output + result.stderr
        assert result.stdout.splitlines()[-1] == (
            "fleet: 2 of 2 vehicles hold their mission, verified"
        )


def test_a_single_upload_warns_of_a_mission_its_summary_does_not_plan(tmp_path: Path) -> None:
    """Another plan's mission in a plan folder: it goes up as given, with a warning."""
    folder = tmp_path / "plan"
    shutil.copytree(DEMO_OUT, folder)
    path = folder / "mission.waypoints"
    rows = [line.split("\t") for line in path.read_text().splitlines()]
    for row in rows[2:]:
        if row[3] == str(WAYPOINT):  # its latitude 22 m further north
            row[8] = f"{float(row[8]) + 0.0002:.8f}"
    path.write_text("".join("\t".join(row) + "\n" for row in rows))
    mission = read_mission(path)
    with simulated(mission) as (_server, url):
        result = CliRunner().invoke(main, ["upload", str(path), "--connect", url])
    assert result.exit_code == 0, result.output + result.stderr
    assert result.stderr == (
        f"urpt-gcs: warning: '{path}' does not fly the stops '{folder / 'summary.json'}' "
        "plans for it: it is not the mission planned there\n"
    )
    with simulated(mission) as (_server, url):
        args = ["upload", str(DEMO_OUT / "mission.waypoints"), "--connect", url]
        same = CliRunner().invoke(main, args)
    assert same.exit_code == 0 and same.stderr == ""


# --- sitl replay: every target of --targets is judged ---------------------------------------

REPLAY = ["sitl", "replay", "--dem", str(DEMO / "site.tif"), "--speedup", "200"]
# In the south-east of the site, some 150 m from every stop of the demo plan.
FAR = Target("X99 south-east field", 47.68850, 9.42580)


def _targets_csv(path: Path, targets: list[Target]) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["name", "lat", "lon"])
        writer.writerows([t.name, f"{t.lat_deg:.9f}", f"{t.lon_deg:.9f}"] for t in targets)
    return path


@pytest.mark.parametrize("name", ["mission.plan", "mission.waypoints"])
def test_a_target_the_plan_does_not_photograph_fails_the_replay(tmp_path: Path, name: str) -> None:
    demo = list(read_targets(DEMO / "targets.kml").targets)
    targets = _targets_csv(tmp_path / "targets.csv", [*demo, FAR])
    result = CliRunner().invoke(
        main, [*REPLAY, "--targets", str(targets), "--plan", str(DEMO_OUT / name)]
    )
    line = _one_line_after_report(result)
    assert "targets   16 of 17 seen" in result.output
    rows = _target_rows(result.output)
    for target in demo:
        assert " photo " in rows[target.name], rows[target.name]
    assert "NOT SEEN: not a target of the plan; nearest photo" in rows[FAR.name]
    assert "result    FAIL" in result.output
    assert line == (
        f"urpt-gcs: error: replay failed: target {FAR.name} of '{targets}' is not one {name} "
        "was planned to photograph, and no photo sees it: plan again with this target file, "
        "or give the one the plan was made from"
    )


def test_a_target_moved_in_the_targets_file_is_judged_where_it_now_is(tmp_path: Path) -> None:
    demo = list(read_targets(DEMO / "targets.kml").targets)
    moved = [
        Target(t.name, t.lat_deg - 0.0015, t.lon_deg) if t.name.startswith("T14") else t
        for t in demo
    ]
    targets = _targets_csv(tmp_path / "targets.csv", moved)
    result = CliRunner().invoke(
        main, [*REPLAY, "--targets", str(targets), "--plan", str(DEMO_OUT / "mission.plan")]
    )
    line = _one_line_after_report(result)
    assert "targets   15 of 16 seen" in result.output
    assert line.startswith(
        f"urpt-gcs: error: replay failed: target T14 east plateau of '{targets}' is not where "
        "mission.plan was planned to photograph it"
    )


def test_the_plans_own_targets_still_pass(tmp_path: Path) -> None:
    targets = _targets_csv(
        tmp_path / "targets.csv", list(read_targets(DEMO / "targets.kml").targets)
    )
    result = CliRunner().invoke(
        main, [*REPLAY, "--targets", str(targets), "--plan", str(DEMO_OUT / "mission.plan")]
    )
    assert result.exit_code == 0, result.output + result.stderr
    assert "targets   16 of 16 seen" in result.output and "result    PASS" in result.output
    assert result.stderr == ""


def _target_rows(report: str) -> dict[str, str]:
    """The report's line of each target (indented 4, its name first), by name."""
    rows = [line for line in report.splitlines() if line[:4] == "    " and line[4] != " "]
    return {row.strip().split("  ")[0]: row for row in rows}


def _one_line_after_report(result: Any) -> str:
    """A failed replay: the report on stdout, one line on stderr, exit 1."""
    assert result.exit_code == 1, result.output + result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_a_sortie_number_without_a_fleet_is_refused_before_connecting() -> None:
    # It was ignored: the file given went up, whatever --sortie said.
    args = ["upload", str(DEMO_OUT / "mission.plan"), "--sortie", "2"]
    result = CliRunner().invoke(main, [*args, "--connect", "udpin://127.0.0.1:1", "--timeout", "1"])
    assert result.exit_code == 1
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("urpt-gcs: error: --sortie 2 picks a sortie of a --fleet upload")
