"""A fleet plan with a vehicle left idle, end to end: the planner's folder is read with the
idle vehicle holding no mission, ``upload --fleet`` puts the mission on the flying vehicle
only (the idle one is not even connected to), and ``sitl replay --fleet`` flies the flying
one alone and passes.

The plan is the demo with a second vehicle at 0.1 m/s, too slow for any share of the targets
to land the fleet sooner than the first vehicle alone.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main
from urpt_gcs.errors import MissionFileError
from urpt_gcs.files.fleet_folder import read_fleet
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.replay.fleet import fleet_report_text, replay_fleet
from urpt_gcs.replay.fly import ReplaySettings, free_udp_port
from urpt_gcs.sim import SitlServer, VehicleSettings

SITE, TARGETS = DEMO / "site.tif", DEMO / "targets.kml"


@pytest.fixture(scope="module")
def idle2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("idle2")
    fleet = folder / "fleet.toml"
    fleet.write_text("[[vehicle]]\n\n[[vehicle]]\nspeed_m_s = 0.1\n")
    out = folder / "out"
    args = [
        "plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(out),
        "--fleet", str(fleet), "--no-map", "--time-limit", "1", "--quiet",
    ]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    return out


def test_the_idle_vehicle_is_read_with_no_mission(idle2: Path) -> None:
    first, second = read_fleet(idle2).vehicles
    assert not first.idle and first.missions and len(first.targets) == 16
    assert second.idle and second.missions == () and second.targets == ()
    assert second.start_delay_s == 0.0


def test_a_mission_left_in_the_idle_vehicles_folder_is_refused(idle2: Path, tmp_path: Path) -> None:
    """A mission file where the plan flies none is not this plan's: refused, in one line."""
    copy = tmp_path / "out"
    shutil.copytree(idle2, copy)
    shutil.copy(copy / "vehicle_1" / "mission.plan", copy / "vehicle_2" / "mission.plan")
    with pytest.raises(MissionFileError, match="vehicle 2 is idle, yet its folder") as caught:
        read_fleet(copy)
    assert "\n" not in str(caught.value)


def test_upload_passes_the_idle_vehicle_by(idle2: Path) -> None:
    """Vehicle 2's connection is given (one per vehicle, in order) but never opened: nobody
    listens there, and the upload still succeeds."""
    fleet = read_fleet(idle2)
    home = read_mission(fleet.vehicles[0].missions[0]).home
    port, nobody = free_udp_port(), free_udp_port()
    with SitlServer(VehicleSettings(home=home), f"udpout://127.0.0.1:{port}") as server:
        result = CliRunner().invoke(
            main,
            [
                "upload", "--fleet", str(idle2), "--connect", f"udpin://127.0.0.1:{port}",
                "--connect", f"udpin://127.0.0.1:{nobody}", "--timeout", "3",
            ],
        )  # fmt: skip
        held = server.vehicle.store.items()
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert "items sent, read back identical" in lines[0]
    assert lines[1].startswith("vehicle 2 on ") and "idle in this plan, nothing sent" in lines[1]
    assert lines[2] == "fleet: 1 of 1 vehicles hold their mission, verified"
    assert len(held) > 1


def test_replay_flies_the_flying_vehicle_alone(idle2: Path) -> None:
    report = replay_fleet(SITE, TARGETS, read_fleet(idle2), ReplaySettings(speedup=50.0))
    text = fleet_report_text(report)
    assert report.ok, (report.problems, report.together.problems, text)
    assert [v.number for v in report.vehicles] == [1]
    assert [v.number for v in report.idle] == [2]
    assert report.approach is None
    assert "vehicle 2  idle in the plan: not flown" in text
