"""A UDP tap between MAVSDK and the vehicle that writes the link to a `.tlog`.

MAVSDK owns the MAVLink link and offers no raw byte stream, so the GCS puts a small forwarder
in front of it: the tap takes the vehicle's side of the URL (``udpin://HOST:PORT``: it listens
where the vehicle sends; ``udpout://HOST:PORT``: it talks first to the vehicle), MAVSDK
connects to the tap on loopback the same way round (``udpin://127.0.0.1:P``: the tap sends it
the vehicle's datagrams; ``udpout://127.0.0.1:P``: MAVSDK's heartbeats open the path), and
every datagram is relayed both ways unchanged and written to the tlog. Serial and TCP URLs are
not tapped (MAVSDK connects directly; no tlog).

The tlog format is the one MAVProxy, QGroundControl and Mission Planner write and pymavlink's
``mavutil.mavlink_connection(path)`` reads: each MAVLink message prefixed by a big-endian
uint64 of microseconds since the unix epoch (the host's wall clock at arrival, not the mission
clock). A datagram holding several messages is split at the MAVLink frame boundaries, each with
the datagram's time; bytes that are not a frame are relayed but not logged (counted).

The tap runs in its own thread with blocking sockets, so a busy event loop never delays the
link (MAVSDK's own threads send the setpoints) and the tlog is written off the loop, buffered.
A write error stops the tlog (counted, logged once), never the relay. No frames here.
"""

from __future__ import annotations

import logging
import selectors
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

log = logging.getLogger(__name__)

TLOG_FILE = "vehicle.tlog"
MAX_DATAGRAM = 65_535
FLUSH_EVERY_S = 1.0


def split_frames(data: bytes) -> tuple[list[bytes], int]:
    """MAVLink v1/v2 frames in `data` (by their length fields; CRCs are not checked) and the
    number of bytes that were not part of a frame."""
    frames: list[bytes] = []
    i, junk = 0, 0
    n = len(data)
    while i < n:
        magic = data[i]
        if magic == 0xFD and i + 3 <= n:  # v2: header 10, checksum 2, signature 13 if flagged
            size = 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
        elif magic == 0xFE and i + 2 <= n:  # v1: header 6, checksum 2
            size = 8 + data[i + 1]
        else:
            i += 1
            junk += 1
            continue
        if i + size > n:
            junk += n - i
            break
        frames.append(data[i:i + size])
        i += size
    return frames, junk


@dataclass
class TapStats:
    to_gcs: int = 0
    to_vehicle: int = 0
    messages_logged: int = 0
    bytes_not_frames: int = 0
    write_errors: int = 0
    send_errors: int = 0
    extra: dict[str, int] = field(default_factory=dict)


def _host_port(rest: str, url: str) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"{url}: expected udpin://HOST:PORT or udpout://HOST:PORT")
    return host or "0.0.0.0", int(port)


def tappable(url: str) -> bool:
    """True for the UDP URLs the tap can sit in (udpin://, udpout://, and udp:// = udpin)."""
    return url.startswith(("udpin://", "udpout://", "udp://"))


class MavlinkTap:
    """Relays between a vehicle URL and MAVSDK on loopback, writing `tlog_path`."""

    def __init__(self, vehicle_url: str, tlog_path: Path | None) -> None:
        if not tappable(vehicle_url):
            raise ValueError(f"{vehicle_url}: only udpin:// and udpout:// URLs can be tapped")
        scheme, _, rest = vehicle_url.partition("://")
        self.vehicle_url = vehicle_url
        self.stats = TapStats()
        self._vehicle_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._gcs_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._vehicle_addr: tuple[str, int] | None = None
        if scheme == "udpout":
            self._vehicle_addr = _host_port(rest, vehicle_url)
            self._vehicle_sock.bind(("0.0.0.0", 0))
        else:  # no SO_REUSEADDR: a port another program holds is an error, not a split link
            self._vehicle_sock.bind(_host_port(rest, vehicle_url))
        self._gcs_sock.bind(("127.0.0.1", 0))
        self._mavsdk_addr: tuple[str, int] | None = None
        if scheme == "udpout":  # MAVSDK talks first to the tap's loopback socket
            self.gcs_url = f"udpout://127.0.0.1:{self._gcs_sock.getsockname()[1]}"
        else:  # MAVSDK listens on a free loopback port; the tap sends to it
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.bind(("127.0.0.1", 0))
                port = int(probe.getsockname()[1])
            self._mavsdk_addr = ("127.0.0.1", port)
            self.gcs_url = f"udpin://127.0.0.1:{port}"
        """The URL MAVSDK connects to instead of the vehicle's."""
        self._file: BinaryIO | None = open(tlog_path, "ab") if tlog_path else None  # noqa: SIM115
        self.tlog_path = tlog_path
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink-tap", daemon=True)
        self._thread.start()

    def _log(self, data: bytes) -> None:
        if self._file is None:
            return
        frames, junk = split_frames(data)
        self.stats.bytes_not_frames += junk
        if not frames:
            return
        stamp = struct.pack(">Q", int(time.time() * 1e6))
        try:
            self._file.write(b"".join(stamp + f for f in frames))
            self.stats.messages_logged += len(frames)
        except (OSError, ValueError) as exc:
            self.stats.write_errors += 1
            log.warning("vehicle.tlog: write failed (%s); the tlog stops, the link goes on", exc)
            self._close_file()

    def _close_file(self) -> None:
        f, self._file = self._file, None
        if f is not None:
            try:
                f.close()
            except OSError as exc:
                log.warning("vehicle.tlog: close failed (%s)", exc)

    def _send(self, sock: socket.socket, data: bytes, addr: tuple[str, int]) -> None:
        try:
            sock.sendto(data, addr)
        except OSError:  # nobody listening yet (ICMP), or a full buffer: a lost datagram
            self.stats.send_errors += 1

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._vehicle_sock, selectors.EVENT_READ, "vehicle")
        sel.register(self._gcs_sock, selectors.EVENT_READ, "gcs")
        next_flush = time.monotonic() + FLUSH_EVERY_S
        try:
            while not self._stop.is_set():
                for key, _ in sel.select(timeout=0.2):
                    sock = key.fileobj
                    assert isinstance(sock, socket.socket)
                    try:
                        data, addr = sock.recvfrom(MAX_DATAGRAM)
                    except OSError:
                        continue  # e.g. ICMP port unreachable from a peer not up yet
                    if key.data == "vehicle":
                        self._vehicle_addr = addr
                        if self._mavsdk_addr is None:
                            continue  # MAVSDK has not spoken yet (udpout)
                        self.stats.to_gcs += 1
                        self._send(self._gcs_sock, data, self._mavsdk_addr)
                    else:
                        self._mavsdk_addr = addr
                        if self._vehicle_addr is None:
                            continue  # the vehicle has not spoken yet (udpin)
                        self.stats.to_vehicle += 1
                        self._send(self._vehicle_sock, data, self._vehicle_addr)
                    self._log(data)
                now = time.monotonic()
                if now >= next_flush and self._file is not None:
                    next_flush = now + FLUSH_EVERY_S
                    try:
                        self._file.flush()
                    except OSError as exc:
                        self.stats.write_errors += 1
                        log.warning("vehicle.tlog: flush failed (%s); the tlog stops", exc)
                        self._close_file()
        finally:
            sel.close()

    def close(self) -> None:
        """Stop relaying, close the sockets and the tlog (flushed)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for sock in (self._vehicle_sock, self._gcs_sock):
            sock.close()
        self._close_file()
