"""Weights on the log scale, normalised in one place; resampling and roughening.

Arrays in, arrays out, inputs never mutated; except :func:`resample_roughen`, the filter's
compiled resampling step, which works in place on the rows it is given. Shapes in
docstrings; N = particles. States are ENU metres and m/s (core.motion); nothing here
depends on their frame.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import inline, kernel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
ModeArray = NDArray[np.int8]


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


@inline
def _systematic(cdf: FloatArray, n: int, u: float) -> IntArray:
    """n systematic draws (u + i) / n from the normalised cumulative weights cdf (M,):
    the first index whose cdf exceeds each position (searchsorted right), at most M - 1."""
    m = cdf.shape[0]
    idx = np.empty(n, np.intp)
    j = 0
    for i in range(n):
        pos = (u + i) / n
        while j < m - 1 and cdf[j] <= pos:
            j += 1
        idx[i] = j
    return idx


@inline
def _cumulative_weights(log_w: FloatArray) -> tuple[FloatArray, float]:
    """(normalised cumulative weights (M,), log of the total weight) of log-weights (M,);
    uniform, with log total -inf, if every weight is -inf."""
    m = log_w.shape[0]
    hi = -np.inf
    for i in range(m):
        hi = max(hi, log_w[i])
    cdf = np.empty(m)
    acc = 0.0
    for i in range(m):
        acc += math.exp(log_w[i] - hi) if hi > -np.inf else 1.0
        cdf[i] = acc
    for i in range(m):
        cdf[i] /= acc
    return cdf, hi + math.log(acc) if hi > -np.inf else -np.inf


@kernel
def _systematic_indices(log_w: FloatArray, n: int, u: float) -> IntArray:
    cdf, _ = _cumulative_weights(log_w)
    return _systematic(cdf, n, u)


def systematic_resample(log_w: FloatArray, n: int, rng: np.random.Generator) -> IntArray:
    """Systematic resampling: n indices drawn in proportion to exp(log_w) (N,). O(N + n)."""
    return _systematic_indices(np.ascontiguousarray(log_w, dtype=np.float64), n, rng.random())


@kernel
def resample_roughen(log_w: FloatArray, states: FloatArray, modes: ModeArray,
                     belief_mean: FloatArray, belief_cov: FloatArray, k: float, dims: int,
                     rng: np.random.Generator) -> float:
    """Systematic resampling of M particles in place (rows of ``states`` (M, D), ``modes``
    (M,) and, unless they have no rows, ``belief_mean`` (M, 2) and ``belief_cov`` (M, 3)),
    then roughening of the first ``dims`` state columns, those the motion model moves
    (Gordon et al. 1993): Gaussian jitter per dimension with std k * range_d * M^(-1/D), D the
    state's width, where the resampled states spread; dimensions with no spread stay, and the
    columns from ``dims`` on (a static or random-walk tag's zero velocity) are neither
    touched nor drawn for. The bandwidth keeps D, not ``dims``: roughening_k is tuned with
    it (with M^(-1/2) a static tag's jitter is 7x smaller at M = 2000, and the robust
    estimator no longer holds against 5 % outliers, tests/core/test_radio_belief.py). Draws:
    one uniform, then the (M, dims) jitter row by row. Returns the log of the total weight of
    log_w (M,) (-inf if every weight is -inf: then resampled uniformly)."""
    m, width = states.shape
    d = min(dims, width)
    cdf, log_mass = _cumulative_weights(log_w)
    idx = _systematic(cdf, m, rng.random())
    old_states = states.copy()
    old_modes = modes.copy()
    old_mean = belief_mean.copy()
    old_cov = belief_cov.copy()
    for i in range(m):
        states[i, :] = old_states[idx[i], :]
        modes[i] = old_modes[idx[i]]
        if belief_mean.shape[0]:
            belief_mean[i, :] = old_mean[idx[i], :]
            belief_cov[i, :] = old_cov[idx[i], :]
    if k <= 0.0 or m < 2:
        return log_mass
    sigma = np.empty(d)
    for c in range(d):
        lo = states[0, c]
        hi = states[0, c]
        for i in range(m):
            lo = min(lo, states[i, c])
            hi = max(hi, states[i, c])
        sigma[c] = k * (hi - lo) * m ** (-1.0 / width)
    for i in range(m):
        for c in range(d):
            states[i, c] += rng.standard_normal() * sigma[c]
    return log_mass
