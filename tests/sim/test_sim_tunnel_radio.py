"""The simulator's receiver re-encoded as TagTracker's MAVLink TUNNEL: what the GCS's TUNNEL
reader gets back from each wire-format datagram."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.io.tunnel import COMMAND_ID_PULSE, pulse_event, unpack_pulse
from mexgen_gcs.io.wire import Detection, Heartbeat, encode_detection, encode_heartbeat
from sim.tunnel_radio import TunnelEncoder


def _parse(data: bytes) -> list:  # type: ignore[type-arg]
    parser = mavlink.MAVLink(None)
    return parser.parse_buffer(data) or []


def test_detection_and_heartbeat_round_trip_through_tunnel() -> None:
    enc = TunnelEncoder(sysid=7)
    det = encode_detection(1763700002.25, -71.5, tag="T3", freq_hz=150_340_000, lat=-34.9,
                           lon=138.6, alt_m=50.0, yaw_deg=10.0)
    (msg,) = _parse(enc.encode(det))
    assert msg.get_type() == "TUNNEL" and msg.get_srcSystem() == 7
    assert msg.get_srcComponent() == mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
    assert msg.payload_type == 0 and msg.payload_length == 120
    raw = bytes(msg.payload[:120])
    assert int.from_bytes(raw[:4], "little") == COMMAND_ID_PULSE
    event = pulse_event(unpack_pulse(raw))
    assert isinstance(event, Detection)
    assert event.t == 1763700002.25 and event.freq_hz == 150_340_000
    assert event.rssi_db == pytest.approx(-71.5, abs=1e-9)
    (beat,) = _parse(enc.encode(encode_heartbeat(1763700003.0, ["T1"])))
    assert pulse_event(unpack_pulse(bytes(beat.payload[:120]))) == Heartbeat(1763700003.0)
    assert beat.get_seq() == (msg.get_seq() + 1) % 256
