"""The geofence on the wire: zones read from a .plan, fence items, and the read-back check."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Sequence
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support.simulated import DEMO_PLAN

from urpt_gcs.errors import LinkError, MissionFileError
from urpt_gcs.flight.geofence import (
    FENCE_TYPE,
    FenceCircle,
    Geofence,
    compare_fence,
    fence_items,
    read_plan_geofence,
)
from urpt_gcs.flight.wire import WireItem
from urpt_gcs.vehicle.link import upload_fence_verified
from urpt_gcs.vehicle.protocol import FenceRefused

SQUARE = ((47.688, 9.422), (47.688, 9.4245), (47.6895, 9.4245), (47.6895, 9.422))


def test_the_demo_plan_fence_is_one_inclusion_polygon() -> None:
    fence = read_plan_geofence(DEMO_PLAN.read_text(), str(DEMO_PLAN))
    raw = json.loads(DEMO_PLAN.read_text())["geoFence"]["polygons"][0]["polygon"]
    assert len(fence.polygons) == 1 and not fence.circles
    assert fence.polygons[0].inclusion
    assert [list(v) for v in fence.polygons[0].vertices] == raw
    assert fence.describe() == f"inclusion polygon ({len(raw)} vertices)"


def test_fence_items_as_qgroundcontrol_sends_them() -> None:
    fence = Geofence(Geofence.inclusion(SQUARE).polygons, (FenceCircle(47.689, 9.423, 50.0),))
    items = fence_items(fence)
    assert [i.seq for i in items] == list(range(5))
    assert {i.mission_type for i in items} == {FENCE_TYPE}
    assert {i.frame for i in items} == {mavlink.MAV_FRAME_GLOBAL}
    vertex = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    assert [(i.command, i.param1) for i in items[:4]] == [(vertex, 4.0)] * 4
    assert (items[0].x, items[0].y) == (476880000, 94220000)
    assert (items[4].command, items[4].param1) == (mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 50)


def test_read_back_as_ardupilot_returns_it_is_equal() -> None:
    sent = fence_items(Geofence.inclusion(SQUARE))
    got = [replace(i, autocontinue=0, current=0) for i in sent]  # as ArduPilot answers
    assert compare_fence(sent, got, "ardupilot").equal


def test_a_moved_vertex_or_a_missing_one_differs() -> None:
    sent = fence_items(Geofence.inclusion(SQUARE))
    moved = [*sent[:2], replace(sent[2], x=sent[2].x + 1), sent[3]]
    (line,) = compare_fence(sent, moved, "ardupilot").mismatches
    assert line.startswith("fence seq 2 (NAV_FENCE_POLYGON_VERTEX_INCLUSION): position sent")
    assert not compare_fence(sent, sent[:3], "ardupilot").equal


@pytest.mark.parametrize(
    ("fence", "message"),
    [
        ({"not": "a list"}, "geoFence.polygons is not a list"),
        ([{"polygon": [[1, 2], [3, 4]]}], "has 2 vertices; give at least 3"),
        ([{"polygon": [[1, 2], [3, 4], "x"]}], "a vertex is not [latitude, longitude]"),
    ],
)
def test_a_bad_fence_section_is_named(fence: object, message: str) -> None:
    plan = json.loads(DEMO_PLAN.read_text())
    plan["geoFence"]["polygons"] = fence
    with pytest.raises(MissionFileError) as raised:
        read_plan_geofence(json.dumps(plan), "m.plan")
    assert str(raised.value).startswith("m.plan: geoFence")
    assert message in str(raised.value)


class FenceScript:
    """A FenceLink that refuses, or reads back what it is told to."""

    url = "scripted://"

    def __init__(self, refuse: bool = False, corrupt: bool = False) -> None:
        self.refuse, self.corrupt = refuse, corrupt
        self.held: list[WireItem] = []

    async def wait_connected(self, timeout_s: float) -> None:
        return None

    async def upload_fence(self, items: Sequence[WireItem]) -> None:
        if self.refuse:
            raise FenceRefused("MAV_MISSION_UNSUPPORTED", "the vehicle keeps no geofence")
        self.held = list(items)

    async def download_fence(self) -> list[WireItem]:
        if self.corrupt:
            return [replace(self.held[0], param1=3.0), *self.held[1:]]
        return self.held


def test_a_verified_fence_and_the_two_failures() -> None:
    fence = Geofence.inclusion(SQUARE)
    report = asyncio.run(upload_fence_verified(FenceScript(), fence, "ardupilot"))
    assert (report.items, report.attempts) == (4, 1)
    with pytest.raises(FenceRefused):
        asyncio.run(upload_fence_verified(FenceScript(refuse=True), fence, "ardupilot"))
    with pytest.raises(LinkError) as raised:
        asyncio.run(upload_fence_verified(FenceScript(corrupt=True), fence, "ardupilot"))
    assert str(raised.value).startswith("geofence not verified on scripted:// after 4 attempts")
    assert "vertex count sent 4, read back 3" in str(raised.value)
