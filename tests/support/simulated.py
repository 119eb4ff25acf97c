"""The simulated vehicle for tests: a real MAVLink peer on a free loopback UDP port."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

from conftest import DEMO_OUT

from urpt_gcs.files.formats import read_plan
from urpt_gcs.flight.mission import Mission
from urpt_gcs.replay.fly import free_udp_port
from urpt_gcs.sim import SitlServer, VehicleSettings

DEMO_PLAN = DEMO_OUT / "mission.plan"


def demo_mission() -> Mission:
    return read_plan(Path(DEMO_PLAN).read_text(), str(DEMO_PLAN))


@contextmanager
def simulated(mission: Mission | None = None, **settings: Any) -> Iterator[tuple[SitlServer, str]]:
    """A simulated vehicle (home at the mission's) and the MAVSDK URL that reaches it."""
    port = free_udp_port()
    vehicle = VehicleSettings(**settings)
    if mission is not None:
        vehicle = replace(vehicle, home=mission.home)
    with SitlServer(vehicle, f"udpout://127.0.0.1:{port}") as server:
        yield server, f"udpin://127.0.0.1:{port}"
