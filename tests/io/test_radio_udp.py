"""UDP radio receiver against real sockets on 127.0.0.1 (ports picked by the OS)."""

from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import socket
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mexgen_gcs.config import load_mission
from mexgen_gcs.io.radio_udp import RadioPolicy, RadioReceiver, _RateLimitedLog
from mexgen_gcs.io.wire import Detection, Heartbeat, encode_detection, encode_heartbeat

REPO = Path(__file__).resolve().parents[2]
T0 = 1763700002.0  # the fixtures' timestamps are within a few seconds of this
TAGS = (("T1", 150_100_000), ("T2", 150_220_000), ("T3", 150_340_000), ("T4", 150_460_000))
LOCAL = (ipaddress.ip_network("127.0.0.1/32"),)


def fixture_rows(name: str) -> list[dict[str, Any]]:
    folder = REPO / "tests" / "fixtures" / "wire-v1"  # the contract fixtures, in the repository
    rows = []
    for line in (folder / name).read_text(encoding="utf-8").splitlines():
        if line.strip():
            row = json.loads(line)
            row["bytes"] = (bytes.fromhex(row["payload_hex"]) if "payload_hex" in row
                            else row["payload"].encode("utf-8"))
            rows.append(row)
    return rows


def make_policy(**changes: Any) -> RadioPolicy:
    """The policy of the tests of the receiver's checks: receiver clocks are not fitted (the
    mission clock counts as not synced), so times are used as sent; the clock tests below
    switch it on."""
    args: dict[str, Any] = {"tag_freqs_hz": TAGS, "freq_tolerance_hz": 5000.0,
                            "allowed_sources": LOCAL, "max_clock_skew_s": 30.0,
                            "clock": lambda: T0, "clock_synced": lambda: False}
    args.update(changes)
    return RadioPolicy(**args)


@pytest.fixture
def sender() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        yield sock
    finally:
        sock.close()


async def wait_until(predicate: Callable[[], bool], timeout_s: float = 20.0) -> None:
    """Poll until predicate() holds; fail after a generous timeout."""
    async with asyncio.timeout(timeout_s):
        while not predicate():
            await asyncio.sleep(0.005)


async def send_all(rx: RadioReceiver, sock: socket.socket, payloads: list[bytes],
                   chunk: int = 50) -> None:
    """Send in chunks and wait until the receiver has seen each chunk (so the kernel's
    receive buffer never overflows and every datagram is accounted for)."""
    start = rx.stats().datagrams
    for i in range(0, len(payloads), chunk):
        for payload in payloads[i:i + chunk]:
            sock.sendto(payload, ("127.0.0.1", rx.port))
        done = start + min(i + chunk, len(payloads))
        await wait_until(lambda done=done: rx.stats().datagrams >= done)


async def test_binds_a_free_port_and_closes() -> None:
    rx = RadioReceiver("udp://127.0.0.1:0", make_policy())
    with pytest.raises(RuntimeError):
        _ = rx.port
    async with rx:
        assert rx.port > 0 and rx.address.host == "127.0.0.1"
        assert rx.address.url() == f"udp://127.0.0.1:{rx.port}"
    await rx.close()  # idempotent
    with pytest.raises(RuntimeError):
        await rx.open()


async def test_port_in_use_fails_loudly() -> None:
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        other = RadioReceiver(f"udp://127.0.0.1:{rx.port}", make_policy())
        with pytest.raises(OSError):
            await other.open()


async def test_every_valid_fixture_is_accepted(sender: socket.socket) -> None:
    rows = fixture_rows("valid.jsonl")
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, [r["bytes"] for r in rows])
        await wait_until(lambda: rx.queue.qsize() == len(rows))
        events = [rx.queue.get_nowait() for _ in rows]
        stats = rx.stats()
    assert stats.rejects == {}
    assert stats.accepted == len(rows) and stats.heartbeats == 3
    assert stats.accepted_by_tag == {"T1": 1, "T2": 2, "T3": 1}
    assert stats.last_heartbeat_s == T0 and stats.last_detection_s == T0
    by_payload = {e.event: e for e in events}
    assert len(by_payload) == len(rows)
    for event in events:
        assert event.recv_time_s == T0 and event.source[0] == "127.0.0.1"
        assert event.source[1] == sender.getsockname()[1]
        if isinstance(event.event, Detection):
            expected = event.event.tag or {150_220_400: "T2"}[event.event.freq_hz]
            assert event.tag_id == expected
        else:
            assert isinstance(event.event, Heartbeat) and event.tag_id is None


async def test_every_invalid_fixture_is_rejected_under_its_reason(sender: socket.socket) -> None:
    rows = [r for r in fixture_rows("invalid.jsonl") if r["reason"] != "empty"]
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, [r["bytes"] for r in rows])
        sender.sendto(b"", ("127.0.0.1", rx.port))  # a zero-length datagram
        await wait_until(lambda: rx.stats().datagrams == len(rows) + 1)
        stats = rx.stats()
    expected = Counter(r["reason"] for r in rows) + Counter(["empty"])
    assert stats.rejects == dict(expected)
    assert stats.accepted == 0 and rx.queue.empty()


@pytest.mark.parametrize(("payload", "reason"), [
    (encode_detection(T0, -50.0, tag="T9"), "unknown_tag"),
    (encode_detection(T0, -50.0, freq_hz=160_000_000), "unknown_freq"),
    (encode_detection(T0, -50.0, freq_hz=150_105_001), "unknown_freq"),
    (encode_detection(T0, -50.0, tag="T1", freq_hz=150_220_000), "tag_freq_mismatch"),
    (encode_detection(T0, -50.0, tag="T1", freq_hz=150_200_000), "tag_freq_mismatch"),
    (encode_detection(T0 + 31.0, -50.0, tag="T1"), "time_skew"),
    (encode_detection(T0 - 3600.0, -50.0, tag="T1"), "time_skew"),
    (encode_heartbeat(T0 - 31.0), "time_skew"),
])
async def test_semantic_rejects(sender: socket.socket, payload: bytes, reason: str) -> None:
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, [payload])
        assert rx.stats().rejects == {reason: 1}
        assert rx.queue.empty()


async def test_frequency_within_tolerance_maps_to_the_nearest_tag(sender: socket.socket) -> None:
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, [encode_detection(T0, -50.0, freq_hz=150_104_999),
                                    encode_detection(T0, -50.0, tag="T4", freq_hz=150_456_000),
                                    encode_detection(T0 + 29.0, -50.0, tag="T3")])
        tags = [rx.queue.get_nowait().tag_id for _ in range(3)]
    assert tags == ["T1", "T4", "T3"]


async def test_source_not_allowed(sender: socket.socket) -> None:
    policy = make_policy(allowed_sources=(ipaddress.ip_network("10.0.0.0/8"),
                                          ipaddress.ip_network("::1/128")))
    async with RadioReceiver("udp://127.0.0.1:0", policy) as rx:
        await send_all(rx, sender, [encode_detection(T0, -50.0, tag="T1"),
                                    encode_heartbeat(T0), b"garbage"])
        assert rx.stats().rejects == {"source_not_allowed": 3}
    assert policy.source_allowed("10.1.2.3") and policy.source_allowed("::ffff:10.1.2.3")
    assert policy.source_allowed("::1") and not policy.source_allowed("127.0.0.1")
    assert not policy.source_allowed("not an address")
    assert make_policy(allowed_sources=()).source_allowed("192.0.2.1")


async def test_heartbeat_listening_narrowed_to_mission_tags(sender: socket.socket) -> None:
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, [encode_heartbeat(T0, ["T1", "T9", "T3"])])
        event = rx.queue.get_nowait()
    assert event.event == Heartbeat(T0, ("T1", "T3"))


async def test_queue_full_is_counted_and_logged(sender: socket.socket,
                                                caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="mexgen_gcs.io.radio_udp")
    async with RadioReceiver("udp://127.0.0.1:0", make_policy(), queue_size=2) as rx:
        await send_all(rx, sender, [encode_detection(T0, -50.0 - i, tag="T1") for i in range(5)])
        stats = rx.stats()
        assert stats.rejects == {"queue_full": 3} and stats.queue_depth == 2
        assert stats.accepted_by_tag == {"T1": 2}
        assert [rx.queue.get_nowait().event.rssi_db for _ in range(2)] == [-50.0, -51.0]
    assert any("queue full" in r.getMessage() for r in caplog.records)


async def test_rejects_are_logged_at_a_limited_rate(sender: socket.socket,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="mexgen_gcs.io.radio_udp")
    async with RadioReceiver("udp://127.0.0.1:0", make_policy(), log_interval_s=3600.0) as rx:
        await send_all(rx, sender, [b"{nope"] * 40 + [b"[1]"] * 40)
        assert rx.stats().rejects == {"bad_json": 40, "not_object": 40}
    lines = [r.getMessage() for r in caplog.records]
    assert sum("bad_json" in line for line in lines) == 1
    assert sum("not_object" in line for line in lines) == 1


def test_rate_limited_log_reports_suppressed_count(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    logger = logging.getLogger("test.ratelimit")
    caplog.set_level(logging.WARNING, logger="test.ratelimit")
    limited = _RateLimitedLog(5.0, logger, monotonic=lambda: now[0])
    for step in range(12):
        now[0] = step * 1.0
        limited.warning("bad_json", "rejected %s", step)
    assert [r.getMessage() for r in caplog.records] == [
        "rejected 0", "rejected 5 (and 4 more since the last report)",
        "rejected 10 (and 4 more since the last report)"]


async def test_hostile_spray_changes_only_counters(sender: socket.socket) -> None:
    rng = np.random.default_rng(20251121)
    spray: list[bytes] = []
    for i in range(2000):
        kind = i % 10
        if kind == 0:
            spray.append(rng.bytes(int(rng.integers(1, 1400))))
        elif kind == 1:
            spray.append(b"{" * int(rng.integers(1, 60000)))  # huge
        elif kind == 2:
            spray.append(b'{"v": 1, "type": "detection", "t": %f, "tag": "T1", "rssi_db": NaN}'
                         % T0)
        elif kind == 3:
            spray.append(encode_detection(T0, float(rng.uniform(-90, -30)),
                                          tag=f"X{int(rng.integers(0, 999))}"))
        elif kind == 4:
            spray.append(encode_detection(T0, -40.0, freq_hz=int(rng.integers(1, 10**9))
                                          | 1 << 31))
        elif kind == 5:
            spray.append(encode_detection(float(rng.uniform(0, T0 - 100)), -40.0, tag="T2"))
        elif kind == 6:
            spray.append(json.dumps({"v": 1, "type": "heartbeat", "t": T0,
                                     "listening": "T1" * int(rng.integers(1, 50))}).encode())
        elif kind == 7:
            spray.append(b"[" * 700 + b"]" * 699)
        elif kind == 8:
            spray.append(json.dumps({"v": 1, "type": "detection", "t": T0, "tag": "T1",
                                     "rssi_db": 1e308 * 10}).encode())
        else:
            spray.append(b'\xff\xfe' + rng.bytes(20))
    async with RadioReceiver("udp://127.0.0.1:0", make_policy()) as rx:
        await send_all(rx, sender, spray)
        stats = rx.stats()
        assert stats.datagrams == 2000 and stats.rejected == 2000
        assert stats.accepted == 0 and rx.queue.empty()
        assert stats.last_detection_s is None and stats.last_heartbeat_s is None
        assert "internal_error" not in stats.rejects
        # still alive: a good datagram goes through
        await send_all(rx, sender, [encode_detection(T0, -44.5, tag="T2")])
        event = await asyncio.wait_for(rx.get(), timeout=10.0)
    assert event.tag_id == "T2" and event.event.rssi_db == -44.5
    assert rx.stats().accepted_by_tag == {"T2": 1}


def test_handle_datagram_never_raises() -> None:
    class BrokenPolicy:
        def source_allowed(self, host: str) -> bool:
            return True

        def clock(self) -> float:
            return T0

        def resolve(self, event: Any, now_s: float) -> Any:
            raise RuntimeError("a bug")

    rx = RadioReceiver("udp://127.0.0.1:0", BrokenPolicy())  # type: ignore[arg-type]
    rx.handle_datagram(encode_heartbeat(T0), ("127.0.0.1", 1))
    rx.handle_datagram(b"x", None)
    assert rx.rejects == {"internal_error": 1, "bad_json": 1}


def test_policy_from_mission() -> None:
    mission = load_mission(REPO / "missions" / "demo.yaml")
    policy = RadioPolicy.from_mission(mission, clock=lambda: T0)
    assert policy.tag_ids == ("T1", "T2", "T3", "T4")
    assert policy.freq_tolerance_hz == 5000.0 and policy.max_clock_skew_s == 30.0
    assert policy.allowed_sources == (ipaddress.ip_network("127.0.0.1/32"),)
    for f in (150_100_000, 150_104_000, 150_215_000, 150_300_000, 1):
        assert policy.tag_for_frequency(f) == mission.tag_for_frequency(f)


# -- receiver clocks ---------------------------------------------------------------------------

class MissionNow:
    """A settable mission clock for the policy."""

    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


async def _heartbeats_then_pulse(rx: RadioReceiver, sender: socket.socket, now: MissionNow,
                                 offset_s: float, n: int = 30) -> None:
    for i in range(n):
        now.t = T0 + i
        await send_all(rx, sender, [encode_heartbeat(T0 + i + offset_s)])
    now.t = T0 + n
    # a pulse heard half a second ago, stamped by the receiver's clock
    await send_all(rx, sender, [encode_detection(T0 + n - 0.5 + offset_s, -50.0, tag="T2")])


def _drain(rx: RadioReceiver) -> list[Any]:
    return [rx.queue.get_nowait() for _ in range(rx.queue.qsize())]


async def test_a_receiver_ten_minutes_off_is_learnt_and_its_pulses_corrected(
        sender: socket.socket) -> None:
    from mexgen_gcs.io.rxclock import ClockReport
    now = MissionNow(T0)
    policy = make_policy(clock=now, clock_synced=lambda: True, clock_report_every_s=10.0)
    async with RadioReceiver("udp://127.0.0.1:0", policy) as rx:
        await _heartbeats_then_pulse(rx, sender, now, 600.0)
        items = _drain(rx)
        source = ("127.0.0.1", sender.getsockname()[1])
        clock = rx.clock_of(*source)
    assert rx.stats().rejects == {}
    reports = [e.event for e in items if isinstance(e.event, ClockReport)]
    assert [r.kind for r in reports] == ["first", "update", "update"]  # at 0, 10, 20 s
    assert all(abs(r.offset_s - 600.0) < 0.05 for r in reports)
    assert reports[0].source == "127.0.0.1"
    (det,) = [e for e in items if isinstance(e.event, Detection)]
    assert det.tag_id == "T2" and det.t_rx_s == T0 + 30 - 0.5 + 600.0
    assert abs(det.event.t - (T0 + 29.5)) < 0.05
    beats = [e for e in items if isinstance(e.event, Heartbeat)]
    assert len(beats) == 30 and all(abs(b.event.t - b.recv_time_s) < 0.05 for b in beats)
    assert clock is not None and clock.samples == 30


async def test_without_correction_the_offset_is_learnt_but_times_used_as_sent(
        sender: socket.socket) -> None:
    from mexgen_gcs.io.rxclock import ClockReport
    now = MissionNow(T0)
    policy = make_policy(clock=now, clock_synced=lambda: True, clock_correction=False)
    async with RadioReceiver("udp://127.0.0.1:0", policy) as rx:
        await _heartbeats_then_pulse(rx, sender, now, 600.0, n=3)
        items = _drain(rx)
        stats = rx.stats()
    assert stats.rejects == {"time_skew": 4}  # 3 heartbeats, 1 detection
    assert [e.event.kind for e in items if isinstance(e.event, ClockReport)] == ["first"]
    assert abs(items[0].event.offset_s - 600.0) < 0.05


async def test_a_timestamp_beyond_the_offset_guard_is_refused_before_learning(
        sender: socket.socket) -> None:
    now = MissionNow(T0)
    policy = make_policy(clock=now, clock_synced=lambda: True, max_clock_offset_s=3600.0)
    async with RadioReceiver("udp://127.0.0.1:0", policy) as rx:
        await send_all(rx, sender, [encode_heartbeat(T0 + 7200.0),
                                    encode_detection(T0 - 3601.0, -50.0, tag="T1"),
                                    encode_heartbeat(T0 + 3599.0)])
        items = _drain(rx)
        assert rx.stats().rejects == {"clock_offset_limit": 2}
        assert rx.clock_of("127.0.0.1", sender.getsockname()[1]).offset_s == 3599.0
    assert [type(e.event).__name__ for e in items] == ["ClockReport", "Heartbeat"]


async def test_a_jump_of_the_receiver_clock_is_reported(sender: socket.socket,
                                                       caplog: pytest.LogCaptureFixture) -> None:
    from mexgen_gcs.io.rxclock import ClockReport
    caplog.set_level(logging.WARNING, logger="mexgen_gcs.io.radio_udp")
    now = MissionNow(T0)
    policy = make_policy(clock=now, clock_synced=lambda: True, clock_report_every_s=1e9)
    async with RadioReceiver("udp://127.0.0.1:0", policy) as rx:
        for i in range(20):
            now.t = T0 + i
            await send_all(rx, sender, [encode_heartbeat(T0 + i + (0.0 if i < 10 else 45.0))])
        reports = [e.event for e in _drain(rx) if isinstance(e.event, ClockReport)]
    assert [r.kind for r in reports] == ["first", "jump"]
    assert abs(reports[1].offset_s - 45.0) < 0.05
    assert reports[1].previous_offset_s == 0.0
    assert any("jumped" in r.getMessage() for r in caplog.records)
