"""The tuning plan: one centre frequency and sample rate that cover all of a mission's tags.

The centre sits between the tags, moved off any tag by at least ``dc_guard_hz`` plus half a
channel (RTL-SDR and most direct-conversion tuners have a spur and 1/f noise at DC). The
usable band is the central ``USABLE_FRACTION`` of the sample rate (the anti-alias filter rolls
off at the edges). A tunable source gets the smallest sample rate of ``RATES_HZ`` (the
RTL-SDR's reliable ones) that covers the tags; a fixed source (a recording) is checked, and a
tag outside its band is refused with a message naming the tag and its frequency.

The ppm correction is a property of the device's crystal: sources that can set it on the
hardware (rtl_tcp, pyrtlsdr) get it there; the others (recordings) have it applied here, by
moving each tag's channel to where the uncorrected crystal puts it.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

from mexgen_gcs.errors import MexgenError

USABLE_FRACTION = 0.8
#: RTL-SDR sample rates that run without dropped samples (225-300 k and 0.9-3.2 M are valid).
RATES_HZ: tuple[float, ...] = (250_000.0, 960_000.0, 1_024_000.0, 1_200_000.0, 1_440_000.0,
                               1_800_000.0, 1_920_000.0, 2_048_000.0, 2_400_000.0)


class TuningError(MexgenError):
    """The tags cannot be covered by the source's band."""


@dataclass(frozen=True, slots=True)
class TagChannel:
    id: str
    freq_hz: float
    offset_hz: float
    """Where the tag appears in the baseband, Hz from the centre (after the ppm correction)."""


@dataclass(frozen=True, slots=True)
class TuningPlan:
    centre_hz: float
    rate_hz: float
    channel_width_hz: float
    ppm: float
    ppm_in_software: bool
    channels: tuple[TagChannel, ...]

    def describe(self) -> str:
        tags = ", ".join(f"{c.id} {c.freq_hz / 1e6:.4f} MHz ({c.offset_hz / 1e3:+.1f} kHz)"
                         for c in self.channels)
        return (f"centre {self.centre_hz / 1e6:.4f} MHz, {self.rate_hz / 1e3:g} ksps, "
                f"channels {self.channel_width_hz:g} Hz wide, ppm {self.ppm:+g}"
                f"{' (applied in software)' if self.ppm_in_software else ''}: {tags}")


def plan_tuning(tags: Sequence[tuple[str, float]], *, channel_width_hz: float = 3000.0,
                dc_guard_hz: float = 5000.0, ppm: float = 0.0, rate_hz: float | None = None,
                centre_hz: float | None = None, ppm_in_software: bool = False) -> TuningPlan:
    """A plan for ``tags`` [(id, freq_hz)]. ``rate_hz``/``centre_hz`` fixed by the source (a
    recording), else chosen. Raises TuningError naming the tag that does not fit."""
    if not tags:
        raise TuningError("no tags to listen for")
    freqs = sorted(f for _, f in tags)
    half_ch = channel_width_hz / 2.0
    if centre_hz is None:
        centre_hz = _centre(freqs, dc_guard_hz + half_ch)
    if rate_hz is None:
        need = 2.0 * max(abs(f - centre_hz) + half_ch for f in freqs) / USABLE_FRACTION
        fitting = [r for r in RATES_HZ if r >= need]
        if not fitting:
            lo_tag = min(tags, key=lambda t: t[1])
            hi_tag = max(tags, key=lambda t: t[1])
            raise TuningError(
                f"tag {hi_tag[0]} at {hi_tag[1] / 1e6:.4f} MHz and tag {lo_tag[0]} at "
                f"{lo_tag[1] / 1e6:.4f} MHz are {(hi_tag[1] - lo_tag[1]) / 1e3:.0f} kHz apart: "
                f"more than the widest rate {RATES_HZ[-1] / 1e6:g} Msps covers")
        rate_hz = fitting[0]
    edge = USABLE_FRACTION * rate_hz / 2.0
    channels = []
    for tid, f in tags:
        offset = f - centre_hz
        if ppm_in_software:
            offset -= centre_hz * ppm * 1e-6  # the LO sits at centre (1 + ppm 1e-6)
        if abs(offset) + half_ch > edge:
            raise TuningError(
                f"tag {tid} at {f / 1e6:.4f} MHz is outside the usable band "
                f"{(centre_hz - edge) / 1e6:.4f}-{(centre_hz + edge) / 1e6:.4f} MHz of a "
                f"{rate_hz / 1e3:g} ksps capture centred at {centre_hz / 1e6:.4f} MHz")
        if abs(offset) < half_ch + 0.5 * dc_guard_hz:
            raise TuningError(f"tag {tid} at {f / 1e6:.4f} MHz sits on the DC spur of a capture "
                              f"centred at {centre_hz / 1e6:.4f} MHz")
        channels.append(TagChannel(tid, float(f), float(offset)))
    return TuningPlan(float(centre_hz), float(rate_hz), channel_width_hz, ppm, ppm_in_software,
                      tuple(channels))


def _centre(freqs: list[float], guard_hz: float) -> float:
    """The middle of the tags, moved into the widest gap near it if a tag is too close."""
    mid = 0.5 * (freqs[0] + freqs[-1])
    if all(abs(f - mid) >= guard_hz for f in freqs):
        return round(mid)
    if len(freqs) == 1:
        return round(freqs[0] + 2.0 * guard_hz)
    gaps = [(b - a, 0.5 * (a + b)) for a, b in itertools.pairwise(freqs)
            if b - a >= 2.0 * guard_hz]
    if gaps:
        return round(min(gaps, key=lambda g: abs(g[1] - mid))[1])
    return round(freqs[-1] + guard_hz)
