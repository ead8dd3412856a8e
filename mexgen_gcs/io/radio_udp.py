"""UDP radio receiver: wire format v1 datagrams in, validated radio events out (no frames here;
poses stay as the receiver sent them, WGS84 degrees and a compass yaw).

`RadioReceiver` binds a UDP socket (asyncio datagram endpoint), decodes each datagram with
`wire.decode`, applies the mission's `RadioPolicy` (allowed source networks, known tags,
frequency -> tag within tolerance, clock skew) and puts accepted events on a bounded queue.
Nothing a sender does can raise out of it: every rejected datagram is counted under its
reason and logged at most once per reason per `log_interval_s`. When the queue is full the
event is counted under `queue_full` and logged, never dropped silently.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import socket
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

from mexgen_gcs.config.urls import UdpAddress, parse_udp_url
from mexgen_gcs.errors import WireError
from mexgen_gcs.io.wire import Detection, Heartbeat, decode

if TYPE_CHECKING:
    from mexgen_gcs.config.mission import Mission

__all__ = [
    "RECEIVE_QUEUE_SIZE",
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
POLICY_REASONS = ("source_not_allowed", "time_skew", "unknown_tag", "unknown_freq",
                  "tag_freq_mismatch")


class RadioEvent(NamedTuple):
    """An accepted datagram: receive time (policy clock, unix s), sender (host, port), the
    mission tag it maps to (None for a heartbeat) and the decoded event."""

    recv_time_s: float
    source: tuple[str, int]
    tag_id: str | None
    event: Detection | Heartbeat


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

    @classmethod
    def from_mission(cls, mission: Mission, clock: Callable[[], float] = time.time
                     ) -> RadioPolicy:
        r = mission.receiver
        return cls(
            tag_freqs_hz=tuple((t.id, t.freq_hz) for t in mission.tags),
            freq_tolerance_hz=r.freq_tolerance_hz,
            allowed_sources=r.networks(),
            max_clock_skew_s=r.max_clock_skew_s,
            clock=clock,
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

    def _handle(self, data: bytes, addr: Any) -> None:
        self._datagrams += 1
        host = str(addr[0]) if isinstance(addr, tuple) and addr else "?"
        port = int(addr[1]) if isinstance(addr, tuple) and len(addr) > 1 else 0
        try:
            if not self.policy.source_allowed(host):
                raise WireError("source_not_allowed", f"{host} is not in receiver.allowed_sources")
            now_s = self.policy.clock()
            tag_id, event = self.policy.resolve(decode(data), now_s)
        except WireError as exc:
            self.rejects[exc.reason] += 1
            self._log.warning(exc.reason, "radio: rejected a datagram from %s:%d: %s",
                              host, port, exc)
            return
        try:
            self.queue.put_nowait(RadioEvent(now_s, (host, port), tag_id, event))
        except asyncio.QueueFull:
            self.rejects["queue_full"] += 1
            self._log.warning("queue_full", "radio: event queue full (%d); dropped a %s from "
                              "%s:%d", self.queue.maxsize, type(event).__name__, host, port)
            return
        if isinstance(event, Heartbeat):
            self._heartbeats += 1
            self._last_heartbeat_s = now_s
        else:
            assert tag_id is not None
            self._accepted_by_tag[tag_id] += 1
            self._last_detection_s = now_s

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
