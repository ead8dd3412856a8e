"""Synthetic IQ files for the receiver's tests: the demo mission's four tags, pulses at known
times and powers, white noise, quantised to cu8 as an RTL-SDR delivers it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mexgen_gcs.config import load_mission
from mexgen_gcs.receiver import synth
from mexgen_gcs.receiver.run import mission_tags
from mexgen_gcs.receiver.tuning import TuningPlan, plan_tuning

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "missions" / "demo.yaml"
NOISE_FS = 10 ** (-30 / 10)  # -30 dBFS: about 4 LSB rms in 8 bits


def demo_mission():  # type: ignore[no-untyped-def]
    return load_mission(DEMO)


def demo_plan() -> TuningPlan:
    return plan_tuning(mission_tags(demo_mission()))


def write_cu8(path: Path, plan: TuningPlan, seconds: float, pulses: list[tuple[int, float, float]],
              rng: np.random.Generator, *, width_s: float = 0.02,
              tones: list[tuple[float, float, float, float | None]] = ()) -> int:  # type: ignore[assignment]
    """Write ``seconds`` of cu8 with pulses (tag index, start s, power dBFS); tones as in
    synth.pulse_train (power_fs, offset_hz, start_sample, stop_sample). Returns samples."""
    fs = plan.rate_hz
    total = round(seconds * fs)
    block = round(0.5 * fs)
    spec = [(t * fs, width_s * fs, 10 ** (p / 10), plan.channels[i].offset_hz)
            for i, t, p in pulses]
    with open(path, "wb") as fh:
        for first in range(0, total, block):
            n = min(block, total - first)
            x = synth.pulse_train(first, n, fs, NOISE_FS, spec, rng, list(tones))
            fh.write(synth.to_cu8(x).tobytes())
    return total


def raw_url(path: Path, plan: TuningPlan) -> str:
    return f"file:{path}?rate={plan.rate_hz:g}&centre={plan.centre_hz:.0f}"
