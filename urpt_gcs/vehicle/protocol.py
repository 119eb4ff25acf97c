"""What the uploader needs from a connected vehicle, and what a link raises.

:class:`VehicleLink` (missions) and :class:`FenceLink` (geofences) are the protocols the
verified upload of :mod:`urpt_gcs.vehicle.link` is written against; MAVSDK's
:class:`urpt_gcs.vehicle.mavsdk_link.MavsdkLink` is the real one. A refusal by the vehicle is
:class:`MissionRejected` (naming the MISSION_ACK result), a transfer that got no answer
:class:`LinkTimeout`; both are :class:`~urpt_gcs.errors.LinkError`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal, Protocol

from urpt_gcs.errors import LinkError
from urpt_gcs.flight.wire import WireItem

__all__ = [
    "DEFAULT_URL",
    "AutopilotKind",
    "FenceLink",
    "FenceRefused",
    "LinkTimeout",
    "MissionAndFenceLink",
    "MissionRejected",
    "UploadUnconfirmed",
    "VehicleLink",
    "check_url",
]

DEFAULT_URL = "udpin://0.0.0.0:14550"
URL_EXAMPLES = "udpin://0.0.0.0:14550, tcpout://127.0.0.1:5760 or serial:///dev/ttyACM0:57600"
# The connection schemes MAVSDK 4.x opens, and which of them name a network port.
_NETWORK_SCHEMES = ("udpin", "udpout", "tcpin", "tcpout", "udp", "tcp")
_SERIAL_SCHEMES = ("serial", "serial_flowcontrol")
AutopilotKind = Literal["ardupilot", "px4", "unknown"]


def check_url(url: str) -> None:
    """Refuse a connection string MAVSDK cannot open, before any work that ends in it.

    Raises
    ------
    LinkError
        One line naming the string, what is wrong and examples that work.
    """
    scheme, sep, rest = url.partition("://")
    problem = None
    if not sep or scheme not in (*_NETWORK_SCHEMES, *_SERIAL_SCHEMES):
        problem = "an unknown kind of link"
    elif scheme in _NETWORK_SCHEMES:
        _, colon, port = rest.rpartition(":")
        if not colon or not port.isdigit() or not 1 <= int(port) <= 65535:
            problem = "not HOST:PORT with a port from 1 to 65535"
    else:
        device, colon, baud = rest.rpartition(":")
        if not colon:
            device, baud = rest, "1"
        if not device.startswith("/") or not baud.isdigit() or int(baud) < 1:
            problem = "not a device path and a baud rate (/dev/ttyACM0:57600)"
    if problem is not None:
        raise LinkError(f"--connect {url!r} is {problem}: use e.g. {URL_EXAMPLES}")


class MissionRejected(LinkError):
    """The vehicle refused the mission.

    ``result`` is the MAV_MISSION_RESULT name, ``seq`` the item it refused (when known),
    ``capacity`` the most items it holds (when it said so). ``starting`` is True for
    ArduPilot's refusal while it boots ("Only 0 items are supported"), which says nothing of
    its capacity.
    """

    def __init__(
        self,
        result: str,
        detail: str = "",
        capacity: int | None = None,
        seq: int | None = None,
        *,
        starting: bool = False,
    ) -> None:
        super().__init__(f"{result}{': ' + detail if detail else ''}")
        self.result = result
        self.capacity = capacity
        self.seq = seq
        self.starting = starting


class FenceRefused(MissionRejected):
    """The vehicle does not take fences at all (it refused the fence mission outright)."""


class LinkTimeout(LinkError):
    """A transfer got no answer in time (a lossy or dropped link)."""


class UploadUnconfirmed(LinkTimeout):
    """The vehicle asked for every item, but its acceptance (MISSION_ACK) never came.

    Most likely the acceptance was lost on the way: only a read-back can tell whether the
    vehicle holds the mission.
    """


class VehicleLink(Protocol):
    """What the uploader needs from a connected vehicle."""

    url: str

    async def autopilot(self) -> AutopilotKind:
        """The autopilot the vehicle's heartbeat names."""
        ...

    async def wait_connected(self, timeout_s: float) -> None:
        """Return once the vehicle is heard; LinkError after ``timeout_s``."""
        ...

    async def upload(self, items: Sequence[WireItem], progress: Callable[[float], None]) -> None:
        """Send a mission; MissionRejected or LinkTimeout if it does not go through.

        UploadUnconfirmed (a LinkTimeout) when every item was asked for but the vehicle's
        acceptance did not come: the read-back then decides.
        """
        ...

    async def download(self) -> list[WireItem]:
        """Read the vehicle's mission back; LinkTimeout if it does not answer."""
        ...

    async def cancel(self) -> None:
        """Abandon a transfer still running."""
        ...


class FenceLink(Protocol):
    """What the fence upload needs from a connected vehicle."""

    url: str

    async def wait_connected(self, timeout_s: float) -> None:
        """Return once the vehicle is heard; LinkError after ``timeout_s``."""
        ...

    async def upload_fence(self, items: Sequence[WireItem]) -> None:
        """Send a fence mission; FenceRefused if the vehicle takes no fences, MissionRejected
        for another refusal, LinkTimeout if it does not answer."""
        ...

    async def download_fence(self) -> list[WireItem]:
        """Read the vehicle's fence back; LinkTimeout if it does not answer."""
        ...


class MissionAndFenceLink(VehicleLink, FenceLink, Protocol):
    """A vehicle that takes missions and fences."""
