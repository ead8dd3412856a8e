"""TagTracker / UAV-RT ``PulseInfo_t``: the TUNNEL payload codec and its mapping to wire-format
events (no I/O, no frames; the receiver is io.tunnel, which documents the mapping). Layout from
DonLakeFlyer/TagTrackerTunnelProtocol ``TunnelProtocol.h``: a C struct, little-endian, natural
alignment, after a ``uint32 command`` header (docs/receiver-interop.md). The simulator's TUNNEL
radio uses this codec too.
"""

from __future__ import annotations

import math
import struct
from dataclasses import astuple, dataclass

from mexgen_gcs.errors import WireError
from mexgen_gcs.io.wire import RSSI_RANGE_DB, Detection, Heartbeat

TUNNEL_MSG_ID = 385
TAGTRACKER_PAYLOAD_TYPE = 0
COMMAND_ID_PULSE = 7
COMMAND_ID_HEARTBEAT = 9
TUNNEL_PAYLOAD_BYTES = 128
TUNNEL_CLOCK_BUCKET_S = 10.0
"""Clock-fit bucket of a TUNNEL source: longer than a pulse group (K = 5 pulses of 2 s)."""

PULSE_STRUCT = struct.Struct(
    "<I"        # header.command                        @0
    "II4x"      # tag_id, frequency_hz, pad             @4, @8
    "dddd"      # start_time_seconds, predict_next_start_seconds, snr, stft_score  @16..@47
    "HH4x"      # group_seq_counter, group_ind, pad     @48, @50
    "dd"        # group_snr, noise_psd                  @56, @64
    "BB6x"      # detection_status, confirmed_status, pad  @72, @73
    "ddd"       # latitude, longitude, altitude_rel     @80, @88, @96
    "fff4x"     # roll_deg, pitch_deg, yaw_deg, tail pad to 8  @104..@119
)
"""``PulseInfo_t`` with the C compiler's alignment padding written out."""
HEARTBEAT_STRUCT = struct.Struct("<IHHf")
"""``Heartbeat_t``: command, system_id, status, cpu_temp_c."""

SUBTHRESHOLD, SUPERTHRESHOLD, CONFIRMED, NO_PULSE = 0, 1, 2, 3
TUNNEL_REASONS = ("mavlink_bad", "tunnel_short", "tunnel_bad_value", "tunnel_subthreshold")


@dataclass(frozen=True, slots=True)
class PulseInfo:
    """``PulseInfo_t`` field by field (the header's names; times in the companion's clock,
    unix s; ``snr`` dB; ``noise_psd`` linear, the detector's units)."""

    tag_id: int
    frequency_hz: int
    start_time_seconds: float
    predict_next_start_seconds: float
    snr: float
    stft_score: float
    group_seq_counter: int
    group_ind: int
    group_snr: float
    noise_psd: float
    detection_status: int
    confirmed_status: int
    latitude: float = 0.0
    longitude: float = 0.0
    altitude_rel: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0


def pack_pulse(pulse: PulseInfo) -> bytes:
    """The 120-byte ``PulseInfo_t`` payload (command 7)."""
    return PULSE_STRUCT.pack(COMMAND_ID_PULSE, *astuple(pulse))


def unpack_pulse(payload: bytes) -> PulseInfo:
    """A ``PulseInfo_t`` from a TUNNEL payload (command 7). Raises WireError(tunnel_short)."""
    if len(payload) < PULSE_STRUCT.size:
        raise WireError("tunnel_short", f"PulseInfo_t needs {PULSE_STRUCT.size} bytes, got "
                        f"{len(payload)}")
    values = PULSE_STRUCT.unpack_from(payload)
    return PulseInfo(*values[1:])


def pulse_event(pulse: PulseInfo, calibration_db: float = 0.0) -> Detection | Heartbeat:
    """The wire-format event of one pulse report (see the module docstring). Raises
    WireError(tunnel_subthreshold | tunnel_bad_value)."""
    t = pulse.start_time_seconds
    if not (math.isfinite(t) and 0.0 <= t <= 1e11):
        raise WireError("tunnel_bad_value", f"start_time_seconds = {t!r}")
    status = pulse.detection_status
    if pulse.frequency_hz == 0 or status == NO_PULSE:
        return Heartbeat(t, None)
    if status == SUBTHRESHOLD:
        raise WireError("tunnel_subthreshold", f"subthreshold pulse on {pulse.frequency_hz} Hz")
    if status not in (SUPERTHRESHOLD, CONFIRMED):
        raise WireError("tunnel_bad_value", f"detection_status = {status}")
    if not (math.isfinite(pulse.snr) and math.isfinite(pulse.noise_psd)
            and pulse.noise_psd > 0.0):
        raise WireError("tunnel_bad_value", f"snr = {pulse.snr!r}, noise_psd = "
                        f"{pulse.noise_psd!r}")
    rssi_db = 10.0 * math.log10(pulse.noise_psd) + pulse.snr + calibration_db
    if not RSSI_RANGE_DB[0] <= rssi_db <= RSSI_RANGE_DB[1]:
        raise WireError("tunnel_bad_value", f"power {rssi_db:.1f} dB outside "
                        f"[{RSSI_RANGE_DB[0]:g}, {RSSI_RANGE_DB[1]:g}]")
    return Detection(t, None, int(pulse.frequency_hz), rssi_db)
