"""Pulse detection per tag channel: energy over the pulse width against a threshold set from a
false-alarm probability, a width gate, CW rejection, the power and the leading edge.

Per frame and tag, the statistic S is the channel's band energy summed over the last F frames,
F = ceil(pulse width / frame duration) (the energy detector matched to the pulse width). The
noise (per-bin energy sigma^2) is the median of the last ``noise_window_s`` of per-frame band
energies over the Gamma(K) median (pulses, a few per cent of the time, barely move a median).
A frame whose S exceeds ``sigma^2 * gamma.isf(pfa_test, K F)`` starts or continues a run; a
run becomes one pulse when it ends, judged at the frame of its largest S:

- CW rejection: a run longer than ``cw_factor`` pulse widths is a carrier, not a pulse
  (counted as ``cw_rejected``); a carrier that stays is absorbed by the noise median instead.
- width gate: above ``gate_snr_db`` the frames more than half on must span the pulse width
  within a factor (``width_gate``), else counted as ``width_rejected`` (impulses, other tags'
  wider pulses).
- power: pulse energy = S - K F sigma^2, divided by the band's capture fraction (leakage of
  the rectangular window), over the pulse width: the pulse's power A^2 in full-scale units.
- leading edge: from the first frame more than half on and its predecessor's share, to a
  fraction of a frame; the time comes from the sample counter (``pipeline``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from mexgen_gcs.receiver.channels import Channeliser, Frames
from mexgen_gcs.receiver.threshold import pfa_per_test, threshold_factor


@dataclass(frozen=True, slots=True)
class DetectorConfig:
    pulse_width_s: float = 0.02
    pfa_per_s: float = 1e-3
    noise_window_s: float = 2.0
    warmup_s: float = 0.25
    cw_factor: float = 3.0
    width_gate: tuple[float, float] = (0.5, 1.6)
    gate_snr_db: float = 10.0


@dataclass(frozen=True, slots=True)
class PulseFound:
    """One detected pulse on a tag channel (powers linear, full scale = 1)."""

    tag_index: int
    start_sample: float
    power_fs: float
    noise_fs: float
    """Noise power in the channel band, full-scale units."""
    snr_db: float
    width_s: float
    freq_offset_hz: float
    clipped: bool


@dataclass
class _Run:
    start: int
    length: int = 0
    best_s: float = -math.inf
    best_frame: int = -1


@dataclass
class DetectorStats:
    runs: int = 0
    pulses: int = 0
    cw_rejected: int = 0
    width_rejected: int = 0
    per_tag: list[int] = field(default_factory=list)


class PulseDetector:
    """Finds pulses in the frames of a `Channeliser`; one instance per receiver run."""

    def __init__(self, channels: Channeliser, config: DetectorConfig, ntags: int) -> None:
        self.ch = channels
        self.cfg = config
        self.ntags = ntags
        frame_s = channels.frame_s
        self.window = max(1, math.ceil(config.pulse_width_s / frame_s - 1e-9))
        self.dof = channels.bins * self.window
        self.tests_per_s = 1.0 / frame_s
        self.pfa_test = pfa_per_test(config.pfa_per_s, self.tests_per_s)
        self.factor = threshold_factor(self.dof, self.pfa_test)
        self._median_k = float(stats.gamma.median(channels.bins))
        # runs last a pulse width longer than their exceedances (see `push`)
        self.max_run = max(self.window + 2, math.ceil(config.cw_factor * self.window)) \
            + self.window - 1
        self._noise_len = max(16, round(config.noise_window_s / frame_s))
        self._warmup = max(8, round(config.warmup_s / frame_s))
        self._hist_len = max(self._noise_len, self.max_run + self.window + 4)
        self._hist = np.zeros((0, ntags))
        self._hist_first = 0
        self._clip_hist = np.zeros(0, bool)
        self._peak_hist = np.zeros((0, ntags), np.int64)
        self._noise_frames = 0
        self.noise_bin = np.full(ntags, np.nan)
        self._runs: list[_Run | None] = [None] * ntags
        self._ex_tail = np.zeros((max(self.window - 1, 0), ntags), bool)
        self.stats = DetectorStats(per_tag=[0] * ntags)

    def reset(self) -> None:
        """Samples were lost: forget the moving sums and open runs (the noise stays)."""
        self._hist = self._hist[:0]
        self._clip_hist = self._clip_hist[:0]
        self._peak_hist = self._peak_hist[:0]
        self._runs = [None] * self.ntags
        self._ex_tail = np.zeros((max(self.window - 1, 0), self.ntags), bool)

    def threshold(self) -> NDArray[np.float64]:
        """Current threshold on S per tag (NaN while the noise is not known yet)."""
        return self.noise_bin * self.factor

    def push(self, frames: Frames) -> list[PulseFound]:
        n = frames.energy.shape[0]
        if n == 0:
            return []
        if self._hist.shape[0] and self._hist_first + self._hist.shape[0] != frames.first:
            self.reset()
        if self._hist.shape[0] == 0:
            self._hist_first = frames.first
        hist = np.concatenate((self._hist, frames.energy))
        clip = np.concatenate((self._clip_hist, frames.clipped))
        peak = np.concatenate((self._peak_hist, frames.peak_bin))
        self._noise_frames += n
        recent = hist[-self._noise_len:]
        self.noise_bin = np.median(recent, axis=0) / self._median_k
        out: list[PulseFound] = []
        old = hist.shape[0] - n  # frames already seen
        if self._noise_frames >= self._warmup:
            csum = np.concatenate((np.zeros((1, self.ntags)), np.cumsum(hist, axis=0)))
            lo = np.maximum(np.arange(old, old + n) + 1 - self.window, 0)
            s = csum[old + 1: old + n + 1] - csum[lo]
            full = (np.arange(old, old + n) + 1 - self.window) >= 0
            raw = (s > self.threshold()[None, :]) & full[:, None]
            # a run ends only after a pulse width without an exceedance, so one pulse whose
            # statistic dips under the threshold for a few frames stays one detection
            ext = np.concatenate((self._ex_tail, raw)).astype(np.int32)
            cs = np.concatenate((np.zeros((1, self.ntags), np.int32), np.cumsum(ext, axis=0)))
            f = self.window
            exceed = (cs[f:] - cs[:-f]) > 0
            self._ex_tail = ext[ext.shape[0] - (f - 1):].astype(bool)
            for t in range(self.ntags):
                out.extend(self._runs_of(t, exceed[:, t], s[:, t], old, hist, clip, peak))
        keep = max(0, hist.shape[0] - self._hist_len)
        self._hist, self._clip_hist, self._peak_hist = hist[keep:], clip[keep:], peak[keep:]
        self._hist_first += keep
        return out

    def _runs_of(self, t: int, ex: NDArray[np.bool_], s: NDArray[np.float64], old: int,
                 hist: NDArray[np.float64], clip: NDArray[np.bool_],
                 peak: NDArray[np.int64]) -> list[PulseFound]:
        out: list[PulseFound] = []
        run = self._runs[t]
        if run is None and not ex.any():
            return out
        n = ex.size
        edges = np.diff(np.concatenate(([0], ex.astype(np.int8), [0])))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1) - 1
        if run is not None and (starts.size == 0 or starts[0] != 0):
            out.extend(self._finish(t, run, hist, clip, peak))  # it ended with the last block
            run = None
        for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
            if run is None:
                run = _Run(start=self._hist_first + old + a)
                self.stats.runs += 1
            seg = s[a: b + 1]
            k = int(np.argmax(seg))
            if seg[k] > run.best_s:
                run.best_s, run.best_frame = float(seg[k]), self._hist_first + old + a + k
            run.length += b - a + 1
            if b < n - 1:
                out.extend(self._finish(t, run, hist, clip, peak))
                run = None
        self._runs[t] = run
        return out

    def _finish(self, t: int, run: _Run, hist: NDArray[np.float64], clip: NDArray[np.bool_],
                peak: NDArray[np.int64]) -> list[PulseFound]:
        if run.length > self.max_run:
            self.stats.cw_rejected += 1
            return []
        ch, m = self.ch, self.ch.frame_len
        sigma2 = float(self.noise_bin[t])
        kbins = ch.bins
        energy = max(run.best_s - kbins * self.window * sigma2, 1e-30) / ch.capture
        width_frames = self.cfg.pulse_width_s / ch.frame_s
        power = energy / (self.cfg.pulse_width_s * ch.rate_hz)  # A^2
        noise_band = sigma2 * kbins / m
        snr_db = 10.0 * math.log10(power / noise_band)
        j = run.best_frame - self._hist_first  # index into hist
        lo = max(0, j - self.window - 2)
        frac = (hist[lo: j + 3, t] - kbins * sigma2) / (power * m * ch.capture)
        on = np.flatnonzero(frac > 0.5)
        if snr_db >= self.cfg.gate_snr_db:
            span = (on[-1] - on[0] + 1) if on.size else 0
            a, b = self.cfg.width_gate
            if not a * width_frames - 1.0 <= span <= b * width_frames + 1.0:
                self.stats.width_rejected += 1
                return []
        if on.size:
            first = int(on[0])
            f0 = float(np.clip(frac[first], 0.0, 1.0))
            fprev = float(np.clip(frac[first - 1], 0.0, 1.0)) if first > 0 else 0.0
            start = (self._hist_first + lo + first + 1 - f0 - fprev) * m
        else:
            start = (run.best_frame + 1) * m - self.cfg.pulse_width_s * ch.rate_hz
        w0 = max(0, j - self.window + 1)
        k = w0 + int(np.argmax(hist[w0: j + 1, t]))
        self.stats.pulses += 1
        self.stats.per_tag[t] += 1
        return [PulseFound(t, float(start), power, noise_band, snr_db,
                           float(on.size * ch.frame_s) if on.size else 0.0,
                           float(peak[k, t]) * ch.bin_hz, bool(clip[w0: j + 1].any()))]
