"""`mexgen-gcs bench receiver`: how much of one core the IQ receiver needs.

Four tags at 150.10-150.46 MHz, 2.4 Msps cu8 (an RTL-SDR's usual rate) with noise, pulses
and clipping flags as a dongle delivers them: the samples are made before the clock starts
and fed in blocks of 0.1 s through the whole receiver (conversion, FFT channels, detector,
calibration, datagram encoding). Real-time factor = seconds of samples per second of CPU;
the CPU share of one core = 1 / real-time factor. Single-threaded (``pin_single_thread``).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from mexgen_gcs.receiver import synth
from mexgen_gcs.receiver.calibration import Calibration
from mexgen_gcs.receiver.convert import convert
from mexgen_gcs.receiver.detector import DetectorConfig
from mexgen_gcs.receiver.output import pulse_datagram, status_datagram
from mexgen_gcs.receiver.pipeline import Pulse, PulseReceiver
from mexgen_gcs.receiver.sources import IQBlock
from mexgen_gcs.receiver.tuning import plan_tuning

TAGS = [("T1", 150_100_000.0), ("T2", 150_220_000.0), ("T3", 150_340_000.0),
        ("T4", 150_460_000.0)]


def measure(rate_hz: float = 2_400_000.0, seconds: float = 10.0, seed: int = 0,
            ntags: int = 4) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    plan = plan_tuning(TAGS[:ntags], rate_hz=rate_hz)
    block = round(0.1 * rate_hz)
    nblocks = round(seconds / 0.1)
    chunk = [(p * rate_hz, 0.02 * rate_hz, 10 ** (-40 / 10), c.offset_hz)
             for c in plan.channels for p in np.arange(0.05, 1.0, 0.5)]
    base = [synth.to_cu8(synth.pulse_train(k * block, block, rate_hz, 1e-3, chunk, rng))
            .tobytes() for k in range(10)]  # one second, repeated
    rx = PulseReceiver(plan, DetectorConfig(), Calibration(), start_unix=0.0)
    pulses = 0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for k in range(nblocks):
        raw = base[k % len(base)]
        samples, clipped = convert(raw, "cu8")
        for ev in rx.process(IQBlock(samples, clipped, raw, "cu8")):
            if isinstance(ev, Pulse):
                pulse_datagram(ev)
                pulses += 1
            else:
                status_datagram(ev)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    stream_s = nblocks * block / rate_hz
    return {"rate_hz": rate_hz, "tags": ntags, "stream_s": stream_s, "cpu_s": cpu,
            "wall_s": wall, "realtime_factor": stream_s / cpu,
            "cpu_share_of_one_core": cpu / stream_s, "pulses": pulses,
            "frame_len": rx.channels.frame_len, "bins_per_channel": rx.channels.bins}


def table(r: dict[str, Any]) -> str:
    return (f"receiver at {r['rate_hz'] / 1e6:g} Msps, {r['tags']} tags: {r['stream_s']:.0f} s "
            f"of samples in {r['cpu_s']:.2f} s CPU ({r['wall_s']:.2f} s wall): real-time "
            f"factor {r['realtime_factor']:.1f}, {100 * r['cpu_share_of_one_core']:.1f} % of "
            f"one core; {r['pulses']} pulses")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="mexgen-gcs bench receiver")
    p.add_argument("--json", action="store_true")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--rate", type=float, default=2_400_000.0)
    args = p.parse_args(argv)
    r = measure(args.rate, args.seconds)
    print(json.dumps(r, indent=2) if args.json else table(r))
    return 0
