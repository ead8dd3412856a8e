"""UDP radio receiver: wire format v1 datagrams in, validated radio events out (no frames here;
poses stay as the receiver sent them, WGS84 degrees and a compass yaw).

`RadioReceiver` binds a UDP socket (asyncio datagram endpoint), decodes each datagram with
`wire.decode`, applies the mission's `RadioPolicy` (allowed source networks, known tags,
frequency -> tag within tolerance, clock skew) and puts accepted events on a bounded queue.

Receiver clocks: every sending host (its IP address: a clock belongs to the computer, whatever
port a program sends from) has a `ReceiverClock` (io.rxclock) learnt from its heartbeats'
timestamps and their arrival on the mission clock. Once it has one, the host's
timestamps are mapped to mission time before anything else looks at them (with
``clock_correction``; without, they are estimated and logged but used as sent), so a receiver
whose clock is minutes off or drifting still has its pulses posed at the right moment. The
guard ``max_clock_offset_s`` refuses (``clock_offset_limit``) a timestamp further than that
from now before any correction: a value no companion computer's clock could be off by is
garbage, not a clock to learn. ``max_clock_skew_s`` then applies to the corrected time (a
source without an estimate yet: to the time as sent). The estimates go on the queue as
`ClockReport` events: the first of each source, a jump, and one every
``clock_report_every_s`` mission seconds.
Nothing a sender does can raise out of it: every rejected datagram is counted under its
reason and logged at most once per reason per `log_interval_s`. When the queue is full the
event is counted under `queue_full` and logged, never dropped silently.
"""

from __future__ import annotations

import asyncio
import dataclasses
import ipaddress
import logging
import math
import socket
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

from mexgen_gcs.config.urls import UdpAddress, parse_udp_url
from mexgen_gcs.errors import WireError
from mexgen_gcs.io.rxclock import BUCKET_S, ClockReport, ReceiverClock
from mexgen_gcs.io.wire import Detection, Heartbeat, decode

if TYPE_CHECKING:
    from mexgen_gcs.config.mission import Mission

__all__ = [
    "RECEIVE_QUEUE_SIZE",
    "ClockReport",
    "RadioEvent",
    "RadioPolicy",
    "RadioReceiver",
    "ReceiverStats",
    "UdpAddress",
    "parse_udp_url",
]

log = logging.getLogger(__name__)

RECEIVE_QUEUE_SIZE = 4096
SOCKET_BUFFER_BYTES = 1 << 20

Network = ipaddress.IPv4Network | ipaddress.IPv6Network

#: Reasons the policy adds to the wire reasons.
POLICY_REASONS = ("source_not_allowed", "clock_offset_limit", "time_skew", "unknown_tag",
                  "unknown_freq", "tag_freq_mismatch")
MAX_CLOCK_SOURCES = 64
"""Receiver clocks kept; the least recently heard host is forgotten beyond this."""


def _always() -> bool:
    return True


class RadioEvent(NamedTuple):
    """An accepted datagram: receive time (policy clock, unix s), sender (host, port), the
    mission tag it maps to (None for a heartbeat or a clock report) and the event, its ``t``
    on the mission clock (corrected for the receiver's clock when there is an estimate);
    ``t_rx_s`` = the ``t`` the receiver sent (None for a clock report)."""

    recv_time_s: float
    source: tuple[str, int]
    tag_id: str | None
    event: Detection | Heartbeat | ClockReport
    t_rx_s: float | None = None


@dataclass(frozen=True, slots=True)
class RadioPolicy:
    """What the mission at hand accepts. Empty `allowed_sources` = any source."""

    tag_freqs_hz: tuple[tuple[str, int], ...]
    """(tag id, frequency Hz) of every mission tag."""
    freq_tolerance_hz: float = 5000.0
    allowed_sources: tuple[Network, ...] = ()
    max_clock_skew_s: float = 30.0
    clock: Callable[[], float] = time.time
    """Unix time now; the receive time of events and the reference for clock skew."""
    max_clock_offset_s: float = 2_592_000.0
    """Timestamps further than this from now (before correction) are refused outright."""
    clock_correction: bool = True
    """Map each source's timestamps to mission time with its learnt clock."""
    clock_synced: Callable[[], bool] = _always
    """False while `clock` is not yet the mission clock (it is learning the vehicle's):
    receiver clocks are not fitted against it then."""
    clock_report_every_s: float = 10.0

    @classmethod
    def from_mission(cls, mission: Mission, clock: Callable[[], float] = time.time,
                     clock_synced: Callable[[], bool] = _always) -> RadioPolicy:
        r = mission.receiver
        return cls(
            tag_freqs_hz=tuple((t.id, t.freq_hz) for t in mission.tags),
            freq_tolerance_hz=r.freq_tolerance_hz,
            allowed_sources=r.networks(),
            max_clock_skew_s=r.max_clock_skew_s,
            clock=clock,
            max_clock_offset_s=r.max_clock_offset_s,
            clock_correction=r.clock_correction,
            clock_synced=clock_synced,
        )

    @property
    def tag_ids(self) -> tuple[str, ...]:
        return tuple(tag for tag, _ in self.tag_freqs_hz)

    def source_allowed(self, host: str) -> bool:
        if not self.allowed_sources:
            return True
        try:
            ip = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return any(ip in net for net in self.allowed_sources)

    def tag_for_frequency(self, freq_hz: int) -> str | None:
        """The nearest tag within the tolerance, or None."""
        best: tuple[float, str] | None = None
        for tag, f in self.tag_freqs_hz:
            off = abs(f - freq_hz)
            if off <= self.freq_tolerance_hz and (best is None or off < best[0]):
                best = (off, tag)
        return None if best is None else best[1]

    def resolve(self, event: Detection | Heartbeat, now_s: float
                ) -> tuple[str | None, Detection | Heartbeat]:
        """(mission tag id, event) for an acceptable event; WireError(reason) otherwise.
        A heartbeat's `listening` is narrowed to the mission's tags."""
        if abs(event.t - now_s) > self.max_clock_skew_s:
            raise WireError("time_skew", f"t is {event.t - now_s:+.1f} s from now, more than "
                            f"{self.max_clock_skew_s:g} s")
        if isinstance(event, Heartbeat):
            if event.listening is None:
                return None, event
            known = tuple(tag for tag in event.listening if tag in self.tag_ids)
            return None, event if known == event.listening else Heartbeat(event.t, known)
        by_freq = self.tag_for_frequency(event.freq_hz) if event.freq_hz is not None else None
        if event.tag is not None:
            if event.tag not in self.tag_ids:
                raise WireError("unknown_tag", f"tag {event.tag!r} is not in the mission")
            if event.freq_hz is not None and by_freq != event.tag:
                raise WireError("tag_freq_mismatch", f"{event.freq_hz} Hz is not tag "
                                f"{event.tag}'s frequency within {self.freq_tolerance_hz:g} Hz")
            return event.tag, event
        if by_freq is None:
            raise WireError("unknown_freq", f"{event.freq_hz} Hz is within "
                            f"{self.freq_tolerance_hz:g} Hz of no mission tag")
        return by_freq, event


@dataclass(frozen=True, slots=True)
class ReceiverStats:
    """A snapshot of the receiver's counters. Times are receive times, unix s."""

    datagrams: int
    accepted: int
    accepted_by_tag: dict[str, int]
    heartbeats: int
    rejects: dict[str, int]
    queue_depth: int
    last_heartbeat_s: float | None
    last_detection_s: float | None
    socket_errors: int

    @property
    def rejected(self) -> int:
        return sum(self.rejects.values())


@dataclass
class _RateLimitedLog:
    """At most one line per key per interval; says how many were suppressed."""

    interval_s: float
    logger: logging.Logger
    monotonic: Callable[[], float] = time.monotonic
    _last: dict[str, float] = field(default_factory=dict)
    _suppressed: Counter[str] = field(default_factory=Counter)

    def warning(self, key: str, message: str, *args: Any) -> None:
        now = self.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.interval_s:
            self._suppressed[key] += 1
            return
        self._last[key] = now
        more = self._suppressed.pop(key, 0)
        suffix = f" (and {more} more since the last report)" if more else ""
        self.logger.warning(message + suffix, *args)


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, receiver: RadioReceiver) -> None:
        self._receiver = receiver

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self._receiver.handle_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:
        self._receiver.note_socket_error(exc)


class RadioReceiver:
    """Receives wire-format datagrams on `listen` (udp://HOST:PORT; port 0 = any free port).

    Use as ``async with RadioReceiver(url, policy) as rx: event = await rx.get()``.
    """

    clock_bucket_s = BUCKET_S
    """Receiver-clock fit bucket (io.rxclock): one heartbeat a second, 2 s."""

    def __init__(
        self,
        listen: str | UdpAddress,
        policy: RadioPolicy,
        *,
        queue_size: int = RECEIVE_QUEUE_SIZE,
        log_interval_s: float = 5.0,
        logger: logging.Logger = log,
    ) -> None:
        self.listen = parse_udp_url(listen) if isinstance(listen, str) else listen
        self.policy = policy
        self.queue: asyncio.Queue[RadioEvent] = asyncio.Queue(maxsize=queue_size)
        self.rejects: Counter[str] = Counter()
        self._log = _RateLimitedLog(log_interval_s, logger)
        self._transport: asyncio.DatagramTransport | None = None
        self._bound: UdpAddress | None = None
        self._closed = False
        self._datagrams = 0
        self._accepted_by_tag: Counter[str] = Counter()
        self._heartbeats = 0
        self._last_heartbeat_s: float | None = None
        self._last_detection_s: float | None = None
        self._socket_errors = 0
        self._clocks: dict[str, ReceiverClock] = {}
        self._next_report: dict[str, float] = {}

    # -- life -----------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind the socket. Raises OSError if the address is taken or not local."""
        if self._transport is not None or self._closed:
            raise RuntimeError("a RadioReceiver is opened once")
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            lambda: _Protocol(self), local_addr=(self.listen.host, self.listen.port)
        )
        self._transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
            except OSError:
                log.debug("could not enlarge the radio socket's receive buffer")
        sockname = transport.get_extra_info("sockname")
        self._bound = UdpAddress(str(sockname[0]), int(sockname[1]))
        log.info("radio receiver listening on %s", self._bound.url())

    async def close(self) -> None:
        """Close the socket (idempotent). Events already queued stay readable."""
        self._closed = True
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    async def __aenter__(self) -> RadioReceiver:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def address(self) -> UdpAddress:
        """The bound address (with the real port when 0 was asked)."""
        if self._bound is None:
            raise RuntimeError("the receiver is not open")
        return self._bound

    @property
    def port(self) -> int:
        return self.address.port

    async def get(self) -> RadioEvent:
        """The next accepted event (waits)."""
        return await self.queue.get()

    # -- datagrams ------------------------------------------------------------------------

    def handle_datagram(self, data: bytes, addr: Any) -> None:
        """Decode, check and enqueue one datagram. Never raises."""
        try:
            self._handle(data, addr)
        except Exception:  # a bug here must not stop the mission; count it and say so
            self.rejects["internal_error"] += 1
            log.exception("radio receiver: unexpected error handling a datagram")

    def decode_events(self, data: bytes) -> list[tuple[Detection | Heartbeat | WireError, bool]]:
        """The events in one datagram (wire format v1: exactly one), each with whether its
        ``t`` is on the receiver's clock (False: already the mission clock); an event that is
        refused is the WireError saying why."""
        try:
            return [(decode(data), True)]
        except WireError as exc:
            return [(exc, True)]

    def feeds_clock(self, event: Detection | Heartbeat) -> bool:
        """Whether the event's ``t`` is a sample of its source's clock: a heartbeat, stamped
        when sent (a detection is stamped when its pulse was heard, an unknown time before)."""
        return isinstance(event, Heartbeat)

    def _handle(self, data: bytes, addr: Any) -> None:
        self._datagrams += 1
        host = str(addr[0]) if isinstance(addr, tuple) and addr else "?"
        port = int(addr[1]) if isinstance(addr, tuple) and len(addr) > 1 else 0
        if not self.policy.source_allowed(host):
            self._reject(WireError("source_not_allowed",
                                   f"{host} is not in receiver.allowed_sources"), host, port)
            return
        for event, on_rx_clock in self.decode_events(data):
            try:
                if isinstance(event, WireError):
                    raise event
                now_s = self.policy.clock()
                t_rx = event.t
                if on_rx_clock:
                    event = self._on_mission_clock(event, (host, port), now_s)
                tag_id, event = self.policy.resolve(event, now_s)
            except WireError as exc:
                self._reject(exc, host, port)
                continue
            self._enqueue(RadioEvent(now_s, (host, port), tag_id, event, t_rx), host, port)

    def _reject(self, exc: WireError, host: str, port: int) -> None:
        self.rejects[exc.reason] += 1
        self._log.warning(exc.reason, "radio: rejected a datagram from %s:%d: %s",
                          host, port, exc)

    def _enqueue(self, item: RadioEvent, host: str, port: int) -> None:
        event, now_s, tag_id = item.event, item.recv_time_s, item.tag_id
        try:
            self.queue.put_nowait(item)
        except asyncio.QueueFull:
            self.rejects["queue_full"] += 1
            self._log.warning("queue_full", "radio: event queue full (%d); dropped a %s from "
                              "%s:%d", self.queue.maxsize, type(event).__name__, host, port)
            return
        if isinstance(event, Heartbeat):
            self._heartbeats += 1
            self._last_heartbeat_s = now_s
        elif isinstance(event, Detection):
            assert tag_id is not None
            self._accepted_by_tag[tag_id] += 1
            self._last_detection_s = now_s

    # -- receiver clocks ----------------------------------------------------------------------

    def _on_mission_clock(self, event: Detection | Heartbeat, source: tuple[str, int],
                          now_s: float) -> Detection | Heartbeat:
        """The event with its ``t`` on the mission clock; fits the source's clock with it
        first when it is a clock sample. Raises WireError(clock_offset_limit)."""
        policy = self.policy
        if abs(event.t - now_s) > policy.max_clock_offset_s:
            raise WireError("clock_offset_limit", f"t is {event.t - now_s:+.0f} s from now, "
                            f"more than receiver.max_clock_offset_s = "
                            f"{policy.max_clock_offset_s:g} s")
        host = source[0]  # the clock is the sending computer's, whatever port it sends from
        clock = self._clocks.pop(host, None)
        if clock is None:
            clock = ReceiverClock(bucket_s=self.clock_bucket_s)
            while len(self._clocks) >= MAX_CLOCK_SOURCES:
                forgotten = next(iter(self._clocks))
                del self._clocks[forgotten]
                self._next_report.pop(forgotten, None)
        self._clocks[host] = clock  # most recently heard last
        if self.feeds_clock(event) and policy.clock_synced():
            before = clock.offset_s if clock.ready else None
            change = clock.observe(event.t, now_s)
            if change is not None:
                report = clock.report(host, change, before if change == "jump" else None)
                self._report_clock(report, source, now_s)
            elif now_s >= self._next_report.get(host, -math.inf):
                self._report_clock(clock.report(host, "update"), source, now_s)
        if not (policy.clock_correction and clock.ready):
            return event
        return dataclasses.replace(event, t=clock.to_mission(event.t))

    def _report_clock(self, report: ClockReport, source: tuple[str, int], now_s: float) -> None:
        self._next_report[source[0]] = now_s + self.policy.clock_report_every_s
        if report.kind == "jump":
            log.warning("radio: the clock of %s jumped from %+.3f s to %+.3f s against the "
                        "mission clock", report.source, report.previous_offset_s or 0.0,
                        report.offset_s)
        elif report.kind == "first":
            log.info("radio: %s's clock is %+.3f s from the mission clock", report.source,
                     report.offset_s)
        self._enqueue(RadioEvent(now_s, source, None, report, None), *source)

    def clock_of(self, host: str, port: int | None = None) -> ReceiverClock | None:
        """The learnt clock of a sending host (any port), if it has sent anything."""
        return self._clocks.get(host)

    def note_socket_error(self, exc: Exception) -> None:
        self._socket_errors += 1
        self._log.warning("socket_error", "radio: socket error: %s", exc)

    def stats(self) -> ReceiverStats:
        """A consistent snapshot of the counters."""
        return ReceiverStats(
            datagrams=self._datagrams,
            accepted=sum(self._accepted_by_tag.values()) + self._heartbeats,
            accepted_by_tag=dict(self._accepted_by_tag),
            heartbeats=self._heartbeats,
            rejects=dict(self.rejects),
            queue_depth=self.queue.qsize(),
            last_heartbeat_s=self._last_heartbeat_s,
            last_detection_s=self._last_detection_s,
            socket_errors=self._socket_errors,
        )
