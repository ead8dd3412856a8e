"""Detection thresholds from a false-alarm probability, and the detector's theoretical curve.

The detector's statistic for one tag is the energy of its channel band (K FFT bins) summed over
F frames (the pulse width). Bins of a rectangular-window FFT of white noise are independent, so
in noise alone the statistic divided by the per-bin noise energy is Gamma(K F, 1) distributed.
One test is made per frame, so a false-alarm probability per tag and second ``pfa_per_s`` is
spread over ``tests_per_s`` tests (a union bound: the measured rate can only be lower).

With a pulse of energy E (same units) inside the window the statistic is a non-central
chi-square: 2 S / sigma^2 ~ ncx2(2 K F, 2 E / sigma^2).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import stats


def pfa_per_test(pfa_per_s: float, tests_per_s: float) -> float:
    """The false-alarm probability of one test so that ``tests_per_s`` tests make at most
    ``pfa_per_s`` false alarms per second (exact for independent tests)."""
    if not 0.0 < pfa_per_s < 1.0 or not tests_per_s > 0.0:
        raise ValueError(f"need 0 < pfa_per_s < 1 and tests_per_s > 0, got {pfa_per_s}, "
                         f"{tests_per_s}")
    return -math.expm1(math.log1p(-pfa_per_s) / tests_per_s)


def threshold_factor(dof: int, pfa_test: float) -> float:
    """Threshold over the per-bin noise energy for a Gamma(dof) statistic at ``pfa_test``."""
    return float(stats.gamma.isf(pfa_test, dof))


def pd_theory(snr_energy: NDArray[np.float64] | float, dof: int,
              factor: float) -> NDArray[np.float64]:
    """Probability that noise plus a pulse of ``snr_energy`` (pulse energy over the per-bin
    noise energy) exceeds ``factor`` (threshold over the per-bin noise energy)."""
    e = np.asarray(snr_energy, dtype=float)
    return np.asarray(stats.ncx2.sf(2.0 * factor, 2 * dof, 2.0 * e))


def noise_from_median(median_energy: NDArray[np.float64], bins: int) -> NDArray[np.float64]:
    """Per-bin noise energy from the median of per-frame band energies (Gamma(bins) each)."""
    return median_energy / float(stats.gamma.median(bins))
