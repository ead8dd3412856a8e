"""TagTracker / UAV-RT pulses over MAVLink TUNNEL as a receiver source (no frames here: the
pulse's own antenna pose is not used, see below).

The UAV-RT detector and TagTracker's controller (DonLakeFlyer/TagTrackerTunnelProtocol,
``TunnelProtocol.h``) send each detected pulse to the ground as a MAVLink ``TUNNEL`` message
(id 385, ``payload_type`` 0) whose payload is a C struct, little-endian with natural
alignment: a ``uint32 command`` header, then for ``COMMAND_ID_PULSE`` (7) ``PulseInfo_t``
(120 bytes, `PULSE_STRUCT`), and for ``COMMAND_ID_HEARTBEAT`` (9) ``Heartbeat_t`` (12 bytes).

`TunnelReceiver` is a `RadioReceiver` whose datagrams are MAVLink (any number of messages per
datagram, v1 or v2, e.g. forwarded by a MAVLink router from the vehicle's stream). Each
``PulseInfo_t`` becomes an event of the GCS's detection wire format:

- ``detection_status`` 1 (superthreshold) or 2 (confirmed): a `Detection` at
  ``start_time_seconds`` (the companion computer's clock: fitted and corrected like any
  receiver's, io.rxclock), on ``frequency_hz`` (mapped to a mission tag within
  ``receiver.freq_tolerance_hz``; TagTracker's numeric ``tag_id`` is not the mission's id),
  with ``rssi_db = 10 log10(noise_psd) + snr + calibration_db``: TagTracker reports the
  pulse's SNR in dB (the header: ``10 log10((PSD_S+N - PSD_N) / PSD_N)``) and the noise PSD
  in its detector's uncalibrated linear units, so their sum is the pulse's power in dB of
  those units; ``receiver.tunnel_calibration_db`` (measured against a known source) makes it
  the dB the mission's radio model expects. Not calibrated power until that is measured.
- status 3 (searched, no pulse) and ``frequency_hz`` 0 (the detector's heartbeat): a
  `Heartbeat` (listening to every tag), so silent periods count as missed detections.
- status 0 (subthreshold): counted under ``tunnel_subthreshold`` and not used.
- ``Heartbeat_t``: a `Heartbeat` stamped with the mission clock at arrival (it has no time).

Pulse times are fitted for the source's clock from every pulse report: a pulse reaches the GCS
after the detector has integrated its group, so the fit's least-delayed sample per
``TUNNEL_CLOCK_BUCKET_S`` is still the detector's processing time late, and a correct
companion clock is read that much behind (the GCS then poses pulses that much later). Set
``receiver.clock_correction: false`` when the companion computer's clock is known good.

The pose in ``PulseInfo_t`` (latitude, longitude, ``altitude_rel`` above launch, roll, pitch,
yaw) is not used: the wire format's altitude is AMSL, so the GCS poses the pulse from its own
telemetry at the (corrected) pulse time. Everything malformed is counted under its reason and
ignored: ``mavlink_bad`` (bad CRC or framing), ``tunnel_short`` (a payload shorter than its
struct), ``tunnel_bad_value`` (a non-finite time, SNR or a noise PSD <= 0, an unknown status,
a power outside the wire range). Other MAVLink messages, other payload types and other
commands are counted in `TunnelReceiver.ignored`, not as rejects.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.errors import WireError
from mexgen_gcs.io.pulseinfo import (
    COMMAND_ID_HEARTBEAT,
    COMMAND_ID_PULSE,
    HEARTBEAT_STRUCT,
    PULSE_STRUCT,
    TAGTRACKER_PAYLOAD_TYPE,
    TUNNEL_CLOCK_BUCKET_S,
    TUNNEL_PAYLOAD_BYTES,
    TUNNEL_REASONS,
    PulseInfo,
    pack_pulse,
    pulse_event,
    unpack_pulse,
)
from mexgen_gcs.io.radio_udp import RadioReceiver
from mexgen_gcs.io.wire import Detection, Heartbeat

__all__ = ["HEARTBEAT_STRUCT", "PULSE_STRUCT", "TUNNEL_REASONS", "PulseInfo", "TunnelReceiver",
           "pack_pulse", "pulse_event", "unpack_pulse"]


class TunnelReceiver(RadioReceiver):
    """A `RadioReceiver` for MAVLink TUNNEL pulse reports (see the module docstring);
    ``calibration_db`` = ``receiver.tunnel_calibration_db``."""

    clock_bucket_s = TUNNEL_CLOCK_BUCKET_S

    def __init__(self, *args: Any, calibration_db: float = 0.0, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.calibration_db = calibration_db
        self.ignored: Counter[str] = Counter()

    def decode_events(self, data: bytes) -> list[tuple[Detection | Heartbeat | WireError, bool]]:
        """Every MAVLink message of the datagram (a fresh parser each: UDP datagrams are
        whole); a message that is not a usable pulse report is a WireError in the list."""
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        try:
            msgs = parser.parse_buffer(bytes(data)) or []
        except Exception:  # pymavlink raises assorted errors on hostile input
            return [(WireError("mavlink_bad", "not MAVLink"), True)]
        out: list[tuple[Detection | Heartbeat | WireError, bool]] = []
        for msg in msgs:
            try:
                event = self._event(msg)
            except WireError as exc:
                out.append((exc, True))
                continue
            if event is not None:
                out.append(event)
        return out

    def _event(self, msg: Any) -> tuple[Detection | Heartbeat, bool] | None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            raise WireError("mavlink_bad", "bad MAVLink framing or CRC")
        if kind != "TUNNEL":
            self.ignored[kind] += 1
            return None
        if msg.payload_type != TAGTRACKER_PAYLOAD_TYPE:
            self.ignored["tunnel_payload_type"] += 1
            return None
        length = min(int(msg.payload_length), TUNNEL_PAYLOAD_BYTES)
        payload = bytes(msg.payload[:length])
        if len(payload) < 4:
            raise WireError("tunnel_short", f"payload_length {length} < 4")
        command = int.from_bytes(payload[:4], "little")
        if command == COMMAND_ID_PULSE:
            return pulse_event(unpack_pulse(payload), self.calibration_db), True
        if command == COMMAND_ID_HEARTBEAT:
            if len(payload) < HEARTBEAT_STRUCT.size:
                raise WireError("tunnel_short", f"Heartbeat_t needs {HEARTBEAT_STRUCT.size} "
                                f"bytes, got {len(payload)}")
            return Heartbeat(self.policy.clock(), None), False
        self.ignored[f"tunnel_command_{command}"] += 1
        return None

    def feeds_clock(self, event: Detection | Heartbeat) -> bool:
        """Every pulse report is a sample of the companion's clock (there is no other)."""
        return True
