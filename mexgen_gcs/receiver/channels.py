"""Per-tag channels: a rectangular-window FFT filter bank, and each tag's band energy per frame.

Samples are cut into frames of ``frame_len`` samples (a power of two near ``rate / 500 Hz``,
so a bin is about 500 Hz wide and a frame lasts about 2 ms); each frame's FFT is a critically
sampled filter bank whose bins, for white noise, are independent with equal energy. A tag's
channel is the K bins nearest its offset from the centre (K bins ~ the channel width). The
channel's energy per frame, normalised by the frame length,

    e = sum_k |X_k|^2 / M

has mean K sigma^2 in noise of variance sigma^2 per complex sample, and A^2 M for a tone of
power A^2 (full scale = 1) at a bin's centre. Frames carry their index, so a frame's first
sample is ``frame * M`` on the source's sample counter. Leftover samples wait for the next
block. Vectorised: one FFT per block of frames, then a gather of the tags' bins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from mexgen_gcs.receiver.tuning import TuningPlan

BIN_TARGET_HZ = 500.0


def frame_length(rate_hz: float, bin_hz: float = BIN_TARGET_HZ) -> int:
    """Power of two nearest rate / bin_hz (at least 16)."""
    return max(16, 2 ** round(math.log2(rate_hz / bin_hz)))


@dataclass(frozen=True, slots=True)
class Frames:
    """A run of consecutive frames: ``first`` is the index of the first one."""

    first: int
    energy: NDArray[np.float64]
    """(frames, tags) band energy per frame, as in the module docstring."""
    peak_bin: NDArray[np.int64]
    """(frames, tags) the strongest bin of the band, -K/2..K/2 about the channel's centre."""
    clipped: NDArray[np.bool_]
    """(frames,) a sample of the frame was at the converter's limit."""


class Channeliser:
    """Cuts samples into frames and gives each tag's band energy per frame."""

    def __init__(self, plan: TuningPlan, frame_len: int | None = None) -> None:
        self.rate_hz = plan.rate_hz
        self.frame_len = frame_len or frame_length(plan.rate_hz)
        self.bin_hz = plan.rate_hz / self.frame_len
        self.bins = max(1, round(plan.channel_width_hz / self.bin_hz))
        centres = np.array([c.offset_hz / self.bin_hz for c in plan.channels])
        lo = np.round(centres - (self.bins - 1) / 2.0).astype(np.int64)
        self._index = (lo[:, None] + np.arange(self.bins)[None, :]) % self.frame_len
        self._flat = self._index.ravel()
        self._carry = np.zeros(0, np.complex64)
        self._carry_clip = np.zeros(0, bool)
        self._next_frame = 0
        self.capture = capture_fraction(self.bins)

    @property
    def frame_s(self) -> float:
        return self.frame_len / self.rate_hz

    def reset(self, next_sample: int) -> None:
        """Samples were lost: drop the partial frame; the next sample pushed is
        ``next_sample`` on the counter (its frame starts with zeros up to it)."""
        m = self.frame_len
        self._next_frame = next_sample // m
        self._carry = np.zeros(next_sample % m, np.complex64)
        self._carry_clip = np.zeros(next_sample % m, bool)

    def push(self, samples: NDArray[np.complex64], clipped: NDArray[np.bool_]) -> Frames:
        """Add samples (with their per-sample clipping flags); returns the whole frames."""
        m = self.frame_len
        x = np.concatenate((self._carry, samples)) if self._carry.size else samples
        c = np.concatenate((self._carry_clip, clipped)) if self._carry_clip.size else clipped
        n = x.size // m
        self._carry, self._carry_clip = x[n * m:].copy(), c[n * m:].copy()
        first = self._next_frame
        self._next_frame += n
        ntags = self._index.shape[0]
        if n == 0:
            return Frames(first, np.zeros((0, ntags)), np.zeros((0, ntags), np.int64),
                          np.zeros(0, bool))
        spec = scipy.fft.fft(x[: n * m].reshape(n, m), axis=1, workers=1)
        sel = spec[:, self._flat]
        power = (sel.real * sel.real + sel.imag * sel.imag).reshape(n, ntags, self.bins)
        energy = power.sum(axis=2, dtype=np.float64) / m
        peak = power.argmax(axis=2).astype(np.int64) - (self.bins - 1) // 2
        cc = c[: n * m]
        clip = (np.asarray(cc.reshape(n, m).any(axis=1)) if cc.any()
                else np.zeros(n, dtype=bool))
        return Frames(first, energy, peak, clip)


def capture_fraction(bins: int, grid: int = 64) -> float:
    """Mean share of a tone's energy inside a K-bin band of a rectangular-window FFT, the tone
    uniform within half a bin of the band's centre (the rest leaks to the bins outside):
    sum over the band's bins j of sinc^2(u - j). Dividing the measured energy by it removes the
    leakage bias of the power estimate."""
    u = (bins - 1) / 2.0 + (np.arange(grid) + 0.5) / grid - 0.5
    frac = (np.sinc(u[:, None] - np.arange(bins)[None, :]) ** 2).sum(axis=1)
    return float(frac.mean())
