"""TagTracker / UAV-RT pulses over MAVLink TUNNEL: the PulseInfo_t layout, the mapping to
detections, and real TUNNEL messages packed by pymavlink sent over UDP loopback to the GCS's
TunnelReceiver."""

from __future__ import annotations

import asyncio
import math
import socket
import struct
from collections.abc import Iterator
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.errors import WireError
from mexgen_gcs.io.radio_udp import RadioPolicy
from mexgen_gcs.io.rxclock import ClockReport
from mexgen_gcs.io.tunnel import (
    HEARTBEAT_STRUCT,
    PULSE_STRUCT,
    PulseInfo,
    TunnelReceiver,
    pack_pulse,
    pulse_event,
    unpack_pulse,
)
from mexgen_gcs.io.wire import Detection, Heartbeat

T0 = 1763700002.0
TAGS = (("T1", 150_100_000), ("T2", 150_220_000))

PULSE = PulseInfo(
    tag_id=12, frequency_hz=150_220_300, start_time_seconds=T0 - 2.5,
    predict_next_start_seconds=T0 - 0.5, snr=14.0, stft_score=3.2, group_seq_counter=41,
    group_ind=4, group_snr=11.0, noise_psd=1e-9, detection_status=2, confirmed_status=1,
    latitude=-34.92, longitude=138.60, altitude_rel=50.0, roll_deg=1.0, pitch_deg=-2.0,
    yaw_deg=271.5)


def test_pulse_info_is_120_bytes_with_natural_alignment() -> None:
    assert PULSE_STRUCT.size == 120 and HEARTBEAT_STRUCT.size == 12
    raw = pack_pulse(PULSE)
    assert len(raw) == 120
    # offsets of the C struct (natural alignment): command @0, tag_id @4, frequency_hz @8,
    # start_time_seconds @16, snr @32, group_seq_counter @48, group_ind @50, noise_psd @64,
    # detection_status @72, confirmed_status @73, latitude @80, yaw_deg @112
    assert struct.unpack_from("<III", raw, 0) == (7, 12, 150_220_300)
    assert struct.unpack_from("<d", raw, 16)[0] == T0 - 2.5
    assert struct.unpack_from("<d", raw, 32)[0] == 14.0
    assert struct.unpack_from("<HH", raw, 48) == (41, 4)
    assert struct.unpack_from("<d", raw, 64)[0] == 1e-9
    assert struct.unpack_from("<BB", raw, 72) == (2, 1)
    assert struct.unpack_from("<d", raw, 80)[0] == -34.92
    assert struct.unpack_from("<f", raw, 112)[0] == pytest.approx(271.5)
    assert unpack_pulse(raw) == replace(PULSE, roll_deg=pytest.approx(1.0),
                                        pitch_deg=pytest.approx(-2.0),
                                        yaw_deg=pytest.approx(271.5))
    with pytest.raises(WireError) as err:
        unpack_pulse(raw[:119])
    assert err.value.reason == "tunnel_short"


def test_power_is_noise_psd_in_db_plus_snr_plus_calibration() -> None:
    event = pulse_event(PULSE, calibration_db=-30.0)
    assert isinstance(event, Detection)
    assert event.rssi_db == pytest.approx(10 * math.log10(1e-9) + 14.0 - 30.0)  # -106 dB
    assert event.t == T0 - 2.5 and event.freq_hz == 150_220_300 and event.tag is None
    assert event.lat is None  # TagTracker's altitude is above launch: the GCS poses it


@pytest.mark.parametrize(("changes", "result"), [
    ({"detection_status": 1}, Detection),
    ({"detection_status": 3, "snr": 0.0}, Heartbeat),
    ({"frequency_hz": 0}, Heartbeat),
    ({"detection_status": 0}, "tunnel_subthreshold"),
    ({"detection_status": 9}, "tunnel_bad_value"),
    ({"noise_psd": 0.0}, "tunnel_bad_value"),
    ({"noise_psd": -1.0}, "tunnel_bad_value"),
    ({"snr": math.nan}, "tunnel_bad_value"),
    ({"start_time_seconds": math.inf}, "tunnel_bad_value"),
    ({"start_time_seconds": -1.0}, "tunnel_bad_value"),
    ({"noise_psd": 1e30}, "tunnel_bad_value"),  # 314 dB: outside the wire range
])
def test_status_and_values(changes: dict, result: type | str) -> None:
    pulse = replace(PULSE, **changes)
    if isinstance(result, str):
        with pytest.raises(WireError) as err:
            pulse_event(pulse)
        assert err.value.reason == result
    else:
        assert isinstance(pulse_event(pulse), result)


# -- real TUNNEL messages over UDP loopback -----------------------------------------------------

@pytest.fixture
def sender() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        yield sock
    finally:
        sock.close()


class Companion:
    """TagTracker's side: pymavlink packs TUNNEL messages (MAVLink 2) as the companion
    computer would send them."""

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=1,
                                   srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)

    def tunnel(self, payload: bytes, payload_type: int = 0) -> bytes:
        body = list(payload[:128]) + [0] * (128 - min(len(payload), 128))
        msg = self.mav.tunnel_encode(255, 190, payload_type, min(len(payload), 128), body)
        return bytes(msg.pack(self.mav))

    def pulse(self, pulse: PulseInfo) -> bytes:
        return self.tunnel(pack_pulse(pulse))

    def heartbeat_t(self) -> bytes:
        return self.tunnel(HEARTBEAT_STRUCT.pack(9, 1, 3, 48.5))

    def mavlink_heartbeat(self) -> bytes:
        msg = self.mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                        mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        return bytes(msg.pack(self.mav))


class MissionNow:
    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


async def _wait(predicate, timeout_s: float = 20.0) -> None:  # type: ignore[no-untyped-def]
    async with asyncio.timeout(timeout_s):
        while not predicate():
            await asyncio.sleep(0.005)


async def test_pymavlink_tunnel_messages_become_detections(sender: socket.socket) -> None:
    now = MissionNow(T0)
    policy = RadioPolicy(TAGS, clock=now, clock_synced=lambda: False)
    c = Companion()
    good = [c.pulse(replace(PULSE, start_time_seconds=T0 - i, snr=10.0 + i)) for i in range(5)]
    t1 = c.pulse(replace(PULSE, frequency_hz=150_100_900, start_time_seconds=T0 - 1.0))
    corrupt = bytearray(c.pulse(PULSE))
    corrupt[-3] ^= 0xFF  # a payload byte: the CRC fails
    datagrams = [
        *good,
        t1 + c.mavlink_heartbeat() + c.heartbeat_t(),  # three messages in one datagram
        c.pulse(replace(PULSE, detection_status=3, snr=0.0)),  # searched, nothing heard
        bytes(corrupt),
        c.tunnel(pack_pulse(PULSE)[:100]),  # truncated payload
        c.tunnel(pack_pulse(PULSE), payload_type=0x8003),  # someone else's tunnel
        c.pulse(replace(PULSE, detection_status=0)),  # subthreshold
        c.pulse(replace(PULSE, frequency_hz=160_000_000)),  # no mission tag there
        c.pulse(replace(PULSE, noise_psd=-1.0)),
        b"\x00\x01garbage",
    ]
    async with TunnelReceiver("udp://127.0.0.1:0", policy, calibration_db=-30.0) as rx:
        for d in datagrams:
            sender.sendto(d, ("127.0.0.1", rx.port))
        await _wait(lambda: rx.stats().datagrams == len(datagrams))
        items = [rx.queue.get_nowait() for _ in range(rx.queue.qsize())]
        stats = rx.stats()
    dets = [e for e in items if isinstance(e.event, Detection)]
    assert [e.tag_id for e in dets] == ["T2"] * 5 + ["T1"]
    assert [e.event.rssi_db for e in dets[:5]] == pytest.approx(
        [-90.0 + 10.0 + i - 30.0 for i in range(5)])
    assert [e.event.t for e in dets] == [T0 - i for i in range(5)] + [T0 - 1.0]
    assert stats.accepted_by_tag == {"T2": 5, "T1": 1}
    assert stats.heartbeats == 2  # Heartbeat_t and the no-pulse report
    assert stats.rejects == {"mavlink_bad": 2, "tunnel_short": 1, "tunnel_subthreshold": 1,
                             "unknown_freq": 1, "tunnel_bad_value": 1}
    assert rx.ignored == {"HEARTBEAT": 1, "tunnel_payload_type": 1}


async def test_a_companion_clock_ten_minutes_off_is_learnt_from_its_pulses(
        sender: socket.socket) -> None:
    now = MissionNow(T0)
    policy = RadioPolicy(TAGS, clock=now)
    c = Companion()
    async with TunnelReceiver("udp://127.0.0.1:0", policy) as rx:
        for i in range(40):
            now.t = T0 + i
            # each pulse reaches the GCS 0.3 s after it was heard, on a clock 600 s ahead
            sender.sendto(c.pulse(replace(PULSE, start_time_seconds=T0 + i - 0.3 + 600.0)),
                          ("127.0.0.1", rx.port))
            await _wait(lambda i=i: rx.stats().datagrams == i + 1)
        items = [rx.queue.get_nowait() for _ in range(rx.queue.qsize())]
    reports = [e.event for e in items if isinstance(e.event, ClockReport)]
    assert reports[0].kind == "first" and abs(reports[-1].offset_s - 599.7) < 0.01
    dets = [e for e in items if isinstance(e.event, Detection)]
    assert len(dets) == 40 and rx.stats().rejects == {}
    # read 0.3 s late: the fit cannot tell the detector's latency from the clock's offset
    assert all(abs(e.event.t - (e.recv_time_s)) < 0.01 for e in dets)


def test_the_mission_chooses_the_receiver_and_refuses_an_unknown_format() -> None:
    from pathlib import Path

    from mexgen_gcs.config import load_mission
    from mexgen_gcs.errors import ConfigError
    from mexgen_gcs.io.radio_udp import RadioReceiver
    from mexgen_gcs.mission.run import apply_overrides, make_receiver

    demo = load_mission(Path(__file__).resolve().parents[2] / "missions" / "demo.yaml")
    policy = RadioPolicy.from_mission(demo)
    assert type(make_receiver(demo, "udp://127.0.0.1:0", policy)) is RadioReceiver
    tunnel = apply_overrides(demo, {"receiver.format": "mavlink-tunnel",
                                    "receiver.tunnel_calibration_db": -30.0})
    rx = make_receiver(tunnel, "udp://127.0.0.1:0", RadioPolicy.from_mission(tunnel))
    assert isinstance(rx, TunnelReceiver) and rx.calibration_db == -30.0
    assert policy.clock_correction and policy.max_clock_offset_s == 2_592_000.0
    with pytest.raises(ConfigError, match=r"receiver\.format"):
        apply_overrides(demo, {"receiver.format": "json"})
