"""Weights on the log scale, normalised in one place; resampling and roughening.

Arrays in, arrays out; inputs are never mutated. Shapes in docstrings; N = particles.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def logsumexp(x: FloatArray, axis: int = -1, keepdims: bool = False) -> FloatArray:
    """log(sum(exp(x))) along axis, stable; -inf where every entry is -inf.

    Plain numpy: scipy.special.logsumexp costs ~0.1 ms a call in array-API overhead, which is
    most of a filter update at N = 1000.
    """
    m = np.max(x, axis=axis, keepdims=True)
    m_safe = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(x - m_safe), axis=axis, keepdims=True)) + m_safe
    return out if keepdims else np.squeeze(out, axis=axis)


def normalise_log_weights(log_w: FloatArray) -> tuple[FloatArray, float]:
    """(..., N) log-weights -> (normalised log-weights, log of the total per leading index).

    The one place weights are normalised. If every weight is -inf or not finite (total
    underflow or a NaN), the weights are reset to uniform and the returned log-total is -inf,
    so callers can tell and nothing downstream sees a NaN.
    """
    total = logsumexp(log_w, axis=-1, keepdims=True)
    bad = ~np.isfinite(total)
    out = log_w - np.where(bad, 0.0, total)
    if np.any(bad):
        n = log_w.shape[-1]
        out = np.where(bad, -np.log(n), out)
    if np.ndim(total) > 1:
        return out, np.squeeze(total, axis=-1)  # type: ignore[return-value]  # batch form
    return out, float(total[0])


def effective_sample_size(log_w: FloatArray) -> float:
    """1 / sum(w^2) for normalised log-weights (N,); in [1, N]."""
    return float(1.0 / np.exp(logsumexp(2.0 * log_w)))


def systematic_resample(log_w: FloatArray, n: int, rng: np.random.Generator) -> IntArray:
    """Systematic resampling: n indices drawn in proportion to exp(log_w) (N,). O(N + n)."""
    w = np.exp(log_w - log_w.max())
    cdf = np.cumsum(w)
    cdf /= cdf[-1]
    positions = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(cdf, positions, side="right"), len(w) - 1)


def roughen(
    states: FloatArray, k: float, rng: np.random.Generator
) -> FloatArray:
    """Regularisation after resampling (Gordon et al. 1993): Gaussian jitter per dimension
    with std k * range_d * N^(-1/D). (N, D) -> new (N, D); dimensions with zero spread stay.
    """
    n, d = states.shape
    if k <= 0.0 or n < 2:
        return states.copy()
    spread = states.max(axis=0) - states.min(axis=0)
    sigma = k * spread * n ** (-1.0 / d)
    return states + rng.normal(size=states.shape) * sigma
