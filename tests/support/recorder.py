"""A ground station's telemetry recorder for tests: a relay that writes a ``.tlog``.

Sits between the ground station and a vehicle (TCP to ArduCopter SITL, UDP to PX4 SITL) and
records every MAVLink frame crossing it, both ways, as QGroundControl and MAVProxy record a
telemetry log: each frame after its arrival time, 8 bytes big-endian in microseconds since
1970. It can also play the pilot who calls the flight off: after the vehicle has reported a
given number of photos, it sends MAV_CMD_NAV_RETURN_TO_LAUNCH as a ground station would.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from support.mavlink_peer import split_frames

# Messages that report a photo taken: ArduPilot's and PX4's.
PHOTO_IDS = (mavlink.MAVLINK_MSG_ID_CAMERA_FEEDBACK, mavlink.MAVLINK_MSG_ID_CAMERA_IMAGE_CAPTURED)
GCS_SYSTEM, GCS_COMPONENT = 255, 190


def _message_id(frame: bytes) -> int:
    if frame[0] == mavlink.PROTOCOL_MARKER_V2:
        return int.from_bytes(frame[7:10], "little")
    return frame[5]


def _system_id(frame: bytes) -> int:
    return frame[5] if frame[0] == mavlink.PROTOCOL_MARKER_V2 else frame[3]


class TlogRecorder:
    """Relay between a ground station and a vehicle that records a ``.tlog``.

    ``tcp``: listens on a loopback TCP port for the ground station (``gcs_url``) and connects
    to the vehicle's TCP port. Otherwise UDP: takes the vehicle's frames on the port it sends
    to, and passes them to the ground station listening on ``gcs_port`` (``udpin``).
    ``rtl_after_photos``: after that many photo reports, command a return to launch.
    """

    def __init__(
        self, vehicle_port: int, tlog: Path, *, tcp: bool, rtl_after_photos: int | None = None
    ) -> None:
        self.tlog = tlog.open("wb")
        self.lock = threading.Lock()
        self.rtl_after = rtl_after_photos
        self.photos = 0
        self.rtl_sent = False
        self.stopping = threading.Event()
        self.vehicle_system = 0
        self.tcp = tcp
        self._vehicle_address: tuple[str, int] | None = None
        self._sequence = 0
        self.threads: list[threading.Thread] = []
        if tcp:
            self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.listener.bind(("127.0.0.1", 0))
            self.listener.listen(1)
            self.gcs_port = self.listener.getsockname()[1]
            self.gcs_url = f"tcpout://127.0.0.1:{self.gcs_port}"
            self.vehicle_port = vehicle_port
            self._start(self._run_tcp)
        else:
            # PX4 sends to a fixed port (``vehicle_port``, its SITL's ``udpin`` URL): stand on
            # it, and answer whoever sends from there.
            self.vehicle_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.vehicle_side.bind(("127.0.0.1", vehicle_port))
            self.vehicle_side.settimeout(0.2)
            self.gcs_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.gcs_side.bind(("127.0.0.1", 0))
            self.gcs_side.settimeout(0.2)
            probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            probe.bind(("127.0.0.1", 0))
            self.gcs_port = probe.getsockname()[1]
            probe.close()
            self.gcs_url = f"udpin://127.0.0.1:{self.gcs_port}"
            self._start(self._udp_from_vehicle)
            self._start(self._udp_from_gcs)

    def _start(self, target: object) -> None:
        thread = threading.Thread(target=target, daemon=True)  # type: ignore[arg-type]
        thread.start()
        self.threads.append(thread)

    def _record(self, frames: list[bytes], from_vehicle: bool) -> None:
        stamp = struct.pack(">Q", int(time.time() * 1e6))
        with self.lock:
            for frame in frames:
                self.tlog.write(stamp + frame)
        if not from_vehicle:
            return
        for frame in frames:
            if not self.vehicle_system and _message_id(frame) == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
                self.vehicle_system = _system_id(frame)
            if _message_id(frame) in PHOTO_IDS:
                self.photos += 1
        if self.rtl_after is not None and not self.rtl_sent and self.photos >= self.rtl_after:
            self.rtl_sent = True
            self._send_rtl()

    def _send_rtl(self) -> None:
        link = mavlink.MAVLink(None, srcSystem=GCS_SYSTEM, srcComponent=GCS_COMPONENT)
        message = link.command_long_encode(
            self.vehicle_system or 1,
            1,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )
        frame = bytes(message.pack(link))
        for _ in range(3):  # as a ground station repeats an unacknowledged command
            self._write_vehicle(frame)
            self._record([frame], from_vehicle=False)
            time.sleep(0.05)

    def _write_vehicle(self, frame: bytes) -> None:
        if self.tcp:
            if self._vehicle_tcp is not None:
                self._vehicle_tcp.sendall(frame)
        elif self._vehicle_address is not None:
            self.vehicle_side.sendto(frame, self._vehicle_address)

    _vehicle_tcp: socket.socket | None = None

    def _run_tcp(self) -> None:
        self.listener.settimeout(0.2)
        while not self.stopping.is_set():
            try:
                gcs, _ = self.listener.accept()
            except TimeoutError:
                continue
            break
        else:
            return
        vehicle = socket.create_connection(("127.0.0.1", self.vehicle_port))
        self._vehicle_tcp = vehicle
        self._start(lambda: self._pump_tcp(gcs, vehicle, from_vehicle=False))
        self._pump_tcp(vehicle, gcs, from_vehicle=True)

    def _pump_tcp(self, source: socket.socket, sink: socket.socket, from_vehicle: bool) -> None:
        source.settimeout(0.2)
        pending = b""
        while not self.stopping.is_set():
            try:
                data = source.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            frames, pending = split_frames(pending + data)
            self._record(frames, from_vehicle)
            try:
                sink.sendall(b"".join(frames))
            except OSError:
                return

    def _udp_from_vehicle(self) -> None:
        while not self.stopping.is_set():
            try:
                data, sender = self.vehicle_side.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            self._vehicle_address = sender
            frames, _ = split_frames(data)
            self._record(frames, from_vehicle=True)
            for frame in frames:
                self.gcs_side.sendto(frame, ("127.0.0.1", self.gcs_port))

    def _udp_from_gcs(self) -> None:
        while not self.stopping.is_set():
            try:
                data, _ = self.gcs_side.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            frames, _ = split_frames(data)
            self._record(frames, from_vehicle=False)
            for frame in frames:
                self._write_vehicle(frame)

    def close(self) -> None:
        """Stop relaying and close the log."""
        self.stopping.set()
        for thread in self.threads:
            thread.join(timeout=2.0)
        for name in ("listener", "vehicle_side", "gcs_side", "_vehicle_tcp"):
            sock = getattr(self, name, None)
            if sock is not None:
                sock.close()
        with self.lock:
            self.tlog.close()
