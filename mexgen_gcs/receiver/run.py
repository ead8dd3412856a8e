"""One receiver run: open the source, plan the tuning, configure the device, then read blocks,
detect, send datagrams and record until the source ends or ``stop`` is set.

Blocking (the source's reads block); the GCS runs it in a thread (`sitl --receiver iq`), the
`receive` command in the main thread. A recording's replay is timed by the recording's start
time; raw files without one start at the host clock's now.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mexgen_gcs.receiver.calibration import Calibration, nearest_gain_db
from mexgen_gcs.receiver.detector import DetectorConfig
from mexgen_gcs.receiver.output import pulse_datagram, status_datagram
from mexgen_gcs.receiver.pipeline import Pulse, PulseReceiver, Status
from mexgen_gcs.receiver.sigmf import SigmfWriter
from mexgen_gcs.receiver.sources import FileSource, IQSource, Tuning
from mexgen_gcs.receiver.tuning import TuningPlan, plan_tuning

log = logging.getLogger(__name__)

DEFAULT_GAIN_DB = 29.7


@dataclass(frozen=True, slots=True)
class ReceiveOptions:
    gain_db: float = DEFAULT_GAIN_DB
    cal_offset_db: float = 0.0
    ppm: float = 0.0
    pfa_per_s: float = 1e-3
    channel_width_hz: float = 3000.0
    rate_hz: float | None = None
    block_s: float = 0.05
    gap_tolerance_s: float = 0.5
    duration_s: float | None = None
    realtime: bool = False
    record: Path | None = None


@dataclass
class RunSummary:
    plan: TuningPlan
    pulses: list[Pulse] = field(default_factory=list)
    statuses: int = 0
    samples: int = 0
    dropped_samples: int = 0
    clipped_frames: int = 0
    cw_rejected: int = 0
    width_rejected: int = 0
    damage: str | None = None


def mission_tags(mission: Any) -> list[tuple[str, float]]:
    return [(t.id, float(t.freq_hz)) for t in mission.tags]


def prepare(mission: Any, source: IQSource, options: ReceiveOptions, *,
            clock: Callable[[], float] = time.time) -> tuple[PulseReceiver, Calibration]:
    """Plan, configure the source, and build the receiver (raises TuningError, SourceError)."""
    fixed = source.fixed
    plan = plan_tuning(
        mission_tags(mission), channel_width_hz=options.channel_width_hz, ppm=options.ppm,
        rate_hz=fixed.rate_hz if fixed else options.rate_hz,
        centre_hz=fixed.centre_hz if fixed else None,
        ppm_in_software=not source.sets_ppm)
    # a recording made here carries its gain and calibration; a raw file takes the options'
    gain = nearest_gain_db(options.gain_db, source.gain_table)
    cal_offset = options.cal_offset_db
    if isinstance(source, FileSource):
        gain = float(source.meta.get("mexgen:gain_db", gain))
        cal_offset = float(source.meta.get("mexgen:cal_offset_db", cal_offset))
    source.tune(Tuning(plan.centre_hz, plan.rate_hz, gain, options.ppm))
    cal = Calibration(gain, cal_offset, source.name)
    config = DetectorConfig(pulse_width_s=mission.receiver.pulse_width_s,
                            pfa_per_s=options.pfa_per_s)
    start = None
    if not source.live:
        start = source.start_unix if isinstance(source, FileSource) else None
        if start is None or options.realtime:
            start = clock()
    rx = PulseReceiver(plan, config, cal, period_s=mission.receiver.pulse_period_s,
                       clock=clock if source.live else None, start_unix=start,
                       gap_tolerance_s=options.gap_tolerance_s)
    return rx, cal


def run_receiver(mission: Any, source: IQSource, options: ReceiveOptions, *,
                 send: Callable[[bytes], None] | None = None,
                 clock: Callable[[], float] = time.time,
                 stop: threading.Event | None = None,
                 on_ready: Callable[[TuningPlan], None] | None = None) -> RunSummary:
    rx, cal = prepare(mission, source, options, clock=clock)
    summary = RunSummary(rx.plan)
    if on_ready is not None:
        on_ready(rx.plan)
    log.info("receiver %s: %s", source.name, rx.plan.describe())
    recorder = None
    block_samples = max(1024, round(options.block_s * rx.rate_hz))
    wall0 = time.monotonic()
    try:
        while stop is None or not stop.is_set():
            block = source.read(block_samples)
            if block is None:
                break
            lost_before = rx.counters.dropped_samples
            events = rx.process(block)
            if options.record is not None:
                if recorder is None:
                    recorder = SigmfWriter(options.record, block.fmt, rx.plan,
                                           gain_db=cal.gain_db, cal_offset_db=cal.cal_offset_db)
                if rx.counters.dropped_samples > lost_before:
                    recorder.gap(rx.stream_samples - block.samples.size)
                recorder.write(block.raw, block.fmt, rx.anchor_unix)
            for ev in events:
                if isinstance(ev, Pulse):
                    summary.pulses.append(ev)
                    if recorder is not None:
                        recorder.annotate(ev)
                    if send is not None:
                        send(pulse_datagram(ev))
                elif isinstance(ev, Status):
                    summary.statuses += 1
                    if send is not None:
                        send(status_datagram(ev))
            stream_s = rx.counters.samples / rx.rate_hz
            if options.duration_s is not None and stream_s >= options.duration_s:
                break
            if options.realtime and not source.live:
                ahead = stream_s - (time.monotonic() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
    finally:
        if recorder is not None:
            recorder.close()
        source.close()
    summary.samples = rx.counters.samples
    summary.dropped_samples = rx.counters.dropped_samples
    summary.clipped_frames = rx.counters.clipped_frames
    summary.cw_rejected = rx.detector.stats.cw_rejected
    summary.width_rejected = rx.detector.stats.width_rejected
    summary.damage = getattr(source, "damage", None)
    return summary
