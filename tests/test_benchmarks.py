"""Every script in ``benchmarks/`` still starts: its imports resolve and its options parse.

The scripts run for minutes and are run on demand, so nothing else would notice when a module
they import moves. ``--help`` stops after the imports and the option parser.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import REPO

SCRIPTS = sorted((REPO / "benchmarks").glob("*.py"))


def test_there_are_benchmark_scripts() -> None:
    assert SCRIPTS, "benchmarks/ holds no script; update this test if that is intended"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_benchmark_script_starts(script: object) -> None:
    done = subprocess.run(
        [sys.executable, str(script), "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert "usage:" in done.stdout
