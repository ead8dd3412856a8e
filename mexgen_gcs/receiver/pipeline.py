"""Samples in, calibrated pulses and per-tag status out, timed by the sample counter.

Time: the counter of samples since the stream began is anchored once to a clock (a recording's
own start time, or the host clock when the first block arrives), and a pulse's time is
``anchor + sample / rate``: host scheduling and buffering never move it. A live stream's
first block may come out of a backlog; during the first ``refine_s`` of samples the anchor
moves earlier whenever a block arrives earlier than the anchor says it could (the earliest
arrival bounds the latency), and never later. Dropped samples: a
live source numbers no samples, so each block compares the counter with the clock; when the
counter lags by more than ``gap_tolerance_s`` the missing samples are counted as dropped, the
counter jumps over them (times stay right) and the detector restarts its sums. Sources that
report their losses (``lost_before``) are counted the same way.

Status: every ``status_period_s`` of stream time, per tag, the noise floor in the channel
(dBm) and how many pulses were heard, so a quiet tag reads "listening, nothing heard, noise
floor N".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from mexgen_gcs.receiver.calibration import Calibration
from mexgen_gcs.receiver.channels import Channeliser
from mexgen_gcs.receiver.detector import DetectorConfig, PulseDetector, PulseFound
from mexgen_gcs.receiver.sources import IQBlock
from mexgen_gcs.receiver.tuning import TuningPlan


@dataclass(frozen=True, slots=True)
class Pulse:
    tag: str
    freq_hz: int
    t_unix: float
    sample: float
    """Leading edge on the stream's sample counter (fractional)."""
    rssi_dbm: float
    snr_db: float
    noise_dbm: float
    width_s: float
    clipped: bool
    interval_s: float | None
    """Time since this tag's previous pulse, when that is within 5 % of a whole number of
    pulse periods (the pulse train is being tracked); else None."""


@dataclass(frozen=True, slots=True)
class Status:
    t_unix: float
    noise_dbm: dict[str, float]
    heard: dict[str, int]
    dropped_samples: int
    clipped_frames: int


@dataclass
class ReceiverCounters:
    samples: int = 0
    dropped_samples: int = 0
    gaps: int = 0
    clipped_frames: int = 0
    pulses: int = 0
    per_tag: dict[str, int] = field(default_factory=dict)


class PulseReceiver:
    """One receiver run over one stream."""

    def __init__(self, plan: TuningPlan, config: DetectorConfig, calibration: Calibration, *,
                 period_s: float = 1.0, clock: Callable[[], float] | None = None,
                 start_unix: float | None = None, gap_tolerance_s: float = 0.5,
                 status_period_s: float = 1.0, refine_s: float = 10.0) -> None:
        if clock is None and start_unix is None:
            raise ValueError("need a clock or a start time")
        self.plan = plan
        self.cal = calibration
        self.channels = Channeliser(plan)
        self.detector = PulseDetector(self.channels, config, len(plan.channels))
        self.tags: Sequence[str] = [c.id for c in plan.channels]
        self.period_s = period_s
        self.clock = clock
        self.anchor_unix = start_unix
        self.gap_tolerance_s = gap_tolerance_s
        self.refine_s = refine_s
        self.status_period_s = status_period_s
        self.counters = ReceiverCounters(per_tag=dict.fromkeys(self.tags, 0))
        self._heard = dict.fromkeys(self.tags, 0)
        self._last_t: dict[str, float] = {}
        self._next_status = status_period_s
        self._samples = 0  # stream samples so far, dropped ones included

    @property
    def stream_samples(self) -> int:
        """Samples of the stream so far, the lost ones included."""
        return self._samples

    @property
    def rate_hz(self) -> float:
        return self.plan.rate_hz

    def time_of(self, sample: float) -> float:
        assert self.anchor_unix is not None
        return self.anchor_unix + sample / self.rate_hz

    def process(self, block: IQBlock) -> list[Pulse | Status]:
        n = block.samples.size
        if self.anchor_unix is None:
            assert self.clock is not None
            self.anchor_unix = self.clock() - n / self.rate_hz
        lost = block.lost_before
        if self.clock is not None and self.anchor_unix is not None:
            late_s = self.clock() - self.time_of(self._samples + n)
            if late_s < 0.0 and self.counters.samples < self.refine_s * self.rate_hz:
                # samples cannot arrive before they were taken: the first block came late
                # (a backlog at start); move the anchor to the earliest arrival seen
                self.anchor_unix += late_s
                late_s = 0.0
            if late_s > self.gap_tolerance_s:
                lost = max(lost, round(late_s * self.rate_hz))
        if lost > 0:
            self._samples += lost
            self.counters.dropped_samples += lost
            self.counters.gaps += 1
            self.channels.reset(self._samples)
            self.detector.reset()
        frames = self.channels.push(block.samples, block.clipped)
        self._samples += n
        self.counters.samples += n
        self.counters.clipped_frames += int(frames.clipped.sum())
        out: list[Pulse | Status] = [self._pulse(p) for p in self.detector.push(frames)]
        stream_s = self._samples / self.rate_hz
        if stream_s >= self._next_status:
            out.append(self._status())
            self._next_status = (math.floor(stream_s / self.status_period_s) + 1) \
                * self.status_period_s
        return out

    def _pulse(self, p: PulseFound) -> Pulse:
        ch = self.plan.channels[p.tag_index]
        t = self.time_of(p.start_sample)
        interval = None
        last = self._last_t.get(ch.id)
        if last is not None:
            k = round((t - last) / self.period_s)
            if k >= 1 and abs(t - last - k * self.period_s) <= 0.05 * self.period_s:
                interval = t - last
        self._last_t[ch.id] = t
        self._heard[ch.id] += 1
        self.counters.pulses += 1
        self.counters.per_tag[ch.id] += 1
        return Pulse(ch.id, round(ch.freq_hz + p.freq_offset_hz), t, p.start_sample,
                     self.cal.dbm(p.power_fs), p.snr_db, self.cal.dbm(p.noise_fs), p.width_s,
                     p.clipped, interval)

    def noise_dbm(self) -> dict[str, float]:
        """Noise floor in each tag's channel band, dBm (NaN before the first estimate)."""
        noise = self.detector.noise_bin * self.channels.bins / self.channels.frame_len
        return {tid: (self.cal.dbm(float(v)) if math.isfinite(v) and v > 0 else math.nan)
                for tid, v in zip(self.tags, noise, strict=True)}

    def _status(self) -> Status:
        heard, self._heard = self._heard, dict.fromkeys(self.tags, 0)
        return Status(self.time_of(self._samples), self.noise_dbm(), heard,
                      self.counters.dropped_samples, self.counters.clipped_frames)
