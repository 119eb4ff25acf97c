"""The simulated vehicle on a MAVLink connection: the loop, message dispatch, link faults.

Connection strings name the simulator's own end, in MAVSDK's style:

* ``udpout://HOST:PORT`` sends to a ground station listening there (MAVSDK
  ``udpin://0.0.0.0:PORT``), as ArduPilot's SITL sends to 14550;
* ``udpin://HOST:PORT`` listens and answers whoever wrote last (MAVSDK ``udpout://``);
* ``tcpin://HOST:PORT`` accepts one TCP client, as ArduPilot's SITL does on 5760 (MAVSDK
  ``tcpout://HOST:PORT``).
"""

from __future__ import annotations

import random
import re
import select
import threading
import time
from collections import deque
from types import TracebackType
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

import urpt_gcs.sim.telemetry as telemetry
from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.sim.events import Current, Event, Photo, PhotoTaken, Reached, Text
from urpt_gcs.sim.model import FORCE_DISARM, Vehicle
from urpt_gcs.sim.settings import VehicleSettings
from urpt_gcs.sim.transfer import MissionTransfer

__all__ = [
    "COMPONENT_ID",
    "MAX_SUBSTEP_S",
    "TICK_S",
    "FaultyLink",
    "Message",
    "SitlServer",
    "pymavlink_device",
]

Message = Any
TICK_S = 0.01
MAX_SUBSTEP_S = 0.1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1
_URL = re.compile(r"(udpin|udpout|tcpin)://([^:/]*):([0-9]{1,5})")


def pymavlink_device(url: str) -> str:
    """pymavlink's device string for one of the connection strings above."""
    match = _URL.fullmatch(url.strip())
    if match is None:
        raise SettingsError(
            f"--listen {url!r} is not udpout://HOST:PORT, udpin://HOST:PORT or tcpin://HOST:PORT"
        )
    kind, host, port = match.groups()
    if not 0 < int(port) < 65536:
        raise SettingsError(f"--listen {url!r}: port {port} is not 1 to 65535")
    return f"{kind}:{host or '0.0.0.0'}:{port}"


class FaultyLink:
    """A pymavlink connection that loses, delays and, on cue, drops packets."""

    def __init__(self, conn: Any, settings: VehicleSettings) -> None:
        self.conn = conn
        self.loss = settings.loss
        self.latency_s = settings.latency_ms / 1000.0
        self._rng_in = random.Random(settings.seed)
        self._rng_out = random.Random(settings.seed + 1)
        self._inbox: deque[tuple[float, Message]] = deque()
        self._outbox: deque[tuple[float, Message]] = deque()
        self.silent_until = 0.0

    def go_silent(self, now: float, seconds: float) -> None:
        """Drop everything both ways for ``seconds``, packets in flight included."""
        self.silent_until = now + seconds
        self._inbox.clear()
        self._outbox.clear()

    def _lost(self, rng: random.Random, now: float) -> bool:
        return now < self.silent_until or (self.loss > 0.0 and rng.random() < self.loss)

    def receive(self, now: float) -> list[Message]:
        """Messages due for delivery now, after loss and latency."""
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            if msg.get_type() != "BAD_DATA" and not self._lost(self._rng_in, now):
                self._inbox.append((now + self.latency_s, msg))
        out = []
        while self._inbox and self._inbox[0][0] <= now:
            out.append(self._inbox.popleft()[1])
        return out

    def send(self, msg: Message, now: float) -> None:
        """Queue a message, unless the link loses it."""
        if not self._lost(self._rng_out, now):
            self._outbox.append((now + self.latency_s, msg))

    def flush(self, now: float) -> None:
        """Write the queued messages whose latency has passed."""
        while self._outbox and self._outbox[0][0] <= now:
            self.conn.mav.send(self._outbox.popleft()[1])


class SitlServer:
    """A simulated vehicle serving one MAVLink connection.

    Use :meth:`serve` to run in the foreground, or the context manager to run in a thread::

        with SitlServer(VehicleSettings(), "udpout://127.0.0.1:14550") as server:
            ...  # connect a ground station; server.photos() when done

    Parameters
    ----------
    settings
        The vehicle and its link faults.
    listen
        The simulator's end of the connection (see the module docstring).
    """

    def __init__(self, settings: VehicleSettings, listen: str) -> None:
        self.settings = settings
        self.device = pymavlink_device(listen)
        self.listen = listen
        self.vehicle = Vehicle(settings)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._items_received = 0
        self._dropped = False

    # --- running -------------------------------------------------------------------------

    def _open(self) -> Any:
        try:
            conn = mavutil.mavlink_connection(
                self.device,
                source_system=self.settings.system_id,
                source_component=COMPONENT_ID,
                dialect="ardupilotmega",
            )
        except OSError as exc:
            raise LinkError(f"cannot open {self.listen} for the simulator: {exc}") from None
        # Speak MAVLink 2 from the first packet: pymavlink would start in MAVLink 1.
        conn.mav = mavlink.MAVLink(
            conn, srcSystem=self.settings.system_id, srcComponent=COMPONENT_ID
        )
        conn.mav.robust_parsing = True
        conn.WIRE_PROTOCOL_VERSION = "2.0"
        conn.first_byte = False
        return conn

    def serve(self) -> None:
        """Run until :meth:`stop` (or Ctrl-C in the foreground)."""
        conn = self._open()
        try:
            self._loop(conn)
        finally:
            conn.close()

    def _run_thread(self) -> None:
        try:
            self.serve()
        except (LinkError, OSError) as exc:
            self._error = exc
            self._ready.set()

    def start(self) -> SitlServer:
        """Start serving in a background thread; raises if the connection cannot open."""
        self._thread = threading.Thread(target=self._run_thread, name="sitl", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise LinkError(str(self._error))
        return self

    def stop(self) -> None:
        """Stop the loop and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def __enter__(self) -> SitlServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()

    def photos(self) -> list[Photo]:
        """Photos taken so far."""
        with self._lock:
            return list(self.vehicle.photos)

    def sim_time_s(self) -> float:
        """Simulated seconds since start."""
        with self._lock:
            return self.vehicle.time_s

    # --- the loop ------------------------------------------------------------------------

    def _loop(self, conn: Any) -> None:
        link = FaultyLink(conn, self.settings)
        mav: mavlink.MAVLink = conn.mav
        start = time.monotonic()
        self._link, self._mav, self._start = link, mav, start
        self._transfer = MissionTransfer(
            self.vehicle.store,
            mav,
            ready=lambda now: now - start >= self.settings.boot_s,
            on_item=self._on_item,
        )
        self._streams = telemetry.Streams()
        self._ready.set()
        last = start
        while not self._stop.is_set():
            now = time.monotonic()
            with self._lock:
                for msg in link.receive(now):
                    self._dispatch(msg, now)
                for out in self._transfer.tick(now):
                    link.send(out, now)
                self._advance((now - last) * self.settings.speedup)
                self._send_events(now)
                for msg_id in self._streams.due(self.vehicle.time_s):
                    link.send(telemetry.BUILDERS[msg_id](mav, self.vehicle), now)
                link.flush(now)
            last = now
            _wait_readable(conn, TICK_S)

    def _advance(self, dt_s: float) -> None:
        steps = max(1, int(dt_s / MAX_SUBSTEP_S) + 1)
        for _ in range(steps):
            self.vehicle.step(dt_s / steps)

    def _on_item(self, now: float) -> None:
        self._items_received += 1
        after = self.settings.drop_after
        if after is not None and not self._dropped and self._items_received >= after:
            self._dropped = True
            self._link.go_silent(now, self.settings.drop_s)

    def _send_events(self, now: float) -> None:
        events: list[Event] = self.vehicle.events
        self.vehicle.events = []
        for event in events:
            self._link.send(self._event_message(event), now)

    def _event_message(self, event: Event) -> Message:
        mav = self._mav
        if isinstance(event, Text):
            return mav.statustext_encode(event.severity, event.text.encode()[:50])
        if isinstance(event, Current):
            return mav.mission_current_encode(event.seq, max(len(self.vehicle.store) - 1, 0))
        if isinstance(event, Reached):
            return mav.mission_item_reached_encode(event.seq)
        assert isinstance(event, PhotoTaken)
        photo = event.photo
        return mav.camera_feedback_encode(
            int(photo.time_s * 1e6), 0, 0, photo.index, photo.lat_e7, photo.lon_e7,
            photo.alt_amsl_m, photo.alt_rel_m, 0.0, -90.0, photo.heading_deg, 0.0,
            mavlink.CAMERA_FEEDBACK_PHOTO, photo.index,
        )  # fmt: skip

    # --- dispatch ------------------------------------------------------------------------

    def _dispatch(self, msg: Message, now: float) -> None:
        target = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        if target not in (0, self.settings.system_id) or component not in (0, COMPONENT_ID):
            return
        kind = msg.get_type()
        send = self._link.send
        if kind.startswith("MISSION_") and kind not in ("MISSION_SET_CURRENT", "MISSION_ACK"):
            for out in self._transfer.handle(msg, now):
                send(out, now)
        elif kind == "MISSION_SET_CURRENT":
            if self.vehicle.set_current(msg.seq):
                send(telemetry.mission_current(self._mav, self.vehicle), now)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            result = self._command(msg, now)
            send(
                self._mav.command_ack_encode(
                    msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
                ),
                now,
            )
        elif kind == "SET_MODE":
            ok = self.vehicle.set_mode(msg.custom_mode)
            result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED
            send(self._mav.command_ack_encode(mavlink.MAVLINK_MSG_ID_SET_MODE, result), now)
        elif kind.startswith("PARAM_"):
            self._param(msg, now)
        elif kind == "REQUEST_DATA_STREAM":
            self._streams.request_stream(
                msg.req_stream_id, msg.req_message_rate, bool(msg.start_stop), self.vehicle.time_s
            )

    def _param(self, msg: Message, now: float) -> None:
        params = self.vehicle.params
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            values = params.all()
        elif kind == "PARAM_REQUEST_READ":
            name = msg.param_id.rstrip("\0")
            one = params.at(msg.param_index) if msg.param_index >= 0 else params.get(name)
            values = [one] if one is not None else []
        elif kind == "PARAM_SET":
            changed = params.set(msg.param_id.rstrip("\0"), msg.param_value)
            values = [changed] if changed is not None else []
        else:
            values = []
        for value in values:
            self._link.send(
                self._mav.param_value_encode(
                    value.name.encode(), value.value, value.param_type, value.count, value.index
                ),
                now,
            )

    def _command(self, msg: Message, now: float) -> int:
        """Run COMMAND_LONG / COMMAND_INT; the MAV_RESULT for COMMAND_ACK."""
        vehicle = self.vehicle
        command = msg.command
        p = (msg.param1, msg.param2, msg.param3, msg.param4)
        p7 = msg.param7 if msg.get_type() == "COMMAND_LONG" else msg.z
        send = self._link.send
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                return vehicle.arm(now - self._start)
            return vehicle.disarm(force=p[1] == FORCE_DISARM)
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return int(mavlink.MAV_RESULT_UNSUPPORTED)
            return _result(vehicle.set_mode(int(p[1])))
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return vehicle.takeoff(p7)
        if command == mavlink.MAV_CMD_MISSION_START:
            return vehicle.mission_start(p[0], p[1])
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return _result(vehicle.set_mode(mavlink.COPTER_MODE_RTL))
        if command == mavlink.MAV_CMD_NAV_LAND:
            return _result(vehicle.set_mode(mavlink.COPTER_MODE_LAND))
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return _result(self._streams.set_interval(int(p[0]), p[1], vehicle.time_s))
        if command in (
            mavlink.MAV_CMD_REQUEST_MESSAGE,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        ):
            msg_id = (
                int(p[0])
                if command == mavlink.MAV_CMD_REQUEST_MESSAGE
                else mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            )
            builder = telemetry.BUILDERS.get(msg_id)
            if builder is None:
                return int(mavlink.MAV_RESULT_UNSUPPORTED)
            send(builder(self._mav, vehicle), now)
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL:
            if msg.get_type() == "COMMAND_LONG" and msg.param5 == 1.0:
                vehicle.take_photo()
            return int(mavlink.MAV_RESULT_ACCEPTED)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED and p[1] > 0.0:
            vehicle.speed_m_s = p[1]
            return int(mavlink.MAV_RESULT_ACCEPTED)
        return int(mavlink.MAV_RESULT_UNSUPPORTED)


def _wait_readable(conn: Any, timeout_s: float) -> None:
    """Sleep until the connection has data, at most ``timeout_s``."""
    fd = getattr(conn, "fd", None)
    if fd is None:
        time.sleep(timeout_s)
        return
    try:
        select.select([fd], [], [], timeout_s)
    except (OSError, ValueError):
        time.sleep(timeout_s)


def _result(ok: bool) -> int:
    return int(mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED)
