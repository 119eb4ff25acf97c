"""The PX4 SITL launcher without PX4: which folder, start-up failures, stopping what it started.

A stand-in ``run.sh`` plays PX4's part; the real flights are in ``test_real_px4.py``.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO
from support.simulated import DEMO_PLAN, demo_mission

from urpt_gcs.cli import main
from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.replay import px4 as px4_sitl


def _build(folder: Path, script: str) -> Path:
    """A folder shaped like a PX4 SITL build whose run.sh runs ``script``."""
    (folder / "bin").mkdir(parents=True)
    (folder / "bin" / "px4").write_text("#!/bin/sh\n")
    (folder / "bin" / "px4").chmod(0o755)
    (folder / "bin" / "px4-param").write_text("px4")  # a symlink that lost its link
    run = folder / "run.sh"
    run.write_text("#!/bin/sh\n" + script)
    run.chmod(run.stat().st_mode | stat.S_IEXEC)
    return folder


def test_the_folder_comes_from_the_flag_or_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(px4_sitl.ENVIRONMENT, raising=False)
    with pytest.raises(SettingsError, match="give --px4 PATH or set URPT_PX4"):
        px4_sitl.find_build(None)
    with pytest.raises(SettingsError, match=r"no run\.sh there"):
        px4_sitl.find_build(tmp_path)
    build = _build(tmp_path / "px4", "exit 0\n")
    monkeypatch.setenv(px4_sitl.ENVIRONMENT, str(build))
    assert px4_sitl.find_build("") == build.resolve()


def test_a_px4_that_does_not_start_is_reported_and_cleaned_up(tmp_path: Path) -> None:
    build = _build(tmp_path / "px4", 'echo "ERROR [px4] no airframe"\nexit 1\n')
    before = set(Path("/tmp").glob("urpt-px4-*"))
    with (
        pytest.raises(LinkError, match=r"PX4 SITL did not start \(it said: .*no airframe"),
        px4_sitl.launch(build, demo_mission().home, 10.0),
    ):
        pass
    assert set(Path("/tmp").glob("urpt-px4-*")) == before


def test_what_was_started_is_stopped_on_an_error(tmp_path: Path) -> None:
    # rcS's px4-* commands are run through links the launcher makes to bin/px4.
    script = (
        '[ "$(readlink "$(command -v px4-param)")" = "$(dirname "$0")/bin/px4" ] || exit 3\n'
        '[ "$PX4_PARAM_TRIG_MODE" = 1 ] && [ "$PX4_SIM_SPEED_FACTOR" = 10 ] || exit 4\n'
        'echo "INFO [commander] Ready for takeoff!"\nexec sleep 600\n'
    )
    build = _build(tmp_path / "px4", script)
    with (
        pytest.raises(KeyboardInterrupt),
        px4_sitl.launch(build, demo_mission().home, 10.0) as sitl,
    ):
        assert sitl.url == f"udpin://127.0.0.1:{14540 + sitl.instance}"
        assert sitl.folder.is_dir()
        os.kill(sitl.pid, 0)  # running
        raise KeyboardInterrupt
    with pytest.raises(ProcessLookupError):
        os.kill(sitl.pid, 0)
    assert not sitl.folder.exists()
    assert not Path(f"/tmp/px4_lock-{sitl.instance}").exists()


def test_replay_on_px4_needs_a_px4_mission(tmp_path: Path) -> None:
    build = _build(tmp_path / "px4", "exit 0\n")
    args = ["sitl", "replay", "--dem", str(DEMO / "site.tif"), "--targets"]
    args += [str(DEMO / "targets.kml"), "--plan", str(DEMO_PLAN)]
    result = CliRunner().invoke(main, [*args, "--px4", str(build)])
    assert result.exit_code == 1
    assert "--px4 flies on PX4: plan the mission with --firmware px4" in result.stderr
    result = CliRunner().invoke(main, [*args, "--px4", str(tmp_path)])
    assert result.exit_code == 1
    assert "no run.sh there" in result.stderr
