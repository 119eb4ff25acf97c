"""The mission protocol, vehicle side: upload, download, clear, as ArduPilot runs it.

A pure state machine: :meth:`MissionTransfer.handle` takes a received message and the time,
:meth:`MissionTransfer.tick` the time alone, and both return the messages to send. Timers are
wall-clock seconds (ArduPilot's are milliseconds of its own clock; see ``sitl/README.md``).

What ArduPilot does and this copies (``MissionItemProtocol.cpp``):

* MISSION_COUNT starts an upload: over capacity it answers MAV_MISSION_NO_SPACE (and says
  "Only N items are supported"); otherwise it truncates the stored mission to the new count
  and requests seq 0. Each item is checked and stored as it arrives, so an upload that stops
  half-way leaves a mixed mission behind.
* It asks for the next item with MISSION_REQUEST (PX4: MISSION_REQUEST_INT) and asks again
  if nothing arrives for a second; after 8 s without an item it gives up with
  MAV_MISSION_OPERATION_CANCELLED.
* An item with the wrong seq is answered MAV_MISSION_INVALID_SEQUENCE and the upload goes on;
  an item the vehicle refuses ends the upload with the refusal's MAV_MISSION_RESULT.
* Downloads answer any seq at random; during an upload they are DENIED.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.sim.store import Item, MissionStore

__all__ = [
    "MISSION",
    "REREQUEST_S",
    "UPLOAD_TIMEOUT_S",
    "Message",
    "MissionTransfer",
]

REREQUEST_S = 1.0
UPLOAD_TIMEOUT_S = 8.0
MISSION = mavlink.MAV_MISSION_TYPE_MISSION

Message = Any  # a pymavlink MAVLink_message


@dataclass(slots=True)
class _Upload:
    sysid: int
    compid: int
    next_seq: int
    last_seq: int
    last_receive_s: float
    last_request_s: float


class MissionTransfer:
    """Vehicle side of the MISSION_* protocol over one :class:`MissionStore`.

    Parameters
    ----------
    store
        The mission held by the vehicle.
    mav
        A pymavlink ``MAVLink`` object, used only to build messages.
    ready
        Called with the time; False while the vehicle is still booting, when ArduPilot
        refuses uploads with MAV_MISSION_NO_SPACE.
    on_item
        Called after each mission item is received (for scripted faults).
    """

    def __init__(
        self,
        store: MissionStore,
        mav: mavlink.MAVLink,
        ready: Callable[[float], bool] = lambda _now: True,
        on_item: Callable[[float], None] = lambda _now: None,
    ) -> None:
        self.store = store
        self.mav = mav
        self.ready = ready
        self.on_item = on_item
        self.upload: _Upload | None = None

    # --- helpers ---------------------------------------------------------------------

    def _ack(self, sysid: int, compid: int, result: int) -> Message:
        return self.mav.mission_ack_encode(sysid, compid, result, MISSION)

    def _request(self, upload: _Upload) -> Message:
        if self.store.px4:
            return self.mav.mission_request_int_encode(
                upload.sysid, upload.compid, upload.next_seq, MISSION
            )
        return self.mav.mission_request_encode(
            upload.sysid, upload.compid, upload.next_seq, MISSION
        )

    def _text(self, severity: int, text: str) -> Message:
        return self.mav.statustext_encode(severity, text.encode())

    # --- the protocol ----------------------------------------------------------------

    def handle(self, msg: Message, now: float) -> list[Message]:
        """Answer one received message; messages that are not MISSION_* get nothing."""
        if getattr(msg, "mission_type", MISSION) != MISSION:
            # Fences and rally points are not simulated.
            return [
                self._ack(
                    msg.get_srcSystem(), msg.get_srcComponent(), mavlink.MAV_MISSION_UNSUPPORTED
                )
            ]
        kind = msg.get_type()
        if kind == "MISSION_COUNT":
            return self._count(msg, now)
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._item(msg, now)
        if kind == "MISSION_REQUEST_LIST":
            return self._request_list(msg)
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            return self._send_item(msg, integer=kind == "MISSION_REQUEST_INT")
        if kind == "MISSION_CLEAR_ALL":
            return self._clear(msg)
        return []

    def tick(self, now: float) -> list[Message]:
        """Ask again for an item that has not come, or give the upload up."""
        upload = self.upload
        if upload is None:
            return []
        if now - upload.last_receive_s > UPLOAD_TIMEOUT_S:
            self.upload = None
            return [
                self._text(mavlink.MAV_SEVERITY_WARNING, "Mission upload timeout"),
                self._ack(upload.sysid, upload.compid, mavlink.MAV_MISSION_OPERATION_CANCELLED),
            ]
        if now - upload.last_request_s > REREQUEST_S:
            upload.last_request_s = now
            return [self._request(upload)]
        return []

    def _busy_with_other(self, msg: Message) -> bool:
        upload = self.upload
        return upload is not None and (msg.get_srcSystem(), msg.get_srcComponent()) != (
            upload.sysid,
            upload.compid,
        )

    def _count(self, msg: Message, now: float) -> list[Message]:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if self._busy_with_other(msg):
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_DENIED)]
        self.upload = None
        if msg.count > self.store.capacity:
            return [
                self._ack(sysid, compid, mavlink.MAV_MISSION_NO_SPACE),
                self._text(
                    mavlink.MAV_SEVERITY_WARNING,
                    f"Only {self.store.capacity} items are supported",
                ),
            ]
        if not self.ready(now):
            # ArduPilot's mission storage reports 0 items until it is up.
            return [
                self._ack(sysid, compid, mavlink.MAV_MISSION_NO_SPACE),
                self._text(mavlink.MAV_SEVERITY_WARNING, "Only 0 items are supported"),
            ]
        self.store.truncate(msg.count)
        if msg.count == 0:
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_ACCEPTED)]
        self.upload = _Upload(sysid, compid, 0, msg.count - 1, now, now)
        return [self._request(self.upload)]

    def _item(self, msg: Message, now: float) -> list[Message]:
        upload = self.upload
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if upload is None:
            return []
        if msg.seq != upload.next_seq:
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_INVALID_SEQUENCE)]
        if (sysid, compid) != (upload.sysid, upload.compid):
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_DENIED)]
        item, result = _decode(msg)
        if result == mavlink.MAV_MISSION_ACCEPTED:
            result = self.store.check(item)
        if result != mavlink.MAV_MISSION_ACCEPTED:
            self.upload = None
            return [self._ack(sysid, compid, result)]
        self.store.write(msg.seq, item)
        self.on_item(now)
        upload.last_receive_s = now
        upload.next_seq += 1
        if upload.next_seq > upload.last_seq:
            self.upload = None
            return [
                self._text(mavlink.MAV_SEVERITY_INFO, "Flight plan received"),
                self._ack(sysid, compid, mavlink.MAV_MISSION_ACCEPTED),
            ]
        upload.last_request_s = now
        return [self._request(upload)]

    def _request_list(self, msg: Message) -> list[Message]:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if self.upload is not None:
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_DENIED)]
        return [self.mav.mission_count_encode(sysid, compid, len(self.store), MISSION)]

    def _send_item(self, msg: Message, integer: bool) -> list[Message]:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if self.upload is not None and integer:
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_DENIED)]
        if not 0 <= msg.seq < len(self.store):
            return [
                self.mav.mission_count_encode(sysid, compid, len(self.store), MISSION),
                self._ack(sysid, compid, mavlink.MAV_MISSION_INVALID_SEQUENCE),
            ]
        item = self.store.read(msg.seq)
        if integer:
            return [
                self.mav.mission_item_int_encode(
                    sysid, compid, msg.seq, item.frame, item.command, 0, item.autocontinue,
                    *item.params, item.x, item.y, item.z, MISSION,
                )
            ]  # fmt: skip
        scale = 1e-7 if item.command != mavlink.MAV_CMD_DO_DIGICAM_CONTROL else 1.0
        return [
            self.mav.mission_item_encode(
                sysid, compid, msg.seq, item.frame, item.command, 0, item.autocontinue,
                *item.params, item.x * scale, item.y * scale, item.z, MISSION,
            )
        ]  # fmt: skip

    def _clear(self, msg: Message) -> list[Message]:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if self._busy_with_other(msg):
            return [self._ack(sysid, compid, mavlink.MAV_MISSION_DENIED)]
        self.upload = None
        self.store.clear()
        return [self._ack(sysid, compid, mavlink.MAV_MISSION_ACCEPTED)]


def _decode(msg: Message) -> tuple[Item, int]:
    """An :class:`Item` from MISSION_ITEM_INT or MISSION_ITEM (degrees scaled to 1e7)."""
    x, y = msg.x, msg.y
    if msg.get_type() == "MISSION_ITEM" and msg.command != mavlink.MAV_CMD_DO_DIGICAM_CONTROL:
        if not (math.isfinite(x) and abs(x) <= 90.0):
            return _EMPTY, int(mavlink.MAV_MISSION_INVALID_PARAM5_X)
        if not (math.isfinite(y) and abs(y) <= 180.0):
            return _EMPTY, int(mavlink.MAV_MISSION_INVALID_PARAM6_Y)
        x, y = x * 1e7, y * 1e7
    elif not (math.isfinite(x) and math.isfinite(y)):
        return _EMPTY, int(mavlink.MAV_MISSION_INVALID)
    item = Item(
        msg.command,
        msg.frame,
        msg.param1,
        msg.param2,
        msg.param3,
        msg.param4,
        round(x),
        round(y),
        msg.z,
        msg.autocontinue,
    )
    return item, int(mavlink.MAV_MISSION_ACCEPTED)


_EMPTY = Item(0, 0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0)
