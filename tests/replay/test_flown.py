"""``urpt-gcs flown`` and ``plan --resume`` on the logs of real flights.

The demo is flown on ArduPilot's ArduCopter SITL and on PX4's SITL through a relay that
records the ground station's ``.tlog`` (as QGroundControl and MAVProxy record one); the
ArduCopter flights also leave the vehicle's own DataFlash ``.bin``. ArduCopter flies it once
in full and once called home after its fifth photo, as a pilot would after a battery
warning; PX4 flies the flight called home.

What the report must say is checked independently of the judge: a flight's targets are those
the replay judge saw on the same flight; a flight stopped after its fifth photo
missed exactly the targets the plan's first five stops do not see (the planner's own record
of what each stop sees, in ``summary.json``). The resumed plan must cover exactly those.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO, SHARED
from mavsdk.asyncio.plugins.param import ParamAsync
from support.recorder import TlogRecorder

from urpt_gcs.cli import main
from urpt_gcs.errors import SettingsError
from urpt_gcs.files.mission_file import read_mission
from urpt_gcs.replay import ardupilot as ardupilot_sitl
from urpt_gcs.replay import px4 as px4_sitl
from urpt_gcs.replay.expected import expected_checks
from urpt_gcs.replay.flightlog import read_flight_log
from urpt_gcs.replay.flown import judge_flown
from urpt_gcs.replay.fly import ReplaySettings, estimate_wall_timeout_s, fly_connected
from urpt_gcs.replay.judge import judge
from urpt_gcs.replay.record import Flight
from urpt_gcs.vehicle.mavsdk_link import connect

SITE, TARGETS = DEMO / "site.tif", DEMO / "targets.kml"
ARDUCOPTER = SHARED / "ardupilot" / "arducopter"
PX4 = SHARED / "px4"
AP_SPEEDUP, PX4_SPEEDUP = 20.0, 10.0
# The flight called home after this many photos.
CUT_AFTER = 5


@dataclass(frozen=True)
class Flown:
    """One flight: the plan folder, what the ground station saw, and its logs."""

    plan: Path
    flight: Flight
    tlog: Path
    dataflash: Path | None


def _plan(out: Path, *extra: str) -> Path:
    args = ["plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(out)]
    result = CliRunner().invoke(main, [*args, "--no-map", "--quiet", *extra])
    assert result.exit_code == 0, result.output
    return out


def _fly(plan: Path, vehicle_port: int, tcp: bool, tlog: Path, cut: int | None) -> Flight:
    mission = read_mission(plan / "mission.plan")
    speedup = AP_SPEEDUP if tcp else PX4_SPEEDUP
    settings = ReplaySettings(speedup=speedup)
    recorder = TlogRecorder(vehicle_port, tlog, tcp=tcp, rtl_after_photos=cut)

    async def run() -> Flight:
        async with connect(recorder.gcs_url, 20.0) as link:
            if tcp:
                # A DataFlash log per flight: ArduPilot closes it at the disarm.
                param = ParamAsync(link.system)
                await param.set_param_int("LOG_FILE_DSRMROT", 1)
                param.destroy()
            timeout = estimate_wall_timeout_s(mission, settings)
            return await fly_connected(link, mission, settings, timeout, print, "SITL")

    try:
        return asyncio.run(run())
    finally:
        recorder.close()


def _newest_dataflash(folder: Path, not_this: Path | None) -> Path:
    """The DataFlash log of the flight just ended (ArduPilot numbers them in order)."""
    logs = sorted(folder.rglob("*.BIN"))
    assert logs and logs[-1] != not_this, f"ArduCopter wrote no new DataFlash log in {folder}"
    return logs[-1]


@pytest.fixture(scope="module")
def arducopter(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Flown]]:
    if not os.access(ARDUCOPTER, os.X_OK):
        pytest.skip(f"no ArduCopter SITL at {ARDUCOPTER}")
    folder = tmp_path_factory.mktemp("flown-ardupilot")
    plan = _plan(folder / "plan")
    flights = {}
    home = read_mission(plan / "mission.plan").home
    with ardupilot_sitl.launch(ARDUCOPTER, home, AP_SPEEDUP) as sitl:
        port = int(sitl.url.rsplit(":", 1)[1])
        last = None
        for name, cut in (("complete", None), ("cut", CUT_AFTER)):
            tlog = folder / f"{name}.tlog"
            flight = _fly(plan, port, True, tlog, cut)
            last = _newest_dataflash(Path(sitl.folder), last)
            kept = folder / f"{name}.bin"
            shutil.copy(last, kept)
            flights[name] = Flown(plan, flight, tlog, kept)
    yield flights


@pytest.fixture(scope="module")
def px4(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Flown]]:
    if not (PX4 / "run.sh").is_file():
        pytest.skip(f"no PX4 SITL at {PX4}")
    folder = tmp_path_factory.mktemp("flown-px4")
    plan = _plan(folder / "plan", "--firmware", "px4")
    # The flight called home only: PX4's photo messages are read from it, and judged against
    # the replay's judge of the same flight; ArduCopter flies the complete one too.
    home = read_mission(plan / "mission.plan").home
    with px4_sitl.launch(PX4, home, PX4_SPEEDUP) as sitl:
        tlog = folder / "cut.tlog"
        flight = _fly(plan, int(sitl.url.rsplit(":", 1)[1]), False, tlog, CUT_AFTER)
    yield {"cut": Flown(plan, flight, tlog, None)}


def _flown(plan: Path, *logs: Path, extra: tuple[str, ...] = ()) -> dict[str, object]:
    args = ["flown", str(plan), *(a for log in logs for a in ("--log", str(log)))]
    result = CliRunner().invoke(main, [*args, "--dem", str(SITE), "--json", *extra])
    assert result.exit_code == 0, result.output
    data: dict[str, object] = json.loads(result.output)
    return data


def _replay_seen(flown: Flown) -> set[str]:
    """What the replay's judge says the same flight saw, every target of the file."""
    mission_path = flown.plan / "mission.plan"
    mission = read_mission(mission_path)
    expected = expected_checks(mission_path, mission, None, None)
    report = judge(flown.flight, mission, SITE, TARGETS, expected, str(mission_path), True)
    return {t.name for t in report.targets if t.photo is not None}


def _not_seen_by_first_stops(plan: Path, photos: int) -> set[str]:
    """The targets the plan's first ``photos`` stops do not see, by the planner's record."""
    summary = json.loads((plan / "summary.json").read_text())
    seen = {name for stop in summary["stops"][:photos] for name in stop["sees"]}
    return set(summary["target_names"]) - seen


def _check_complete(flown: Flown, log: Path) -> None:
    data = _flown(flown.plan, log)
    names = json.loads((flown.plan / "summary.json").read_text())["target_names"]
    assert data["missed"] == []
    assert data["seen"] == len(names) == 16
    assert {t["name"] for t in data["by_target"] if t["seen"]} == _replay_seen(flown)  # type: ignore[attr-defined]
    assert data["logs"][0]["photos"] == len(flown.flight.photos)  # type: ignore[index]


def _check_cut(flown: Flown, log: Path, out: Path) -> None:
    data = _flown(flown.plan, log)
    photos = data["logs"][0]["photos"]  # type: ignore[index]
    # Called home after the fifth photo: a sixth may have been taken before the command took.
    assert CUT_AFTER <= photos < 10, photos
    assert photos == len(flown.flight.photos)
    missing = _not_seen_by_first_stops(flown.plan, photos)
    assert missing, "the flight was cut before its last stop"
    assert set(data["missed"]) == missing  # type: ignore[arg-type]
    assert {t["name"] for t in data["by_target"] if t["seen"]} == _replay_seen(flown)  # type: ignore[attr-defined]
    # Re-fly only those, with the plan's own settings and home.
    result = CliRunner().invoke(
        main, ["plan", "--resume", str(flown.plan), "--log", str(log), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    resumed = json.loads((out / "summary.json").read_text())
    original = json.loads((flown.plan / "summary.json").read_text())
    assert set(resumed["target_names"]) == missing
    assert {n for s in resumed["stops"] for n in s["sees"]} == missing
    assert resumed["home"]["lat_deg"] == original["home"]["lat_deg"]
    assert resumed["settings"] == original["settings"] | {"home": resumed["settings"]["home"]}
    assert resumed["firmware"] == original["firmware"]
    print(f"\n{log.name}: {photos} photos, {len(missing)} missed, resumed plan "
          f"{resumed['tour_length_m']:.1f} m over {len(resumed['stops'])} stops")  # fmt: skip


@pytest.mark.sitl_real
def test_a_complete_arducopter_flight_saw_every_target(arducopter: dict[str, Flown]) -> None:
    flown = arducopter["complete"]
    _check_complete(flown, flown.tlog)
    assert flown.dataflash is not None
    _check_complete(flown, flown.dataflash)


@pytest.mark.sitl_real
def test_an_arducopter_flight_called_home_is_resumed(
    arducopter: dict[str, Flown], tmp_path: Path
) -> None:
    flown = arducopter["cut"]
    _check_cut(flown, flown.tlog, tmp_path / "from-tlog")
    assert flown.dataflash is not None
    _check_cut(flown, flown.dataflash, tmp_path / "from-bin")


@pytest.mark.sitl_real
def test_a_px4_flight_called_home_is_resumed(px4: dict[str, Flown], tmp_path: Path) -> None:
    _check_cut(px4["cut"], px4["cut"].tlog, tmp_path / "resumed")


@pytest.mark.sitl_real
def test_both_sorties_logs_together(arducopter: dict[str, Flown]) -> None:
    """The cut flight and the complete one together saw everything; alone, the cut did not."""
    data = _flown(arducopter["cut"].plan, arducopter["cut"].tlog, arducopter["complete"].tlog)
    assert data["missed"] == []


def _error(*args: str) -> str:
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


@pytest.mark.sitl_real
def test_bad_logs_get_one_line(
    arducopter: dict[str, Flown], px4: dict[str, Flown], tmp_path: Path
) -> None:
    flown = arducopter["complete"]
    plan = str(flown.plan)
    garbage = tmp_path / "noise.tlog"
    garbage.write_bytes(os.urandom(20_000))
    assert "holds no MAVLink" in _error("flown", plan, "--log", str(garbage), "--dem", str(SITE))
    fake_bin = tmp_path / "noise.bin"
    fake_bin.write_bytes(os.urandom(20_000))
    assert "holds no" in _error("flown", plan, "--log", str(fake_bin), "--dem", str(SITE))
    ulog = tmp_path / "flight.ulg"
    ulog.write_bytes(b"ULog\x01")
    assert ".ulg" in _error("flown", plan, "--log", str(ulog))
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    assert "is empty" in _error("flown", plan, "--log", str(empty))
    # A PX4 flight's log against the ArduPilot plan.
    line = _error("flown", plan, "--log", str(px4["cut"].tlog), "--dem", str(SITE))
    assert "PX4 vehicle" in line and "ArduPilot" in line
    # A log of another plan (PX4's plan flown, checked against PX4's sibling on another plan).
    other = _plan(tmp_path / "other", "--fov", "40")
    line = _error("flown", str(other), "--log", str(flown.tlog), "--dem", str(SITE))
    assert "no sortie of this plan" in line
    # No camera messages: the log without its CAMERA_FEEDBACK records.
    blind = tmp_path / "blind.tlog"
    blind.write_bytes(_without(flown.tlog.read_bytes(), 180))
    assert "no photo message" in _error("flown", plan, "--log", str(blind), "--dem", str(SITE))
    # A fleet's folder, a folder with no plan.
    assert "no summary.json" in _error("flown", str(tmp_path), "--log", str(flown.tlog))


def _without(tlog: bytes, message_id: int) -> bytes:
    """A tlog's records without those of one message id."""
    kept, at = [], 0
    while at + 10 < len(tlog):
        frame = tlog[at + 8 :]
        length = frame[1]
        size = 8 + (12 + length + (13 if frame[2] & 1 else 0) if frame[0] == 0xFD else 8 + length)
        record = tlog[at : at + size]
        msgid = int.from_bytes(frame[7:10], "little") if frame[0] == 0xFD else frame[5]
        if msgid != message_id:
            kept.append(record)
        at += size
    return b"".join(kept)


@pytest.mark.sitl_real
def test_a_log_cut_mid_flight_is_read_with_a_warning(
    arducopter: dict[str, Flown], tmp_path: Path
) -> None:
    """A tlog that ends in the air (copied while flying): what it holds is judged, and it says
    that photos after its end are unknown."""
    whole = arducopter["complete"].tlog.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(whole[: len(whole) // 2] + b"\xfd\x09")  # and a frame torn off
    log = read_flight_log(cut)
    assert log.armed_at_end
    assert any("cut short" in w for w in log.warnings)
    report = judge_flown(arducopter["complete"].plan, [cut], SITE)
    assert 0 < len(report.missed) < 16


def test_flown_needs_a_plan_folder(tmp_path: Path) -> None:
    log = tmp_path / "x.tlog"
    log.write_bytes(struct.pack(">Q", 0) + b"\xfd")
    with pytest.raises(SettingsError, match=r"holds no summary\.json"):
        judge_flown(tmp_path, [log])


def test_log_flag_without_resume_is_refused() -> None:
    assert "--log belongs to --resume" in _error(
        "plan", "--dem", str(SITE), "--targets", str(TARGETS), "--log", "x.tlog"
    )
