"""Statistics for experiment summaries: success with a binomial interval, completion times with
the failed (censored) runs counted, paired differences with their interval.

No frames here. Times are seconds; a run that did not complete within the limit L is right
censored at L (all censoring is at the limit, so the restricted mean min(T, L) needs no
estimator beyond the plain mean). All intervals are two-sided 95 % unless asked otherwise.

- :func:`success_ci`: Wilson score interval (``scipy.stats.binomtest(...).proportion_ci``);
- :func:`km_median`: Kaplan-Meier median time with the interval where the pointwise log-log
  confidence band of the survival function crosses 1/2 (``scipy.stats.ecdf`` on
  ``scipy.stats.CensoredData``); None where it never does within the limit;
- :func:`restricted_mean`: mean of min(T, L) with a t interval (failures count as L);
- :func:`paired_mean`: mean of paired differences with a t interval.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

FloatArray = NDArray[np.float64]
LEVEL = 0.95


@dataclass(frozen=True, slots=True)
class Estimate:
    """A point estimate with its interval (bounds may be None: not reached / undefined)."""

    value: float | None
    low: float | None
    high: float | None

    def text(self, digits: int = 0, beyond: str = "–") -> str:
        """'v [lo, hi]'; an undefined value reads ``beyond`` (e.g. '> 1000' for a median not
        reached), an open upper bound '>', and nothing at all '–'."""
        def f(x: float | None, open_text: str) -> str:
            return open_text if x is None else f"{x:.{digits}f}"
        if self.value is None and self.low is None:
            return beyond
        return f"{f(self.value, beyond)} [{f(self.low, '–')}, {f(self.high, '>')}]"


def success_ci(successes: int, runs: int, level: float = LEVEL) -> Estimate:
    """Success rate with its Wilson score interval."""
    if runs <= 0:
        return Estimate(None, None, None)
    ci = stats.binomtest(successes, runs).proportion_ci(confidence_level=level, method="wilson")
    return Estimate(successes / runs, float(ci.low), float(ci.high))


def km_median(times_s: FloatArray, done: NDArray[np.bool_], limit_s: float,
              level: float = LEVEL) -> Estimate:
    """Kaplan-Meier median completion time of runs (``done`` False: censored at the limit).

    value None when fewer than half complete within the limit (the median is "> limit");
    the interval from the pointwise log-log band of the survival function."""
    t = np.asarray(times_s, dtype=np.float64)
    ok = np.asarray(done, dtype=bool)
    if t.size == 0:
        return Estimate(None, None, None)
    if not ok.any():
        return Estimate(None, None, None)
    data = stats.CensoredData(uncensored=t[ok], right=np.full(int((~ok).sum()), limit_s))
    sf = stats.ecdf(data).sf
    grid = np.unique(np.r_[t[ok], limit_s])
    with warnings.catch_warnings():  # undefined at S = 0 or 1: those points read as NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        band = sf.confidence_interval(level, method="log-log")

    def first_below_half(values: FloatArray) -> float | None:
        below = np.flatnonzero(np.nan_to_num(values, nan=1.0) <= 0.5)
        return float(grid[below[0]]) if below.size and grid[below[0]] <= limit_s else None

    with np.errstate(invalid="ignore", divide="ignore"):
        return Estimate(first_below_half(sf.evaluate(grid)),
                        first_below_half(band.low.evaluate(grid)),
                        first_below_half(band.high.evaluate(grid)))


def survival_curve(times_s: FloatArray, done: NDArray[np.bool_], limit_s: float
                   ) -> tuple[FloatArray, FloatArray]:
    """The Kaplan-Meier fraction of runs not yet complete, as step points (t, S(t)) from 0 to
    the limit (for plots)."""
    t = np.asarray(times_s, dtype=np.float64)
    ok = np.asarray(done, dtype=bool)
    if not ok.any():
        return np.array([0.0, limit_s]), np.array([1.0, 1.0])
    data = stats.CensoredData(uncensored=t[ok], right=np.full(int((~ok).sum()), limit_s))
    sf = stats.ecdf(data).sf
    grid = np.unique(np.r_[0.0, t[ok], limit_s])
    return grid, sf.evaluate(grid)


def restricted_mean(times_s: FloatArray, done: NDArray[np.bool_], limit_s: float,
                    level: float = LEVEL) -> Estimate:
    """Mean of min(T, L) over all runs, a failed run counting as L, with a t interval."""
    r = np.where(np.asarray(done, dtype=bool), np.asarray(times_s, dtype=np.float64), limit_s)
    return _mean_ci(np.minimum(r, limit_s), level)


def paired_mean(differences: FloatArray, level: float = LEVEL) -> Estimate:
    """Mean of paired differences with a t interval (None bounds for fewer than 2 pairs)."""
    return _mean_ci(np.asarray(differences, dtype=np.float64), level)


def _mean_ci(x: FloatArray, level: float) -> Estimate:
    if x.size == 0:
        return Estimate(None, None, None)
    mean = float(x.mean())
    if x.size < 2:
        return Estimate(mean, None, None)
    sd = float(x.std(ddof=1))
    if sd == 0.0:
        return Estimate(mean, mean, mean)
    half = float(stats.t.ppf(0.5 + level / 2.0, x.size - 1)) * sd / math.sqrt(x.size)
    return Estimate(mean, mean - half, mean + half)
