"""MAVSDK 4.x as the drone link: :class:`MavsdkLink`, a `VehicleLink` and a `FenceLink`.

Missions go through ``mission_raw`` (items exactly as given, no home added or removed).
``mavlink_direct`` watches MISSION_ACK and STATUSTEXT during an upload, so a refusal is
reported with the vehicle's own MAV_MISSION_RESULT (MAVSDK folds several into one result) and
ArduPilot's explanation ("Only 700 items are supported"). MAVSDK's log goes to the
``urpt_gcs.mavsdk`` logger instead of the terminal.

On a lossy link (see :data:`UPLOAD_TIMEOUT_S`) MAVSDK's answer timeout is raised for uploads,
and an upload whose every item the vehicle asked for but whose acceptance never came is
reported as :class:`~urpt_gcs.vehicle.protocol.UploadUnconfirmed`, for the read-back to settle.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import functools
import json
import logging
import time
from collections.abc import AsyncIterator, Callable, Coroutine, Sequence
from contextlib import asynccontextmanager
from typing import Any

from mavsdk.asyncio.mavsdk import Configuration, Mavsdk
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.autopilot import Autopilot
from mavsdk.component_type import ComponentType
from mavsdk.exceptions import MavsdkError
from mavsdk.plugins.mission_raw import MissionItem as MavsdkItem
from mavsdk.plugins.mission_raw import MissionPlan, MissionRawError, MissionRawResult
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.errors import LinkError
from urpt_gcs.flight.geofence import FENCE_TYPE
from urpt_gcs.flight.wire import WireItem
from urpt_gcs.vehicle.protocol import (
    DEFAULT_URL,
    URL_EXAMPLES,
    AutopilotKind,
    FenceRefused,
    LinkTimeout,
    MissionRejected,
    UploadUnconfirmed,
)

__all__ = [
    "DOWNLOAD_TIMEOUT_S",
    "FINAL_ACK_WAIT_S",
    "REFUSAL_TEXT_WAIT_S",
    "UPLOAD_TIMEOUT_S",
    "MavsdkLink",
    "connect",
    "connect_systems",
]

# A message heard during a transfer: when (monotonic seconds) and its fields.
_Heard = tuple[float, dict[str, Any]]
# ArduPilot sends its explanation (STATUSTEXT) just after the MISSION_ACK.
REFUSAL_TEXT_WAIT_S = 0.3
# How long MAVSDK waits for each answer in a mission transfer, set through the C library's
# mavsdk_set_timeout_s (Mavsdk::set_timeout_s; the Python binding does not wrap it). MAVSDK
# reads it when a transfer starts, and gives an item up once its sends and timeouts for that
# item add up to five.
#
# Uploads: MAVSDK never resends an item by itself; it answers the vehicle's requests, and
# ArduPilot asks again for a missing item only once a second (MissionItemProtocol::update:
# 1000 ms plus its stream slow-down). At MAVSDK's default 0.5 s every second of waiting spent two
# of the five, so an item lost twice failed the whole attempt: at 20 % loss each way 1 of 20
# demo uploads verified, with 3 retries. At 2 s a timeout fires only when two of the vehicle's
# re-requests in a row are lost, and the five go to real resends: 80 of 80 verified, 2 of them
# on a second attempt (benchmarks/upload_loss.py). 1.5 s did as well in the simulator; 2 s
# leaves room for the slow-down ArduPilot adds on a busy radio. A dead link is noticed after
# 10 s instead of 2.5 s.
UPLOAD_TIMEOUT_S = 2.0
# Downloads: MAVSDK itself asks again for what does not come, so a short wait recovers faster;
# this is MAVSDK's own default (Mavsdk::DEFAULT_TIMEOUT_S, seen as 0.5 s in its log).
DOWNLOAD_TIMEOUT_S = 0.5
# After the vehicle asked for the last item, an ArduPilot that did not get it asks again about
# once a second; when nothing (no MISSION_ACK, no request) comes for this long, its acceptance
# was most likely lost. Rather than wait out MAVSDK's five timeouts (10 s), stop and let the
# read-back tell whether the vehicle holds the mission. Misjudging takes the last item and then
# three re-requests in a row lost (about 0.2 % of uploads at 20 % loss each way; 0.8 % at 2.5 s,
# where it was seen): the vehicle, still waiting, refuses the read-back and the attempt is lost.
FINAL_ACK_WAIT_S = 3.5
# When no MISSION_ACK was seen, the MAV_MISSION_RESULT behind MAVSDK's own result.
_RESULT_ACK = {
    MissionRawResult.TOO_MANY_MISSION_ITEMS: "MAV_MISSION_NO_SPACE",
    MissionRawResult.DENIED: "MAV_MISSION_DENIED",
    MissionRawResult.UNSUPPORTED: "MAV_MISSION_UNSUPPORTED",
    MissionRawResult.INVALID_SEQUENCE: "MAV_MISSION_INVALID_SEQUENCE",
    MissionRawResult.PROTOCOL_ERROR: "MAV_MISSION_ERROR",
    MissionRawResult.TRANSFER_CANCELLED: "MAV_MISSION_OPERATION_CANCELLED",
}
_log = logging.getLogger("urpt_gcs.mavsdk")
# MAVSDK's own log goes to this logger; without a handler configured by the application,
# Python would print its warnings to stderr beside our one-line messages.
_log.addHandler(logging.NullHandler())


@functools.cache
def _route_mavsdk_logs() -> None:
    """Send MAVSDK's log to ours, once per process: subscribing again frees the callback
    the library may be inside on another thread (a crash, seen with a fleet connecting)."""
    from mavsdk.logging import LogLevel, log_subscribe

    levels = {
        LogLevel.DEBUG: logging.DEBUG,
        LogLevel.INFO: logging.INFO,
        LogLevel.WARN: logging.WARNING,
        LogLevel.ERROR: logging.ERROR,
    }

    def forward(level: Any, message: str, _file: str | None, _line: int) -> bool:
        _log.log(levels.get(level, logging.INFO), "%s", message)
        return True  # do not print: the operator sees our one-line messages

    log_subscribe(forward)


class MavsdkLink:
    """A vehicle reached through MAVSDK 4.x (``mission_raw``, ``mavlink_direct``)."""

    def __init__(self, sdk: Mavsdk, system: Any, url: str) -> None:
        self.sdk = sdk
        self.system = system
        self.url = url
        self.mission = MissionRawAsync(system)
        self.direct = MavlinkDirectAsync(system)

    async def autopilot(self) -> AutopilotKind:
        """The autopilot named by the vehicle's HEARTBEAT (as MAVSDK recorded it)."""
        kind = await self.system.autopilot_type()
        if kind == Autopilot.ARDUPILOT:
            return "ardupilot"
        if kind == Autopilot.PX4:
            return "px4"
        return "unknown"

    async def wait_connected(self, timeout_s: float) -> None:
        """Return once MAVSDK hears the vehicle; LinkError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not await self.system.is_connected():
            if time.monotonic() > deadline:
                raise LinkError(f"lost the vehicle on {self.url} for more than {timeout_s:g} s")
            await asyncio.sleep(0.1)

    def set_transfer_timeout(self, seconds: float) -> None:
        """Set MAVSDK's answer timeout for the transfers started from now on."""
        # mavsdk.asyncio.Mavsdk wraps mavsdk.mavsdk.Mavsdk, which holds the C library and the
        # handle (a mavsdk::Mavsdk*). C signature: void mavsdk_set_timeout_s(mavsdk_t, double).
        try:
            native = self.sdk._mavsdk
            setter = native._lib.mavsdk_set_timeout_s
            handle = native._handle
        except AttributeError as exc:
            _log.warning("cannot set MAVSDK's transfer timeout (%s): keeping its default", exc)
            return
        setter.argtypes = [ctypes.c_void_p, ctypes.c_double]
        setter.restype = None
        if handle:
            setter(handle, ctypes.c_double(seconds))

    @asynccontextmanager
    async def _uploading(
        self,
        watched: Sequence[tuple[str, list[_Heard]]],
        *helpers: Coroutine[Any, Any, None],
    ) -> AsyncIterator[None]:
        """Around an upload (mission or fence): collect the messages ``watched`` names, each
        into its list, run ``helpers`` beside it, and give MAVSDK the upload's answer timeout;
        afterwards stop them all and set the download timeout back."""
        watchers = [asyncio.create_task(self._watch(name, into)) for name, into in watched]
        watchers += [asyncio.create_task(helper) for helper in helpers]
        await asyncio.sleep(0)  # let the subscriptions start before the first packet
        self.set_transfer_timeout(UPLOAD_TIMEOUT_S)
        try:
            yield
        finally:
            self.set_transfer_timeout(DOWNLOAD_TIMEOUT_S)
            for watcher in watchers:
                watcher.cancel()
            await asyncio.gather(*watchers, return_exceptions=True)

    async def _watch(self, name: str, into: list[_Heard]) -> None:
        messages = self.direct.subscribe_message(name)
        try:
            async for message in messages:
                into.append((time.monotonic(), json.loads(message.fields_json)))
        finally:
            await messages.aclose()

    async def _stop_when_acceptance_lost(
        self,
        last_seq: int,
        requests: list[_Heard],
        acks: list[_Heard],
        gave_up: asyncio.Event,
    ) -> None:
        """Cancel MAVSDK's wait for a MISSION_ACK the vehicle has most likely sent and lost."""
        while not acks:
            await asyncio.sleep(0.1)
            if not requests:
                continue
            asked_at, request = requests[-1]
            if request.get("seq") == last_seq and time.monotonic() - asked_at > FINAL_ACK_WAIT_S:
                gave_up.set()
                # Nothing to cancel if MAVSDK finished meanwhile: the upload then ends on its own.
                with contextlib.suppress(MissionRawError):
                    await self.mission.cancel_mission_upload()
                return

    async def upload(self, items: Sequence[WireItem], progress: Callable[[float], None]) -> None:
        """Upload with progress; MissionRejected names the vehicle's MISSION_ACK result.

        LinkTimeout when the vehicle stops answering; UploadUnconfirmed when it asked for every
        item but its acceptance did not come.
        """
        acks: list[_Heard] = []
        texts: list[_Heard] = []
        requests: list[_Heard] = []
        gave_up = asyncio.Event()
        watched = [
            ("MISSION_ACK", acks),
            ("STATUSTEXT", texts),
            ("MISSION_REQUEST", requests),
            ("MISSION_REQUEST_INT", requests),
        ]
        stopper = self._stop_when_acceptance_lost(len(items) - 1, requests, acks, gave_up)
        plan = MissionPlan([_to_mavsdk(item) for item in items])
        async with self._uploading(watched, stopper):
            try:
                async for _result, data in self.mission.upload_mission_with_progress(plan):
                    progress(float(data.progress))
            except MissionRawError as exc:
                lost = exc.result == MissionRawResult.TIMEOUT or (
                    exc.result == MissionRawResult.TRANSFER_CANCELLED and gave_up.is_set()
                )
                if lost and any(r.get("seq") == len(items) - 1 for _t, r in requests):
                    raise UploadUnconfirmed(
                        f"the vehicle on {self.url} asked for all {len(items)} items but its "
                        "acceptance did not come"
                    ) from None
                if lost:
                    raise LinkTimeout(f"no answer from the vehicle on {self.url}") from None
                await asyncio.sleep(REFUSAL_TEXT_WAIT_S)
                last = requests[-1][1].get("seq") if requests else None
                raise _rejection(exc.result, acks, texts, last) from None

    async def download(self) -> list[WireItem]:
        """The vehicle's mission, as MISSION_ITEM_INT items."""
        self.set_transfer_timeout(DOWNLOAD_TIMEOUT_S)
        try:
            got = await self.mission.download_mission()
        except MissionRawError as exc:
            if exc.result == MissionRawResult.TIMEOUT:
                raise LinkTimeout(f"no answer to the download on {self.url}") from None
            raise LinkError(
                f"the vehicle did not send its mission back ({exc.result.name})"
            ) from None
        return [_from_mavsdk(item) for item in got]

    async def upload_fence(self, items: Sequence[WireItem]) -> None:
        """Upload a fence mission (``mission_raw.upload_geofence``, items as given).

        FenceRefused when the vehicle answers MAV_MISSION_UNSUPPORTED (it keeps no fences),
        MissionRejected for another refusal, LinkTimeout when it does not answer.
        """
        acks: list[_Heard] = []
        texts: list[_Heard] = []
        async with self._uploading([("MISSION_ACK", acks), ("STATUSTEXT", texts)]):
            try:
                await self.mission.upload_geofence([_to_mavsdk(item) for item in items])
            except MissionRawError as exc:
                if exc.result == MissionRawResult.TIMEOUT:
                    raise LinkTimeout(f"no answer to the geofence upload on {self.url}") from None
                await asyncio.sleep(REFUSAL_TEXT_WAIT_S)
                fence_acks = [(t, a) for t, a in acks if a.get("mission_type") == FENCE_TYPE]
                refusal = _rejection(exc.result, fence_acks, texts, None)
                if refusal.result == "MAV_MISSION_UNSUPPORTED":
                    raise FenceRefused(refusal.result, "the vehicle keeps no geofence") from None
                raise refusal from None

    async def download_fence(self) -> list[WireItem]:
        """The vehicle's fence mission (``mission_raw.download_geofence``)."""
        self.set_transfer_timeout(DOWNLOAD_TIMEOUT_S)
        try:
            got = await self.mission.download_geofence()
        except MissionRawError as exc:
            if exc.result == MissionRawResult.TIMEOUT:
                raise LinkTimeout(f"no answer to the geofence download on {self.url}") from None
            raise LinkError(
                f"the vehicle on {self.url} did not send its geofence back ({exc.result.name})"
            ) from None
        return [_from_mavsdk(item) for item in got]

    async def cancel(self) -> None:
        """Cancel an upload or download MAVSDK may still be running."""
        # Nothing may be running, which MAVSDK reports as an error: that is the wanted state.
        with contextlib.suppress(MissionRawError):
            await self.mission.cancel_mission_upload()
        with contextlib.suppress(MissionRawError):
            await self.mission.cancel_mission_download()


def _to_mavsdk(item: WireItem) -> MavsdkItem:
    return MavsdkItem(
        item.seq, item.frame, item.command, item.current, item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z,
        item.mission_type,
    )  # fmt: skip


def _from_mavsdk(item: MavsdkItem) -> WireItem:
    return WireItem(
        item.seq, item.frame, item.command, item.current, item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z,
        item.mission_type,
    )  # fmt: skip


def _rejection(
    result: MissionRawResult,
    acks: list[_Heard],
    texts: list[_Heard],
    seq: int | None,
) -> MissionRejected:
    refusals = [ack["type"] for _t, ack in acks if ack.get("type") != mavlink.MAV_MISSION_ACCEPTED]
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(refusals[-1]) if refusals else None
    fallback = _RESULT_ACK.get(result, f"MAVSDK {result.name}")
    name = entry.name if entry is not None else fallback
    capacity = None
    detail = ""
    for _t, text in texts:
        words = str(text.get("text", "")).split()
        # ArduPilot: "Only 700 items are supported" comes with a refusal over capacity.
        if words[:1] == ["Only"] and words[2:5] == ["items", "are", "supported"]:
            capacity = int(words[1]) if words[1].isdigit() else None
            detail = " ".join(words)
    if capacity == 0 and name == "MAV_MISSION_NO_SPACE":
        # Its mission storage is not up yet (AP_Mission reports 0 until it is): no capacity.
        return MissionRejected(name, f"{detail} (still starting)", seq=seq, starting=True)
    return MissionRejected(name, detail, capacity, seq)


@asynccontextmanager
async def connect(url: str = DEFAULT_URL, timeout_s: float = 10.0) -> AsyncIterator[MavsdkLink]:
    """Connect to the first autopilot heard on ``url`` (a MAVSDK connection string).

    Raises
    ------
    LinkError
        If the connection cannot be opened or no autopilot is heard within ``timeout_s``.
    """
    _route_mavsdk_logs()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        try:
            await sdk.add_any_connection(url)
        except MavsdkError as exc:
            raise LinkError(f"cannot open {url!r} ({exc}): use e.g. {URL_EXAMPLES}") from None
        system = await sdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise LinkError(
                f"no autopilot heard on {url} within {timeout_s:g} s: check that the vehicle "
                "is powered, the radio or SITL is running, and the connection string"
            )
        link = MavsdkLink(sdk, system, url)
        try:
            yield link
        finally:
            link.mission.destroy()
            link.direct.destroy()


@asynccontextmanager
async def connect_systems(
    url: str, system_ids: Sequence[int], timeout_s: float = 10.0
) -> AsyncIterator[dict[int, MavsdkLink]]:
    """Connect to several autopilots on one link, by their MAVLink system ids.

    One MAVSDK instance hears every system on the connection (``Mavsdk.get_systems``); each
    gets its own plugins, which address it by its id. The links share MAVSDK's transfer
    timeout, so transfers on them should run one at a time.

    Raises
    ------
    LinkError
        If the connection cannot be opened or a system id is not heard within ``timeout_s``.
    """
    _route_mavsdk_logs()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        try:
            await sdk.add_any_connection(url)
        except MavsdkError as exc:
            raise LinkError(f"cannot open {url!r} ({exc}): use e.g. {URL_EXAMPLES}") from None
        wanted = set(system_ids)
        found: dict[int, Any] = {}
        deadline = time.monotonic() + timeout_s
        while True:
            for system in await sdk.get_systems():
                sysid = await system.get_system_id()
                if sysid in wanted and await system.has_autopilot():
                    found.setdefault(sysid, system)
            if len(found) == len(wanted) or time.monotonic() > deadline:
                break
            await asyncio.sleep(0.1)
        missing = sorted(wanted - set(found))
        if missing:
            heard = sorted(found) or "none"
            raise LinkError(
                f"no autopilot with system id {', '.join(map(str, missing))} heard on {url} "
                f"within {timeout_s:g} s (heard: {heard}): check each vehicle's SYSID_THISMAV "
                "and that all of them reach this link"
            )
        links = {
            sysid: MavsdkLink(sdk, found[sysid], f"{url} (system {sysid})") for sysid in system_ids
        }
        try:
            yield links
        finally:
            for link in links.values():
                link.mission.destroy()
                link.direct.destroy()
