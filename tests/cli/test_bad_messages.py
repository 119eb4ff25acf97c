"""Messages that must advise what the operator's own settings allow, in cases the catalogue
(test_bad_inputs.py) cannot reach from the command line alone."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

import urpt_gcs.pipeline.separation as separation
from urpt_gcs.cli import main


def _plan(out: Path, *args: str) -> tuple[int, str]:
    base = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    result = CliRunner().invoke(
        main, [*base, "--out", str(out), "--no-map", "--time-limit", "0.5", *args]
    )
    return result.exit_code, result.stderr


def test_a_clash_in_altitude_mode_advises_the_layers_not_altitude_mode(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # No start delay allowed: two vehicles from one home meet as they climb.
    monkeypatch.setattr(separation, "MAX_DELAY_SHARE", 0.0)
    code, stderr = _plan(tmp_path / "out", "--vehicles", "2", "--separation", "altitude")
    assert code == 1, stderr
    (line,) = stderr.strip().splitlines()
    assert "come within" in line
    assert line.endswith("or raise --layer-spacing")
    assert "--separation altitude" not in line
    assert not (tmp_path / "out").exists()


def test_a_replay_timeout_under_a_second_is_named_as_given() -> None:
    # It was printed rounded to whole seconds: "did not land within 0 s".
    args = [
        "sitl",
        "replay",
        "--dem",
        str(DEMO / "site.tif"),
        "--targets",
        str(DEMO / "targets.kml"),
        "--plan",
        str(Path(__file__).resolve().parents[1] / "data" / "demo_plan" / "mission.plan"),
        "--timeout",
        "0.5",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    (line,) = result.stderr.strip().splitlines()
    assert "did not land within 0.5 s of wall time" in line
