"""The planner's reward: Renyi divergence between the updated and the predicted particle belief,
plus an action cost (paper eq. reward_sum and eq. renyidiv).

Frame: headings are compass radians (0 = north, clockwise), as everywhere in core.

Both beliefs live on the same particles, so the divergence is a function of the weights only::

    Psi(B+, B) = 1 / (alpha - 1) log sum_i w+_i^alpha w_i^(1 - alpha)

computed on the log scale from the normalised log-weights before and after the update
(``likelihood.bayes_update``, the one place the planner normalises weights).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]


def logsumexp(x: NDArray[np.floating], axis: int = -1) -> FloatArray:
    """Stable log(sum(exp(x))) along ``axis`` in float64; -inf where every entry is -inf."""
    x = np.asarray(x, dtype=np.float64)
    m = np.max(x, axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return np.squeeze(np.log(np.sum(np.exp(x - m), axis=axis, keepdims=True)) + m, axis=axis)


def renyi_divergence(
    log_w_post: NDArray[np.floating], log_w_prior: NDArray[np.floating], alpha: float
) -> FloatArray:
    """Reference Renyi divergence of order alpha between two weightings of the same particles.

    log_w_post, log_w_prior: (..., N) log-weights (normalised here). Returns (...) float64 >= 0
    (0 when the two are equal). alpha > 0, alpha != 1. O(N) per row; the readable definition
    that :func:`renyi_gain` is tested against.
    """
    _check_alpha(alpha)
    post = np.asarray(log_w_post, np.float64)
    prior = np.asarray(log_w_prior, np.float64)
    post = post - logsumexp(post)[..., None]
    prior = prior - logsumexp(prior)[..., None]
    with np.errstate(invalid="ignore"):
        mixed = np.where(np.isneginf(post) | np.isneginf(prior), -np.inf,
                         alpha * post + (1.0 - alpha) * prior)
    return np.maximum(logsumexp(mixed) / (alpha - 1.0), 0.0)


def renyi_gain(
    log_w_post: Float32Array,
    log_w_prior: Float32Array,
    alpha: float,
    scratch: Float32Array | None = None,
    post_log_total: FloatArray | float = 0.0,
    prior_log_total: FloatArray | float = 0.0,
) -> FloatArray:
    """Renyi divergence (order alpha) of the updated from the predicted belief, fast path.

    log_w_post, log_w_prior: (B..., N) float32 log-weights with every entry <= 0 (normalised,
    or max-shifted as ``likelihood.bayes_update`` leaves them) whose rows sum, in linear
    scale, to exp(``*_log_total``) (B...) (0 = normalised); entries may be -inf. Returns
    (B...) float64 >= 0. One exp and 4 other passes: for alpha < 1 the exponent
    ``alpha log w+ + (1 - alpha) log w`` is <= 0, so a log-sum-exp needs no max pass; rows
    where it underflows (possible only if the posterior sits on particles whose prior weight is
    below ~e^-70 of the largest) are redone exactly in float64. ``scratch``: an optional
    (B..., N) float32 buffer, so that a rollout allocates nothing per step.
    """
    _check_alpha(alpha)
    if alpha > 1.0:  # the exponent can be positive: take the exact path
        post = np.asarray(log_w_post, np.float64) - np.asarray(post_log_total)[..., None]
        prior = np.asarray(log_w_prior, np.float64) - np.asarray(prior_log_total)[..., None]
        return renyi_divergence(post, prior, alpha)
    b = np.multiply(log_w_prior, np.float32((1.0 - alpha) / alpha), out=scratch)
    b += log_w_post
    b *= np.float32(alpha)
    np.exp(b, out=b)
    mix = np.asarray(b.sum(axis=-1, dtype=np.float32), dtype=np.float64)
    if mix.min(initial=1.0) < 1e-30:
        under = mix < 1e-30
        exact = alpha * log_w_post[under].astype(np.float64) + (1.0 - alpha) * log_w_prior[under]
        log_mix = np.log(np.where(under, 1.0, mix))
        log_mix[under] = logsumexp(exact)
    else:
        log_mix = np.log(mix)
    log_mix -= alpha * np.asarray(post_log_total) + (1.0 - alpha) * np.asarray(prior_log_total)
    log_mix *= 1.0 / (alpha - 1.0)
    return np.maximum(log_mix, 0.0)


def turn_cost(headings_rad: FloatArray, course_rad: float) -> FloatArray:
    """Action cost of turning from the current course: |heading - course| / pi in [0, 1], (A,).

    The paper's r(B, u) term; the planner charges ``action_cost_weight * turn_cost`` once, at
    the first look-ahead step (a held heading only turns once).
    """
    d = np.abs((np.asarray(headings_rad) - course_rad + math.pi) % (2.0 * math.pi) - math.pi)
    return d / math.pi


def _check_alpha(alpha: float) -> None:
    if not (alpha > 0.0 and alpha != 1.0 and math.isfinite(alpha)):
        raise ValueError(f"the Renyi order alpha must be > 0 and != 1 (got {alpha})")
