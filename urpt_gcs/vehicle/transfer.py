"""The verified-transfer routine: one retry loop for whatever is sent and read back.

A mission and a geofence go to the vehicle the same way: send, read back, compare; a timeout or
a read-back that differs is tried again, a refusal too unless trying again cannot cure it.
:func:`until_verified` is that loop, once; what differs between the two (messages, what a
refusal means, ArduPilot's start-up wait, which only a mission has) is a :class:`Transfer`
(:mod:`urpt_gcs.vehicle.link` has one for each).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Coroutine, Sequence
from typing import Any, Protocol

from urpt_gcs.errors import LinkError
from urpt_gcs.flight.wire import Comparison, WireItem
from urpt_gcs.progress import Progress
from urpt_gcs.vehicle.protocol import LinkTimeout, MissionRejected

__all__ = [
    "STARTING_FIRST_PAUSE_S",
    "STARTING_MAX_PAUSE_S",
    "STARTING_WAIT_S",
    "Stalled",
    "StartingWait",
    "Transfer",
    "until_stalled",
    "until_verified",
]

# A real ArduCopter SITL is ready about 2 s after its first client connects (0.15 s at 10x);
# a board on a slow SD card can take several seconds more.
STARTING_WAIT_S = 30.0
STARTING_FIRST_PAUSE_S = 0.5
STARTING_MAX_PAUSE_S = 4.0


class Transfer(Protocol):
    """One kind of verified transfer (a mission, a fence) as :func:`until_verified` runs it."""

    @property
    def differs(self) -> str:
        """What a read-back that differs is called in the messages."""
        ...

    @property
    def pause_after_last(self) -> bool:
        """Whether a refusal on the last attempt is still followed by the busy wait."""
        ...

    def announce(self, attempt: int, attempts: int, problem: str) -> None:
        """Say that attempt ``attempt`` starts (``problem``: why the one before failed)."""
        ...

    async def attempt(self) -> list[WireItem]:
        """Send the items and read them back; LinkTimeout or MissionRejected if that fails."""
        ...

    async def starting(self, refusal: MissionRejected) -> bool:
        """Wait out a refusal that does not count as an attempt; False if it counts."""
        ...

    def refused(self, refusal: MissionRejected) -> None:
        """Raise at once for a refusal that trying again cannot cure."""
        ...

    def compare(self, got: Sequence[WireItem]) -> Comparison:
        """The read-back against what was sent."""
        ...

    def gave_up(self, attempts: int, problem: str, refusal: MissionRejected | None) -> LinkError:
        """The error once every attempt has failed."""
        ...


async def until_verified(
    transfer: Transfer, retries: int, busy_wait_s: float
) -> tuple[list[WireItem], Comparison, int]:
    """Attempt ``transfer`` until a read-back is equal, up to ``retries`` more times.

    A timeout or a differing read-back is tried again; a refusal too, after ``busy_wait_s``
    times the attempt number, unless the transfer says trying again cannot cure it.

    Returns
    -------
    tuple
        The read-back, its comparison with what was sent, and the attempt that succeeded.

    Raises
    ------
    LinkError
        The transfer's own error once every attempt has failed, or its refusal.
    """
    attempts = retries + 1
    problem = ""
    refusal: MissionRejected | None = None
    attempt = 0
    while attempt < attempts:
        attempt += 1
        transfer.announce(attempt, attempts, problem)
        refusal = None
        try:
            got = await transfer.attempt()
        except LinkTimeout as exc:
            problem = str(exc)
            continue
        except MissionRejected as exc:
            if await transfer.starting(exc):
                attempt -= 1
                continue
            transfer.refused(exc)
            refusal, problem = exc, f"the vehicle refused it with {exc}"
            if attempt < attempts or transfer.pause_after_last:
                await asyncio.sleep(busy_wait_s * attempt)
            continue
        check = transfer.compare(got)
        if check.equal:
            return got, check, attempt
        more = f" (and {len(check.mismatches) - 1} more)" if len(check.mismatches) > 1 else ""
        problem = f"{transfer.differs}: {check.mismatches[0]}{more}"
    raise transfer.gave_up(attempts, problem, refusal)


class StartingWait:
    """Waits out ArduPilot's start-up refusals with a growing pause, up to STARTING_WAIT_S."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.waiting = False
        self._since: float | None = None
        self._pause_s = STARTING_FIRST_PAUSE_S

    async def pause(self, say: Progress) -> None:
        now = time.monotonic()
        if self._since is None:
            self._since = now
        if now - self._since > STARTING_WAIT_S:
            raise MissionRejected(
                "MAV_MISSION_NO_SPACE",
                f"the vehicle on {self.url} is still starting after {STARTING_WAIT_S:g} s (it "
                "says 'Only 0 items are supported' until its mission storage is up): wait for "
                "'ArduPilot Ready' and upload again",
                starting=True,
            )
        self.waiting = True
        say(f"the vehicle is still starting: trying again in {self._pause_s:g} s")
        await asyncio.sleep(self._pause_s)
        self._pause_s = min(self._pause_s * 2.0, STARTING_MAX_PAUSE_S)


class Stalled(Exception):
    """A transfer made no progress for too long."""


async def until_stalled(
    transfer: Coroutine[Any, Any, None], heard: list[float], stall_s: float
) -> None:
    """Run ``transfer``, cancelled with Stalled once ``heard[0]`` (its last progress) is
    ``stall_s`` old."""
    task = asyncio.ensure_future(transfer)
    try:
        while True:
            left = heard[0] + stall_s - time.monotonic()
            if left <= 0.0:
                raise Stalled
            done, _pending = await asyncio.wait({task}, timeout=left)
            if done:
                task.result()
                return
    finally:
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
