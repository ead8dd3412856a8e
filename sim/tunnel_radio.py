"""The simulated receiver speaking TagTracker's MAVLink TUNNEL instead of wire format v1
(``python -m sim --radio-format mavlink-tunnel``): each datagram the radio would send is
re-encoded as one MAVLink 2 ``TUNNEL`` message (payload_type 0) carrying a ``PulseInfo_t``, as
TagTracker's controller on a companion computer sends it (docs/receiver-interop.md).

A detection becomes a confirmed pulse (``detection_status`` 2) at its ``t`` on its frequency,
with ``noise_psd`` fixed at `NOISE_PSD` and ``snr = rssi_db - 10 log10(NOISE_PSD)``, so that the
GCS's ``10 log10(noise_psd) + snr`` gives the wire format's ``rssi_db`` back (with
``receiver.tunnel_calibration_db: 0``). A heartbeat becomes a no-pulse report (status 3,
``frequency_hz`` 0) at its ``t``. The pose is left at zero (the GCS does not use it). No frames.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.io.pulseinfo import (
    CONFIRMED,
    NO_PULSE,
    TAGTRACKER_PAYLOAD_TYPE,
    TUNNEL_PAYLOAD_BYTES,
    PulseInfo,
    pack_pulse,
)
from mexgen_gcs.io.wire import Detection, decode

NOISE_PSD = 1e-10
"""The noise PSD every simulated report carries (-100 dB of the detector's units)."""
RADIO_FORMATS = ("wire-v1", "mavlink-tunnel")


class TunnelEncoder:
    """Re-encodes wire-format datagrams as TUNNEL messages from ``sysid`` (the vehicle's) and
    the onboard computer's component id, numbering them as one MAVLink link."""

    def __init__(self, sysid: int = 1) -> None:
        self._mav = mavlink.MAVLink(None, srcSystem=sysid,
                                    srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
        self._group = 0

    def encode(self, datagram: bytes) -> bytes:
        event = decode(datagram)
        if isinstance(event, Detection):
            self._group = (self._group + 1) & 0xFFFF
            pulse = PulseInfo(
                tag_id=0, frequency_hz=int(event.freq_hz or 0), start_time_seconds=event.t,
                predict_next_start_seconds=0.0,
                snr=event.rssi_db - 10.0 * math.log10(NOISE_PSD), stft_score=0.0,
                group_seq_counter=self._group, group_ind=0, group_snr=0.0, noise_psd=NOISE_PSD,
                detection_status=CONFIRMED, confirmed_status=1)
        else:
            pulse = PulseInfo(
                tag_id=0, frequency_hz=0, start_time_seconds=event.t,
                predict_next_start_seconds=0.0, snr=0.0, stft_score=0.0, group_seq_counter=0,
                group_ind=0, group_snr=0.0, noise_psd=NOISE_PSD, detection_status=NO_PULSE,
                confirmed_status=0)
        payload = pack_pulse(pulse)
        body = list(payload) + [0] * (TUNNEL_PAYLOAD_BYTES - len(payload))
        msg = self._mav.tunnel_encode(0, 0, TAGTRACKER_PAYLOAD_TYPE, len(payload), body)
        packed = bytes(msg.pack(self._mav))
        self._mav.seq = (self._mav.seq + 1) % 256  # as MAVLink.send would
        return packed
