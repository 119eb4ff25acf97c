"""A real MAVLink peer for tests: an autopilot that only sends HEARTBEAT.

MAVSDK's mission importers need a connected autopilot, because what they produce depends on
its firmware (ArduPilot gets home at seq 0). A heartbeat is all they need: MAVSDK also sends
the peer COMMAND_LONG and PING, which it does not wait on for an import, so they go unanswered.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from types import TracebackType
from typing import Any

from mavsdk.asyncio.mavsdk import Configuration, Mavsdk
from mavsdk.component_type import ComponentType
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

HEARTBEAT_PERIOD_S = 0.5


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


class HeartbeatAutopilot:
    """Send HEARTBEAT as system 1, component 1 to ``127.0.0.1:port`` at 2 Hz until exit."""

    def __init__(self, port: int, autopilot: int) -> None:
        self._port = port
        self._autopilot = autopilot
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="heartbeat-autopilot", daemon=True)

    def __enter__(self) -> HeartbeatAutopilot:
        self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        link = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{self._port}", source_system=1, source_component=1
        )
        try:
            while not self._stop.is_set():
                link.mav.heartbeat_send(
                    mavlink.MAV_TYPE_QUADROTOR,
                    self._autopilot,
                    0,
                    0,
                    mavlink.MAV_STATE_STANDBY,
                )
                # Read what MAVSDK sends so it does not pile up; nothing needs an answer.
                while link.recv_match(blocking=False) is not None:
                    pass
                self._stop.wait(HEARTBEAT_PERIOD_S)
        finally:
            link.close()


@asynccontextmanager
async def mavsdk_autopilot(autopilot: int, timeout_s: float = 5.0) -> AsyncIterator[Any]:
    """A MAVSDK ``System`` connected over loopback UDP to a :class:`HeartbeatAutopilot`.

    ``autopilot`` is the MAV_AUTOPILOT the peer reports (ARDUPILOTMEGA or PX4).
    """
    port = free_udp_port()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        with HeartbeatAutopilot(port, autopilot):
            system = await sdk.first_autopilot(timeout_s=timeout_s)
            if system is None:
                raise AssertionError(f"no heartbeat reached MAVSDK on UDP {port} in {timeout_s} s")
            yield system


def split_frames(buffer: bytes) -> tuple[list[bytes], bytes]:
    """Whole MAVLink 1/2 frames from the start of ``buffer``, and what is left over."""
    frames = []
    start = 0
    while start < len(buffer):
        magic = buffer[start]
        if magic not in (mavlink.PROTOCOL_MARKER_V2, mavlink.PROTOCOL_MARKER_V1):
            start += 1  # not a frame start: skipped, as a receiver would
            continue
        if len(buffer) - start < 3:
            break
        length = buffer[start + 1]
        if magic == mavlink.PROTOCOL_MARKER_V2:
            signed = buffer[start + 2] & mavlink.MAVLINK_IFLAG_SIGNED
            size = 10 + length + 2 + (13 if signed else 0)
        else:
            size = 6 + length + 2
        if len(buffer) - start < size:
            break
        frames.append(buffer[start : start + size])
        start += size
    return frames, buffer[start:]
