"""Mission files: QGroundControl ``.plan`` and Mission Planner ``.waypoints``.

Writers take a :class:`~urpt_gcs.flight.mission.Mission` and return the file's text; readers
take the text and the file's name (for messages) and return a ``Mission`` or raise
:class:`~urpt_gcs.errors.MissionFileError`.
"""

from __future__ import annotations

from urpt_gcs.files.formats.qgc_plan import plan_json, read_plan
from urpt_gcs.files.formats.waypoints import read_waypoints, waypoints_text

__all__ = ["plan_json", "read_plan", "read_waypoints", "waypoints_text"]
