"""The IQ receiver in the GCS process (`sitl --receiver iq`, `fly --iq-source URL`): a thread
that opens the source (an rtl_tcp server, a dongle, a recording), runs `mexgen_gcs.receiver`
and sends its detections and heartbeats to the GCS's own radio port, as a separate receiver
would.

The receiver's sample clock is anchored to the mission clock (the vehicle's time), so it
waits until that clock has synchronised with the vehicle before connecting. A failure ends
the thread with a logged error; the GCS then sees a silent radio and its safety rules act.
"""

from __future__ import annotations

import collections
import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mexgen_gcs.io.clock import Clock
from mexgen_gcs.receiver.output import UdpSender
from mexgen_gcs.receiver.run import ReceiveOptions, RunSummary, run_receiver
from mexgen_gcs.receiver.sources import SourceError
from mexgen_gcs.receiver.tuning import TuningError
from mexgen_gcs.receiver.urls import open_source

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class IqReceiverSpec:
    source: str
    """A source URL of `mexgen_gcs.receiver.urls` (e.g. ``rtltcp://127.0.0.1:1234``)."""
    options: ReceiveOptions
    hold_s: float = 0.0
    """Hold each detection (heartbeats go at once) at most this long (mission clock) until
    the GCS's telemetry covers its time (``covered``), so the pulse can be posed when it
    arrives (a simulator run K times faster than real time delivers telemetry K times later
    in its own time)."""


class IqReceiverThread:
    def __init__(self, mission: Any, spec: IqReceiverSpec, radio_url: str, clock: Clock,
                 sync_timeout_s: float = 120.0,
                 covered: Callable[[float], bool] | None = None) -> None:
        self.mission = mission
        self.spec = spec
        self.radio_url = radio_url
        self.clock = clock
        self.sync_timeout_s = sync_timeout_s
        self.covered = covered or (lambda t: True)
        self.stop = threading.Event()
        self.summary: RunSummary | None = None
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="iq-receiver", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self, timeout_s: float = 10.0) -> None:
        self.stop.set()
        self._thread.join(timeout_s)

    def _covers(self, data: bytes) -> bool:
        try:
            return bool(self.covered(float(json.loads(data)["t"])))
        except (ValueError, KeyError, IndexError, RuntimeError):
            return False

    def _run(self) -> None:
        deadline = time.monotonic() + self.sync_timeout_s
        while not self.stop.is_set() and not getattr(self.clock, "synced", True):
            if time.monotonic() > deadline:
                self.error = "the mission clock never synchronised; the IQ receiver did not start"
                log.error(self.error)
                return
            time.sleep(0.05)
        sender = UdpSender(self.radio_url)
        held: collections.deque[tuple[float, bytes]] = collections.deque()

        def send(data: bytes) -> None:
            now = self.clock.now()
            if b'"heartbeat"' in data:
                sender.send(data)  # the receiver is alive now, whatever it holds
            else:
                held.append((now + self.spec.hold_s, data))
            while held and (held[0][0] <= now or self._covers(held[0][1])):
                sender.send(held.popleft()[1])

        try:
            source = open_source(self.spec.source)
            self.summary = run_receiver(self.mission, source, self.spec.options,
                                        send=send, clock=self.clock.now, stop=self.stop)
            s = self.summary
            log.info("IQ receiver: %d pulses, %d of %d samples dropped", len(s.pulses),
                     s.dropped_samples, s.samples)
        except (SourceError, TuningError, OSError) as exc:
            if not self.stop.is_set():
                self.error = f"IQ receiver: {exc}"
                log.error(self.error)
        finally:
            sender.close()
