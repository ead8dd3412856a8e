"""Synthetic IQ: white noise, rectangular tag pulses, CW tones, and 8-bit quantisation as an
RTL-SDR delivers it. Used by the statistics study, the benchmark, tests and the simulator's
rtl_tcp server, so they all hear the same kind of signal. Powers are linear, full scale = 1
(a complex sample of magnitude 1); every random draw takes an explicit Generator.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Complex = NDArray[np.complex64]

SIM_CAL_OFFSET_DB = 24.6
"""Calibration offset of the simulator's rtl_tcp dongle (``python -m sim --iq-server``):
``dBm = dBFS - gain + SIM_CAL_OFFSET_DB``, as a field calibration would measure it."""


def noise(n: int, power_fs: float, rng: np.random.Generator) -> Complex:
    """n samples of complex white Gaussian noise of total power ``power_fs``."""
    scale = np.float32(np.sqrt(power_fs / 2.0))
    out = rng.standard_normal(2 * n, dtype=np.float32)
    out *= scale
    return out.view(np.complex64)


def add_tone(x: Complex, first_sample: int, power_fs: float, freq_hz: float, rate_hz: float,
             phase: float = 0.0, start: float = 0.0, stop: float | None = None) -> None:
    """Add (in place) a tone of ``power_fs`` at ``freq_hz`` from the centre, on from sample
    ``start`` to ``stop`` (absolute, fractional allowed: the edge sample gets its share),
    where x[0] is absolute sample ``first_sample``. The phase runs on absolute samples, so a
    tone split over blocks is continuous."""
    n = x.size
    stop_s = first_sample + n if stop is None else stop
    a = max(int(np.floor(start)), first_sample)
    b = min(int(np.ceil(stop_s)), first_sample + n)
    if b <= a:
        return
    idx = np.arange(a, b, dtype=np.float64)
    w = np.clip(np.minimum(idx + 1.0 - start, stop_s - idx), 0.0, 1.0)
    ph = phase + 2.0 * np.pi * freq_hz / rate_hz * idx
    tone = (np.sqrt(power_fs) * w) * np.exp(1j * ph)
    x[a - first_sample: b - first_sample] += tone.astype(np.complex64)


def to_cu8(x: Complex) -> NDArray[np.uint8]:
    """Interleaved unsigned 8-bit I/Q as rtl_tcp sends them (127.5 = zero), clipped at 0/255."""
    v = x.view(np.float32) * np.float32(127.5) + np.float32(127.5)
    np.clip(np.rint(v), 0, 255, out=v)
    return v.astype(np.uint8)


def pulse_train(first_sample: int, n: int, rate_hz: float, noise_power_fs: float,
                pulses: list[tuple[float, float, float, float]], rng: np.random.Generator,
                tones: Sequence[tuple[float, float, float, float | None]] = ()) -> Complex:
    """Samples ``first_sample .. first_sample + n`` of noise plus rectangular pulses
    (start_sample, width_samples, power_fs, offset_hz) and tones (power_fs, offset_hz,
    start_sample, stop_sample or None); pulses outside the block are skipped."""
    x = noise(n, noise_power_fs, rng)
    end = first_sample + n
    for start, width, power, offset in pulses:
        if start < end and start + width > first_sample:
            add_tone(x, first_sample, power, offset, rate_hz, phase=float(start) * 0.37,
                     start=start, stop=start + width)
    for power, offset, start, stop in tones:
        add_tone(x, first_sample, power, offset, rate_hz, start=start, stop=stop)
    return x


def from_cu8(data: NDArray[np.uint8]) -> Complex:
    """The inverse of `to_cu8` (up to the quantisation)."""
    v = data.astype(np.float32)
    v -= np.float32(127.5)
    v *= np.float32(1.0 / 127.5)
    return v.view(np.complex64)
