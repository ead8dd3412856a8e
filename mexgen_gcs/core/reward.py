"""The planner's reward: Renyi divergence between the updated and the predicted particle belief,
plus an action cost (paper eq. reward_sum and eq. renyidiv).

Frame: headings are compass radians (0 = north, clockwise), as everywhere in core.

Both beliefs live on the same particles, so the divergence is a function of the weights only::

    Psi(B+, B) = 1 / (alpha - 1) log sum_i w+_i^alpha w_i^(1 - alpha)

computed here on the log scale as the readable reference; the planner evaluates it inside
its compiled update step (``core.rollout_kernels.update_step``), which is tested against
:func:`renyi_divergence`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


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
    that the planner's compiled step is tested against.
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
