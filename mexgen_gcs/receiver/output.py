"""Pulses and status as detection wire format v1 datagrams (docs/wire-format.md).

A pulse is a ``detection`` with the tag id, the measured carrier and ``rssi_db`` = the
calibrated power in dBm, plus the optional diagnostics ``snr_db``, ``noise_dbm``,
``width_ms``, ``clipped`` and ``interval_s`` (keys the GCS ignores and logs keep). The status
is a ``heartbeat`` listing the tags listened for, plus ``noise_dbm`` and ``heard`` per tag:
a tag listened for with ``heard`` 0 was not heard over a noise floor of ``noise_dbm``. No
pose is sent: the GCS poses each pulse from its own telemetry at ``t``. Every datagram is
checked with the codec before it leaves.
"""

from __future__ import annotations

import json
import math
import socket
from typing import Any

from mexgen_gcs.config.urls import parse_udp_url
from mexgen_gcs.io import wire
from mexgen_gcs.receiver.pipeline import Pulse, Status


def pulse_datagram(p: Pulse) -> bytes:
    rssi = min(max(p.rssi_dbm, wire.RSSI_RANGE_DB[0]), wire.RSSI_RANGE_DB[1])
    obj = json.loads(wire.encode_detection(p.t_unix, rssi, tag=p.tag, freq_hz=p.freq_hz))
    obj.update(snr_db=round(p.snr_db, 2), noise_dbm=_finite(p.noise_dbm),
               width_ms=round(p.width_s * 1e3, 2), clipped=p.clipped)
    if p.interval_s is not None:
        obj["interval_s"] = round(p.interval_s, 6)
    return _checked(obj)


def status_datagram(s: Status) -> bytes:
    obj = json.loads(wire.encode_heartbeat(s.t_unix, list(s.heard)))
    obj["noise_dbm"] = {k: _finite(v) for k, v in s.noise_dbm.items()}
    obj["heard"] = dict(s.heard)
    obj["dropped_samples"] = s.dropped_samples
    obj["clipped_frames"] = s.clipped_frames
    return _checked(obj)


def _finite(x: float) -> float | None:
    return round(x, 2) if math.isfinite(x) else None


def _checked(obj: dict[str, Any]) -> bytes:
    data = json.dumps(obj, separators=(",", ":"), allow_nan=False).encode("utf-8")
    wire.decode(data)  # raises WireError for anything the GCS would refuse
    return data


class UdpSender:
    """Sends datagrams to ``udp://HOST:PORT``."""

    def __init__(self, url: str) -> None:
        addr = parse_udp_url(url)
        self.address = (addr.host, addr.port)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0
        self.errors = 0

    def send(self, data: bytes) -> None:
        try:
            self._sock.sendto(data, self.address)
            self.sent += 1
        except OSError:  # nobody listening yet: a lost datagram, like any UDP
            self.errors += 1

    def close(self) -> None:
        self._sock.close()
