"""The ``urpt-gcs`` command line: a thin layer over the library, one module per command group.

Only :class:`urpt_gcs.errors.UrptError` is caught: its message goes to stderr on one line and
the exit status is 1. Usage errors (unknown flags, a word where a number belongs) exit 2.
"""

from __future__ import annotations

from urpt_gcs.cli import batch, bench, flown, plan, vehicle
from urpt_gcs.cli._root import main

__all__ = ["batch", "bench", "flown", "main", "plan", "vehicle"]
