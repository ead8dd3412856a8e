"""Receiver clocks: each radio receiver's clock offset and drift against the mission clock,
learnt from the timestamps it sends and the mission time they arrive at (no frames here: times
only, unix seconds).

A receiver stamps its datagrams with its own clock ``r``; the GCS notes the mission time ``m``
at which each arrives. ``d = r - m = offset(m) - delay``, where the delay (network, queueing,
the receiver's own latency) is never negative. The fit is ``offset(m) = a + b (m - m_ref)``,
``m_ref`` the newest sample's arrival: ``a`` is the offset now (s), ``b`` the drift (1e-6 b =
ppm, the receiver's seconds per mission second minus one).

How: samples (heartbeats: stamped when sent, so the delay is the network's) are kept for
``window_s`` mission seconds and grouped in ``bucket_s`` buckets; in each bucket only the
sample with the LARGEST ``d`` (the least delayed) is kept, so a late datagram never drags the
estimate. The drift is the least-squares slope through those bucket maxima once they span
``min_fit_span_s``; before that the drift is 0 and the offset is the newest bucket's maximum.
The offset is the regression line at ``m_ref``: it is biased low by the mean least delay of a
bucket (the loopback tests: under a millisecond of wall time), which is the accuracy the
pulse times get.

Jumps: a sample further than ``jump_s`` (or ``JUMP_SPREADS`` times the spread of the bucket
maxima about the fit, when larger) from the fit is held back; ``jump_confirm`` such
samples in a row, all on the same side, mean the receiver's clock stepped (an NTP or GPS time
fix on a companion computer that booted without a real-time clock): the window restarts from
them and `observe` says ``"jump"``. A single late datagram (a delay spike) is dropped from the
fit and does not restart it.

Mission time of a receiver timestamp: ``m = (r - a + b m_ref) / (1 + b)`` (inverts
``r = m + a + b (m - m_ref)``).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

ClockChange = Literal["first", "jump"]

WINDOW_S = 120.0
BUCKET_S = 2.0
MIN_FIT_SPAN_S = 20.0
JUMP_S = 5.0
"""A step smaller than this is followed by the fit (within a bucket when the clock steps
forward, over the window when back) instead of restarting it: the mission clock a simulated
vehicle gives a loaded machine at speed-up 10 wanders by +-3 s (docs/receiver-clocks.md)."""
JUMP_SPREADS = 4.0
"""...or this many times the fit's own spread, when that is larger: a jump must stand out of
the noise the samples already show (the mission clock's own wander under load)."""
JUMP_CONFIRM = 3
MAX_DRIFT_PPM = 50_000.0
"""A fitted drift beyond +-5 % is not a crystal's: the fit keeps the last sane value."""


@dataclass(frozen=True, slots=True)
class ClockReport:
    """A receiver clock estimate for the flight log (``receiver_clock`` records); ``source``
    is the sending host.

    ``kind``: ``first`` (the first estimate of this source), ``update`` (periodic), ``jump``
    (the receiver's clock stepped; ``previous_offset_s`` is the estimate before it)."""

    source: str
    kind: Literal["first", "update", "jump"]
    offset_s: float
    drift_ppm: float
    samples: int
    spread_s: float
    previous_offset_s: float | None = None


class ReceiverClock:
    """One receiver's clock against the mission clock (see the module docstring)."""

    def __init__(
        self,
        *,
        window_s: float = WINDOW_S,
        bucket_s: float = BUCKET_S,
        min_fit_span_s: float = MIN_FIT_SPAN_S,
        jump_s: float = JUMP_S,
        jump_confirm: int = JUMP_CONFIRM,
        max_drift_ppm: float = MAX_DRIFT_PPM,
    ) -> None:
        self.window_s = window_s
        self.bucket_s = bucket_s
        self.min_fit_span_s = min_fit_span_s
        self.jump_s = jump_s
        self.jump_confirm = max(1, jump_confirm)
        self.max_drift = max_drift_ppm * 1e-6
        self._samples: collections.deque[tuple[float, float]] = collections.deque()
        self._pending: list[tuple[float, float]] = []
        self._a = 0.0
        self._b = 0.0
        self._m_ref = 0.0
        self._ready = False
        self.spread_s = math.nan
        self.samples_total = 0
        self.samples_held_back = 0
        self.jumps = 0

    # -- state -------------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        """At least one sample: the offset is known (the drift may still be 0)."""
        return self._ready

    @property
    def offset_s(self) -> float:
        """Receiver minus mission time at the newest sample, s."""
        return self._a

    @property
    def drift_ppm(self) -> float:
        return self._b * 1e6

    @property
    def samples(self) -> int:
        return len(self._samples)

    def report(self, source: str, kind: Literal["first", "update", "jump"],
               previous_offset_s: float | None = None) -> ClockReport:
        return ClockReport(source, kind, self._a, self.drift_ppm, len(self._samples),
                           self.spread_s, previous_offset_s)

    # -- input -------------------------------------------------------------------------------

    def observe(self, receiver_t: float, arrival_m: float) -> ClockChange | None:
        """One receiver timestamp and the mission time it arrived at. Returns ``"first"`` for
        the first usable sample, ``"jump"`` when the clock stepped, else None. Non-finite
        values are ignored."""
        if not (math.isfinite(receiver_t) and math.isfinite(arrival_m)):
            return None
        self.samples_total += 1
        d = float(receiver_t) - float(arrival_m)
        m = float(arrival_m)
        if self._ready:
            err = d - self._predict_d(m)
            spread = self.spread_s if math.isfinite(self.spread_s) else 0.0
            if abs(err) > max(self.jump_s, JUMP_SPREADS * spread):
                self._pending.append((m, d))
                self.samples_held_back += 1
                if len(self._pending) < self.jump_confirm:
                    return None
                sides = {math.copysign(1.0, pd - self._predict_d(pm)) for pm, pd in self._pending}
                if len(sides) > 1:  # spikes either way: not a step of the clock
                    self._pending = self._pending[-1:]
                    return None
                self.jumps += 1
                self._samples = collections.deque(self._pending)
                self._pending = []
                self._fit()
                return "jump"
            self._pending.clear()
        self._samples.append((m, d))
        while self._samples and m - self._samples[0][0] > self.window_s:
            self._samples.popleft()
        self._fit()
        if not self._ready:
            self._ready = True
            return "first"
        return None

    def _fit(self) -> None:
        arr = np.asarray(self._samples, dtype=np.float64)
        m, d = arr[:, 0], arr[:, 1]
        self._m_ref = float(m[-1])
        keys = np.floor(m / self.bucket_s)
        order = np.lexsort((d, keys))  # by bucket, then d ascending
        ks = keys[order]
        last = np.r_[ks[1:] != ks[:-1], True]
        sel = order[last]  # each bucket's largest d
        ms, ds = m[sel], d[sel]
        b = 0.0
        if len(sel) >= 3 and float(ms[-1] - ms[0]) >= self.min_fit_span_s:
            x = ms - self._m_ref
            xc = x - x.mean()
            slope = float(np.dot(xc, ds - ds.mean()) / np.dot(xc, xc))
            b = slope if math.isfinite(slope) and abs(slope) <= self.max_drift else self._b
            a = float(np.mean(ds - b * x))
            self.spread_s = float(np.std(ds - (a + b * x)))
        else:
            a = float(ds[-1])
            self.spread_s = float(np.std(ds)) if len(ds) > 1 else 0.0
        self._a, self._b = a, b

    def _predict_d(self, m: float) -> float:
        return self._a + self._b * (m - self._m_ref)

    # -- output ------------------------------------------------------------------------------

    def to_mission(self, receiver_t: float) -> float:
        """The mission time of a receiver timestamp (identity before the first sample)."""
        if not self._ready:
            return float(receiver_t)
        return (float(receiver_t) - self._a + self._b * self._m_ref) / (1.0 + self._b)
