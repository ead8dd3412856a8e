"""The detector against theory on synthetic IQ: ``python -m mexgen_gcs.receiver.study``.

Eight tags 20 kHz apart in a 250 ksps capture, white complex Gaussian noise, rectangular
pulses of 20 ms at random sample offsets and within +-200 Hz of the channel centre; the whole
receiver (FFT channels, noise estimate, threshold, runs, gates, power) runs on them. SNR is
the pulse's power over the noise power in the tag's channel (K bins, about 3 kHz).

- ``pd_curve``: probability of detection against SNR at the chosen false-alarm rate, and the
  detector's theoretical curve (the non-central chi-square of `threshold.pd_theory` with the
  pulse's whole energy in one window; misalignment and leakage are what the measured curve
  loses against it);
- ``false_alarms``: detections per tag-hour in noise alone, and with CW interferers (a steady
  carrier in one channel, one keyed on for 3 s of every 10 s in another), with exact Poisson
  95 % intervals;
- ``power_bias``: the calibrated power's bias and spread against SNR.

Every draw takes a Generator seeded from ``seed``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import optimize, stats

from mexgen_gcs.receiver import synth
from mexgen_gcs.receiver.calibration import Calibration
from mexgen_gcs.receiver.detector import DetectorConfig
from mexgen_gcs.receiver.pipeline import Pulse, PulseReceiver
from mexgen_gcs.receiver.sources import IQBlock
from mexgen_gcs.receiver.threshold import pd_theory
from mexgen_gcs.receiver.tuning import plan_tuning

RATE_HZ = 250_000.0
TAGS = [(f"S{i}", 150_030_000.0 + 20_000.0 * i) for i in range(8)]
NOISE_FS = 1e-2
WIDTH_S = 0.02
BLOCK_S = 0.5


def _receiver(pfa_per_s: float) -> PulseReceiver:
    plan = plan_tuning(TAGS, rate_hz=RATE_HZ, centre_hz=150_100_000.0)
    return PulseReceiver(plan, DetectorConfig(pulse_width_s=WIDTH_S, pfa_per_s=pfa_per_s),
                         Calibration(), start_unix=0.0)


def _band_noise(rx: PulseReceiver) -> float:
    return NOISE_FS * rx.channels.bins / rx.channels.frame_len


def _run(rx: PulseReceiver, seconds: float, pulses: list[tuple[float, float, float, float]],
         tones: list[tuple[float, float, float, float | None]], rng: np.random.Generator
         ) -> list[Pulse]:
    block = round(BLOCK_S * RATE_HZ)
    out: list[Pulse] = []
    for first in range(0, round(seconds * RATE_HZ), block):
        x = synth.pulse_train(first, block, RATE_HZ, NOISE_FS, pulses, rng, tones)
        clipped = np.zeros(block, bool)
        out += [e for e in rx.process(IQBlock(x, clipped, b"", "cf32")) if isinstance(e, Pulse)]
    return out


def _schedule(rx: PulseReceiver, snr_db: float, count: int, rng: np.random.Generator,
              warmup_s: float = 1.0, spacing_s: float = 0.25) -> tuple[list[Any], float]:
    """``count`` pulses per tag, ``spacing_s`` apart with random offsets; (pulses, seconds)."""
    power = _band_noise(rx) * 10 ** (snr_db / 10)
    pulses = []
    for i, ch in enumerate(rx.plan.channels):
        starts = warmup_s + spacing_s * np.arange(count) + rng.uniform(0, 0.1, count) + 0.01 * i
        df = rng.uniform(-200.0, 200.0, count)
        pulses += [(s * RATE_HZ, WIDTH_S * RATE_HZ, power, ch.offset_hz + f)
                   for s, f in zip(starts, df, strict=True)]
    return pulses, warmup_s + spacing_s * count + 0.5


def _matched(found: list[Pulse], pulses: list[Any], rx: PulseReceiver) -> list[tuple[Pulse,
                                                                                    Any]]:
    """Each found pulse with the true pulse it belongs to (same tag, within a pulse width)."""
    offsets = {c.id: c.offset_hz for c in rx.plan.channels}
    out = []
    for p in found:
        for q in pulses:
            if abs(q[3] - offsets[p.tag]) < 1000 and abs(p.sample - q[0]) < WIDTH_S * RATE_HZ:
                out.append((p, q))
                break
    return out


def pd_curve(snrs_db: Sequence[float], pulses_per_tag: int, pfa_per_s: float = 1e-3,
             seed: int = 0) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    rows = []
    rx0 = _receiver(pfa_per_s)
    det = rx0.detector
    ch = rx0.channels
    frames = WIDTH_S / ch.frame_s
    for snr in snrs_db:
        rx = _receiver(pfa_per_s)
        pulses, seconds = _schedule(rx, snr, pulses_per_tag, rng)
        found = _run(rx, seconds, pulses, [], rng)
        hits = len({id(q) for _, q in _matched(found, pulses, rx)})
        energy = 10 ** (snr / 10) * ch.bins * frames * ch.capture
        rows.append({"snr_db": snr, "pulses": len(pulses), "detected": hits,
                     "pd": hits / len(pulses),
                     "pd_theory": float(pd_theory(energy, det.dof, det.factor))})
    return {"rows": rows, "snr50_theory_db": _snr_at(0.5, det.dof, det.factor, ch.bins * frames
                                                     * ch.capture),
            "snr50_measured_db": _interp_snr(rows, 0.5), "pfa_per_s": pfa_per_s,
            "dof": det.dof, "threshold_factor": det.factor, "bins": ch.bins,
            "window_frames": det.window}


def _snr_at(pd: float, dof: int, factor: float, scale: float) -> float:
    e = optimize.brentq(lambda e: float(pd_theory(e, dof, factor)) - pd, 1e-3, 1e5)
    return 10 * math.log10(e / scale)


def _interp_snr(rows: list[dict[str, Any]], pd: float) -> float:
    snr = np.array([r["snr_db"] for r in rows])
    p = np.maximum.accumulate(np.array([r["pd"] for r in rows]))
    return float(np.interp(pd, p + 1e-9 * np.arange(p.size), snr))


def false_alarms(seconds: float, pfa_per_s: float = 1e-3, cw: bool = False,
                 seed: int = 1) -> dict[str, Any]:
    """Detections in noise alone (and with CW interferers) over ``seconds`` x 8 tags."""
    rng = np.random.default_rng(seed)
    rx = _receiver(pfa_per_s)
    tones: list[tuple[float, float, float, float | None]] = []
    if cw:
        cw_power = _band_noise(rx) * 10.0  # 10 dB over the channel's noise
        steady = rx.plan.channels[0].offset_hz + 300.0
        keyed = rx.plan.channels[1].offset_hz - 400.0
        tones.append((cw_power, steady, 0.0, None))
        for on in np.arange(2.0, seconds, 10.0):
            tones.append((cw_power, keyed, on * RATE_HZ, (on + 3.0) * RATE_HZ))
    found = _run(rx, seconds, [], tones, rng)
    tag_s = seconds * len(TAGS)
    n = len(found)
    lo = stats.chi2.ppf(0.025, 2 * n) / 2 if n else 0.0
    hi = stats.chi2.ppf(0.975, 2 * n + 2) / 2
    per_h = 3600.0 / tag_s
    return {"cw": cw, "tag_seconds": tag_s, "false_alarms": n, "per_tag_hour": n * per_h,
            "ci95_per_tag_hour": (lo * per_h, hi * per_h), "target_per_tag_hour":
            pfa_per_s * 3600.0, "cw_rejected": rx.detector.stats.cw_rejected,
            "by_tag": {t: sum(1 for p in found if p.tag == t) for t, _ in TAGS}}


def power_bias(snrs_db: Sequence[float], pulses_per_tag: int, seed: int = 2) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    rows = []
    for snr in snrs_db:
        rx = _receiver(1e-3)
        pulses, seconds = _schedule(rx, snr, pulses_per_tag, rng)
        found = _run(rx, seconds, pulses, [], rng)
        err = np.array([p.rssi_dbm - 10 * math.log10(q[2]) for p, q in
                        _matched(found, pulses, rx)])
        rows.append({"snr_db": snr, "n": int(err.size), "bias_db": float(err.mean()),
                     "std_db": float(err.std(ddof=1)) if err.size > 1 else math.nan})
    return {"rows": rows}


def study(quick: bool = False) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
    """The three measurements: Pd against SNR, false alarms (noise, CW), power bias."""
    n = 12 if quick else 50
    pd = pd_curve([float(v) for v in np.arange(-4.0, 8.1, 1.0)], n)
    fa_s = 100.0 if quick else 1800.0
    fa = [false_alarms(fa_s), false_alarms(fa_s, cw=True)]
    pb = power_bias([4.0, 6.0, 10.0, 15.0, 20.0, 30.0], n)
    return pd, fa, pb


def plot(pd: dict[str, Any], pb: dict[str, Any], path: str) -> None:
    """Pd measured against the detector's theory, and the power error against SNR (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    snr = [r["snr_db"] for r in pd["rows"]]
    ax1.plot(snr, [r["pd_theory"] for r in pd["rows"]], "-",
             label="theory (whole pulse in a window)")
    ax1.plot(snr, [r["pd"] for r in pd["rows"]], "o", label="measured")
    ax1.set(xlabel="SNR in the tag's channel (dB)", ylabel="probability of detection",
            title=f"Pd at {pd['pfa_per_s']:g} false alarms per tag-second")
    ax1.grid(True, alpha=0.3)
    ax1.legend()
    rows = pb["rows"]
    ax2.errorbar([r["snr_db"] for r in rows], [r["bias_db"] for r in rows],
                 yerr=[r["std_db"] for r in rows], fmt="o", capsize=3)
    ax2.axhline(0.0, color="grey", lw=0.8)
    ax2.set(xlabel="SNR in the tag's channel (dB)", ylabel="power error (dB): mean +- spread",
            title="Calibrated power against the truth")
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def report(quick: bool = False, plot_path: str | None = None) -> str:
    pd, fa, pb = study(quick)
    if plot_path is not None:
        plot(pd, pb, plot_path)
    lines = [f"Detector: {pd['bins']} bins x {pd['window_frames']} frames ({pd['dof']} degrees "
             f"of freedom), threshold {pd['threshold_factor']:.1f} x the per-bin noise at "
             f"{pd['pfa_per_s']:g} false alarms per tag-second.", "",
             "| SNR in channel (dB) | pulses | detected | Pd measured | Pd theory |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['snr_db']:+.0f} | {r['pulses']} | {r['detected']} | {r['pd']:.3f} | "
              f"{r['pd_theory']:.3f} |" for r in pd["rows"]]
    lines += ["", f"SNR at Pd 0.5: measured {pd['snr50_measured_db']:+.2f} dB, theory "
              f"{pd['snr50_theory_db']:+.2f} dB "
              f"(difference {pd['snr50_measured_db'] - pd['snr50_theory_db']:+.2f} dB).", "",
              "| interference | tag-hours | false alarms | per tag-hour | 95 % interval | "
              "target | CW runs rejected |", "|---|---|---|---|---|---|---|"]
    for f in fa:
        lo, hi = f["ci95_per_tag_hour"]
        lines.append(f"| {'CW (steady + keyed)' if f['cw'] else 'noise alone'} | "
                     f"{f['tag_seconds'] / 3600:.2f} | {f['false_alarms']} | "
                     f"{f['per_tag_hour']:.2f} | {lo:.2f}-{hi:.2f} | "
                     f"<= {f['target_per_tag_hour']:.1f} | {f['cw_rejected']} |")
    lines += ["", "| SNR in channel (dB) | pulses measured | power bias (dB) | spread (dB) |",
              "|---|---|---|---|"]
    lines += [f"| {r['snr_db']:+.0f} | {r['n']} | {r['bias_db']:+.2f} | {r['std_db']:.2f} |"
              for r in pb["rows"]]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m mexgen_gcs.receiver.study")
    p.add_argument("--quick", action="store_true", help="fewer pulses and seconds")
    p.add_argument("--plot", metavar="PNG", default=None,
                   help="also draw Pd against SNR (with theory) and the power error to this PNG")
    args = p.parse_args(argv)
    print(report(args.quick, args.plot))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
