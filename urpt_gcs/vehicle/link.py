"""The drone link: put a mission on the vehicle and prove it holds exactly that mission.

:func:`upload` connects (MAVSDK 4.x, ``mission_raw``), checks the autopilot against the
mission's firmware, uploads, downloads the mission back and compares it item by item
(:mod:`urpt_gcs.vehicle.readback`). A timeout, a lost link or a read-back that differs restarts the
whole upload, up to ``retries`` more times; success is reported only for a verified read-back.
Within one attempt, a read-back that gets no answer is read again, and an upload whose
acceptance never came (:class:`~urpt_gcs.vehicle.protocol.UploadUnconfirmed`) is settled by
the read-back alone.

The uploader is written against :class:`~urpt_gcs.vehicle.protocol.VehicleLink`; the real one
is :class:`urpt_gcs.vehicle.mavsdk_link.MavsdkLink`. Errors are
:class:`~urpt_gcs.errors.LinkError`; a refusal by the vehicle is
:class:`~urpt_gcs.vehicle.protocol.MissionRejected`, which names the MISSION_ACK result
(``MAV_MISSION_NO_SPACE``...).

ArduPilot refuses every upload for a moment after boot with ``MAV_MISSION_NO_SPACE`` and
"Only 0 items are supported" (its mission storage is not up yet): that is read as "still
starting", waited out with a growing pause for up to
:data:`~urpt_gcs.vehicle.transfer.STARTING_WAIT_S`, and not counted as a failed attempt.

A plan's geofence goes up after the mission, as a fence mission read back and compared the
same way (:func:`upload_fence_verified`). A vehicle that refuses fences altogether gets the
mission alone and a warning; a fence it accepted but does not hold as sent is an error.
Mission and fence share one retry loop (:func:`urpt_gcs.vehicle.transfer.until_verified`);
what differs between them (messages, what a refusal means, ArduPilot's start-up wait) is
said by a transfer object each.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.flight.geofence import Geofence, compare_fence, fence_items
from urpt_gcs.flight.mission import (
    Firmware,
    GeoPoint,
    Mission,
    below_home,
    command_name,
    upload_problem,
)
from urpt_gcs.flight.wire import Comparison, WireItem, wire_items
from urpt_gcs.progress import Progress
from urpt_gcs.vehicle.mavsdk_link import connect
from urpt_gcs.vehicle.protocol import (
    DEFAULT_URL,
    AutopilotKind,
    FenceLink,
    FenceRefused,
    LinkTimeout,
    MissionAndFenceLink,
    MissionRejected,
    UploadUnconfirmed,
    VehicleLink,
)
from urpt_gcs.vehicle.readback import compare
from urpt_gcs.vehicle.transfer import Stalled, StartingWait, until_stalled, until_verified

__all__ = [
    "READBACK_S_PER_ITEM",
    "RETRYABLE",
    "FenceReport",
    "UploadReport",
    "UploadSettings",
    "refuse_unfit",
    "upload",
    "upload_async",
    "upload_fence_verified",
    "upload_verified",
    "upload_with_fence",
]

READBACK_S_PER_ITEM = 1.0
_NAMES = {"ardupilot": "ArduPilot", "px4": "PX4", "unknown": "an unknown autopilot"}


@dataclass(frozen=True, slots=True)
class UploadSettings:
    """How hard :func:`upload` tries.

    Attributes
    ----------
    retries
        Whole uploads tried again after the first fails (timeout, refusal while the vehicle
        boots, read-back that differs).
    timeout_s
        Wait this long for the autopilot's heartbeat (also to come back after a drop).
    transfer_timeout_s
        Give an upload up when it has made no progress for this long (a whole upload over a
        lossy link takes longer: ArduPilot asks for a lost item again only once a second), and
        a read-back when it has not ended after this long plus a second per item.
    readback_tries
        Read the mission back this many times before giving the attempt up (downloads only
        read, and MAVSDK gives a download up after five lost requests for one item).
    busy_wait_s
        After MAV_MISSION_NO_SPACE without a capacity message (ArduPilot still starting), wait
        this long times the attempt number before trying again.
    """

    retries: int = 3
    timeout_s: float = 10.0
    transfer_timeout_s: float = 30.0
    busy_wait_s: float = 3.0
    readback_tries: int = 3

    def __post_init__(self) -> None:
        if not 0 <= self.retries <= 100:
            raise SettingsError(f"--retries {self.retries} is out of range; use 0 to 100")
        if not 1 <= self.readback_tries <= 100:
            raise SettingsError(
                f"read-back tries {self.readback_tries} is out of range; use 1 to 100"
            )
        for name, value in (
            ("--timeout", self.timeout_s),
            ("transfer timeout", self.transfer_timeout_s),
            ("busy wait", self.busy_wait_s),
        ):
            if not (math.isfinite(value) and 0.0 <= value <= 3600.0):
                raise SettingsError(f"{name} {value} s is out of range; use 0 to 3600 s")


@dataclass(frozen=True, slots=True)
class UploadReport:
    """A verified upload: the vehicle holds the mission, item for item."""

    url: str
    autopilot: AutopilotKind
    firmware: Firmware
    items: int
    attempts: int
    elapsed_s: float
    vehicle_home: GeoPoint | None
    warnings: tuple[str, ...] = field(default=())
    fence: FenceReport | None = None


@dataclass(frozen=True, slots=True)
class FenceReport:
    """A verified geofence: the vehicle holds the fence, item for item."""

    description: str
    items: int
    attempts: int
    elapsed_s: float


async def upload_verified(
    link: VehicleLink,
    mission: Mission,
    settings: UploadSettings | None = None,
    progress: Progress | None = None,
) -> UploadReport:
    """Upload ``mission`` over ``link`` until a download reads it back equal.

    Parameters
    ----------
    link
        A connected vehicle.
    mission
        The mission; its firmware decides the home item at seq 0.
    settings
        Retries and timeouts; defaults if omitted.
    progress
        Called with a short message as the upload goes on.

    Returns
    -------
    UploadReport
        Only when the vehicle holds the mission.

    Raises
    ------
    SettingsError
        Before anything is sent, if the mission has more items than MAVLink can count or an
        item holds a value no vehicle should be given (:func:`refuse_unfit`).
    LinkError
        If the vehicle refuses the mission (:class:`MissionRejected`), runs another firmware,
        or no attempt ends in a matching read-back.
    """
    settings = settings or UploadSettings()
    say = progress or (lambda _msg: None)
    started = time.monotonic()
    refuse_unfit(mission)
    autopilot = await link.autopilot()
    warnings: list[str] = list(below_home(mission))
    if autopilot == "unknown":
        warnings.append(
            f"the vehicle does not say whether it runs ArduPilot or PX4: uploaded with "
            f"{_NAMES[mission.firmware]}'s conventions, as the mission was planned"
        )
    elif autopilot != mission.firmware:
        raise LinkError(
            f"the mission was planned for {_NAMES[mission.firmware]} but the vehicle on "
            f"{link.url} runs {_NAMES[autopilot]}: plan it again with --firmware {autopilot}"
        )
    transfer = _MissionTransfer(link, wire_items(mission), mission.firmware, settings, say)
    got, check, attempt = await until_verified(transfer, settings.retries, settings.busy_wait_s)
    warnings.extend(check.warnings)
    home = _vehicle_home(got) if mission.firmware == "ardupilot" else None
    warnings.extend(_home_warnings(mission, home))
    return UploadReport(
        url=link.url,
        autopilot=autopilot,
        firmware=mission.firmware,
        items=len(transfer.items),
        attempts=attempt,
        elapsed_s=time.monotonic() - started,
        vehicle_home=home,
        warnings=tuple(warnings),
    )


async def upload_fence_verified(
    link: FenceLink,
    fence: Geofence,
    firmware: Firmware,
    settings: UploadSettings | None = None,
    progress: Progress | None = None,
) -> FenceReport:
    """Upload ``fence`` as a fence mission until a download reads it back equal.

    Parameters
    ----------
    link
        A connected vehicle.
    fence
        The zones; must not be empty.
    firmware
        Whose read-back normalisation to allow for (:func:`urpt_gcs.flight.geofence.compare_fence`).
    settings
        Retries and timeouts; defaults if omitted.
    progress
        Called with a short message as the upload goes on.

    Returns
    -------
    FenceReport
        Only when the vehicle holds the fence.

    Raises
    ------
    FenceRefused
        If the vehicle does not take fences (the mission it holds is unaffected).
    LinkError
        If it refuses this fence, or no attempt ends in a matching read-back.
    """
    settings = settings or UploadSettings()
    say = progress or (lambda _msg: None)
    started = time.monotonic()
    transfer = _FenceTransfer(link, fence, fence_items(fence), firmware, settings, say)
    _got, _check, attempt = await until_verified(transfer, settings.retries, settings.busy_wait_s)
    return FenceReport(fence.describe(), len(transfer.items), attempt, time.monotonic() - started)


class _MissionTransfer:
    """The mission: progress in tenths, read back up to ``readback_tries`` times per attempt;
    ArduPilot's refusals while it boots are waited out and not counted."""

    differs = "read-back differs"
    pause_after_last = False

    def __init__(
        self,
        link: VehicleLink,
        items: Sequence[WireItem],
        firmware: Firmware,
        settings: UploadSettings,
        say: Progress,
    ) -> None:
        self.link = link
        self.items = items
        self.firmware = firmware
        self.settings = settings
        self.say = say
        self._starting = StartingWait(link.url)

    def announce(self, attempt: int, attempts: int, problem: str) -> None:
        if attempt > 1 and not self._starting.waiting:
            self.say(f"retrying ({problem}): attempt {attempt} of {attempts}")
        self._starting.waiting = False

    async def attempt(self) -> list[WireItem]:
        return await _attempt(self.link, self.items, self.settings, self.say)

    async def starting(self, refusal: MissionRejected) -> bool:
        if not refusal.starting:
            return False
        # Not a failed attempt: the vehicle cannot take any mission yet.
        await self._starting.pause(self.say)
        return True

    def refused(self, refusal: MissionRejected) -> None:
        _check_refusal(refusal, self.link.url, self.items)

    def compare(self, got: Sequence[WireItem]) -> Comparison:
        return compare(self.items, got, self.firmware)

    def gave_up(self, attempts: int, problem: str, refusal: MissionRejected | None) -> LinkError:
        url = self.link.url
        if refusal is not None:
            cause = (
                f"it may have no room for {len(self.items)} items, or still be starting "
                "(ArduPilot refuses uploads for a few seconds after boot): wait and try again"
                if refusal.result == "MAV_MISSION_NO_SPACE"
                else "another ground station may be uploading to it: stop that and try again"
            )
            return MissionRejected(
                refusal.result,
                f"the vehicle on {url} refused the mission on all {attempts} attempts: {cause}",
            )
        return LinkError(
            f"mission not verified on {url} after {attempts} attempts: {problem}; the "
            "vehicle may hold a partial mission: do not fly it"
        )


class _FenceTransfer:
    """The geofence: one upload and one read-back per attempt; a vehicle that keeps no fences
    (:class:`FenceRefused`) ends it at once."""

    differs = "fence read-back differs"
    pause_after_last = True

    def __init__(
        self,
        link: FenceLink,
        fence: Geofence,
        items: Sequence[WireItem],
        firmware: Firmware,
        settings: UploadSettings,
        say: Progress,
    ) -> None:
        self.link = link
        self.fence = fence
        self.items = items
        self.firmware = firmware
        self.settings = settings
        self.say = say

    def announce(self, attempt: int, attempts: int, problem: str) -> None:
        self.say(
            f"uploading the geofence ({self.fence.describe()})"
            + (f" ({problem}): attempt {attempt} of {attempts}" if attempt > 1 else "")
        )

    async def attempt(self) -> list[WireItem]:
        await self.link.wait_connected(self.settings.timeout_s)
        await self.link.upload_fence(self.items)
        self.say("reading the geofence back")
        return await self.link.download_fence()

    async def starting(self, refusal: MissionRejected) -> bool:
        return False

    def refused(self, refusal: MissionRejected) -> None:
        if isinstance(refusal, FenceRefused):
            raise refusal
        if refusal.result not in RETRYABLE:
            raise MissionRejected(
                refusal.result,
                f"the vehicle on {self.link.url} refused the geofence "
                f"({self.fence.describe()}): simplify the fence or check the vehicle's FENCE_* "
                "parameters",
            ) from None

    def compare(self, got: Sequence[WireItem]) -> Comparison:
        return compare_fence(self.items, got, self.firmware)

    def gave_up(self, attempts: int, problem: str, refusal: MissionRejected | None) -> LinkError:
        return LinkError(
            f"geofence not verified on {self.link.url} after {attempts} attempts: {problem}; "
            "the vehicle may hold a partial fence: do not fly until it is uploaded"
        )


def refuse_unfit(mission: Mission) -> None:
    """Raise :class:`SettingsError` for a mission that must not reach a vehicle.

    A negative hold, an altitude below any ground, a yaw that is no angle or more than 65 535
    items would be stored wrapped or truncated, or flown as something else, and the read-back
    would still match; so they are refused before any transfer.
    """
    problem = upload_problem(mission)
    if problem is not None:
        raise SettingsError(f"not uploaded: {problem}")


# Refusals that can come from the link or a passing state, not from the mission.
RETRYABLE = frozenset(
    {
        "MAV_MISSION_NO_SPACE",  # ArduPilot still starting (a real capacity limit says so)
        "MAV_MISSION_DENIED",  # another ground station is uploading
        "MAV_MISSION_OPERATION_CANCELLED",  # the vehicle gave up waiting for an item
        "MAV_MISSION_INVALID_SEQUENCE",  # an item arrived twice or late
        # A transfer that lost its state: MAVSDK's protocol error, and PX4's answer to an item
        # that arrives after its transfer timed out or while another is busy (an item PX4
        # cannot take gets a code of its own).
        "MAV_MISSION_ERROR",
    }
)


def _check_refusal(exc: MissionRejected, url: str, items: Sequence[WireItem]) -> None:
    """Raise at once for a refusal that trying again cannot cure."""
    if exc.result == "MAV_MISSION_NO_SPACE" and exc.capacity is not None:
        raise MissionRejected(
            exc.result,
            f"the vehicle on {url} holds at most {exc.capacity} items and the mission has "
            f"{len(items)}: plan fewer targets or split the mission",
            exc.capacity,
        ) from None
    if exc.result in RETRYABLE:
        return
    where = "the mission"
    if exc.seq is not None and 0 <= exc.seq < len(items):
        where = f"mission item seq {exc.seq} ({command_name(items[exc.seq].command)})"
    raise MissionRejected(
        exc.result,
        f"the vehicle on {url} refused {where}: correct it in the plan and upload again",
        seq=exc.seq,
    ) from None


async def _attempt(
    link: VehicleLink, items: Sequence[WireItem], settings: UploadSettings, say: Progress
) -> list[WireItem]:
    shown = [-1]
    heard = [time.monotonic()]

    def on_progress(fraction: float) -> None:
        heard[0] = time.monotonic()
        if not math.isfinite(fraction):
            return  # MAVSDK's final SUCCESS carries no progress
        tenth = int(min(max(fraction, 0.0), 1.0) * 10)
        if tenth > shown[0]:
            shown[0] = tenth
            say(f"uploading {len(items)} items: {tenth * 10}%")

    await link.wait_connected(settings.timeout_s)
    try:
        await until_stalled(link.upload(items, on_progress), heard, settings.transfer_timeout_s)
    except UploadUnconfirmed as exc:
        # Success still needs the read-back below to match item for item.
        say(f"{exc}: reading the mission back to check")
    except Stalled:
        await link.cancel()
        raise LinkTimeout(
            f"the upload made no progress for {settings.transfer_timeout_s:g} s"
        ) from None
    # The link gives a read-back up itself when the vehicle stops answering; this limit only
    # guards against a transfer that never ends. A read-back at 20 % loss takes about 0.3 s
    # per item (MAVSDK asks again after 0.5 s), so a second per item leaves a wide margin.
    limit_s = settings.transfer_timeout_s + READBACK_S_PER_ITEM * len(items)
    problem = ""
    for read in range(1, settings.readback_tries + 1):
        say("reading the mission back" + (f" ({problem}): try {read}" if read > 1 else ""))
        try:
            return await asyncio.wait_for(link.download(), limit_s)
        except asyncio.TimeoutError:
            await link.cancel()
            problem = f"the read-back took over {limit_s:g} s"
        except LinkTimeout as exc:
            problem = str(exc)
    raise LinkTimeout(problem)


def _vehicle_home(got: Sequence[WireItem]) -> GeoPoint | None:
    if not got:
        return None
    home = got[0]
    try:
        return GeoPoint(home.x * 1e-7, home.y * 1e-7, float(home.z))
    except SettingsError:
        return None


def _home_warnings(mission: Mission, home: GeoPoint | None) -> list[str]:
    if home is None or (home.lat_deg == 0.0 and home.lon_deg == 0.0):
        return []
    planned = mission.home
    north = math.radians(home.lat_deg - planned.lat_deg) * 6_371_000.0
    east = (
        math.radians(home.lon_deg - planned.lon_deg)
        * 6_371_000.0
        * math.cos(math.radians(planned.lat_deg))
    )
    distance = math.hypot(north, east)
    if distance <= 10.0:
        return []
    return [
        f"the vehicle's home is {distance:.0f} m from the planned home: altitudes are relative "
        "to the home the vehicle sets when it arms, so arm it at the planned take-off point"
    ]


async def upload_async(
    mission: Mission,
    url: str = DEFAULT_URL,
    settings: UploadSettings | None = None,
    progress: Progress | None = None,
    fence: Geofence | None = None,
) -> UploadReport:
    """:func:`upload` for a caller already inside an event loop."""
    settings = settings or UploadSettings()
    say = progress or (lambda _msg: None)
    refuse_unfit(mission)  # before a connection is even tried
    say(f"waiting for an autopilot on {url}")
    async with connect(url, settings.timeout_s) as link:
        return await upload_with_fence(link, mission, settings, progress, fence)


async def upload_with_fence(
    link: MissionAndFenceLink,
    mission: Mission,
    settings: UploadSettings,
    progress: Progress | None = None,
    fence: Geofence | None = None,
) -> UploadReport:
    """The verified upload of the mission, then of the fence if there is one, on a vehicle
    already connected; a vehicle that keeps no fences gets a warning instead."""
    report = await upload_verified(link, mission, settings, progress)
    if fence is None or fence.empty:
        return report
    try:
        verified = await upload_fence_verified(link, fence, mission.firmware, settings, progress)
    except FenceRefused as exc:
        return replace(
            report,
            warnings=(
                *report.warnings,
                f"the vehicle refused the geofence ({exc.result}): it flies the mission "
                "without the plan's fence; set one on the vehicle if it needs one",
            ),
        )
    return replace(report, fence=verified)


def upload(
    mission: Mission,
    url: str = DEFAULT_URL,
    retries: int = 3,
    timeout_s: float = 10.0,
    progress: Progress | None = None,
    *,
    transfer_timeout_s: float = 30.0,
    busy_wait_s: float = 3.0,
    fence: Geofence | None = None,
) -> UploadReport:
    """Upload a mission and verify the vehicle's read-back; then its geofence, if given.

    Parameters
    ----------
    mission
        The mission to put on the vehicle.
    url
        MAVSDK connection string, e.g. ``udpin://0.0.0.0:14550`` (telemetry radio or
        MAVProxy forwarding), ``tcpout://127.0.0.1:5760`` (ArduPilot SITL),
        ``serial:///dev/ttyACM0:57600``.
    retries
        Whole uploads tried again after the first fails.
    timeout_s
        How long to wait for the autopilot's heartbeat.
    progress
        Called with a short message at each step.
    transfer_timeout_s, busy_wait_s
        See :class:`UploadSettings`.
    fence
        The plan's geofence, uploaded after the mission as a fence mission and read back
        (:func:`upload_fence_verified`); None or empty for none.

    Returns
    -------
    UploadReport
        Only when the read-back matches; ``fence`` says whether the fence is verified, and a
        warning says when the vehicle refused to take a fence at all.

    Raises
    ------
    SettingsError
        Before connecting, for a mission no vehicle should be given (:func:`refuse_unfit`).
    LinkError
        With a one-line reason: no vehicle, wrong firmware, a refusal naming the MISSION_ACK
        result, or no verified read-back (of the mission or the fence) after every retry.
    """
    settings = UploadSettings(retries, timeout_s, transfer_timeout_s, busy_wait_s)
    return asyncio.run(upload_async(mission, url, settings, progress, fence))
