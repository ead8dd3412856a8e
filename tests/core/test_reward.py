"""Renyi divergence reward and the action (turn) cost."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.reward import logsumexp, renyi_divergence, renyi_gain, turn_cost


def test_divergence_of_equal_beliefs_is_zero():
    log_w = np.log(np.random.default_rng(0).dirichlet(np.ones(30), size=4))
    np.testing.assert_allclose(renyi_divergence(log_w, log_w, 0.1), 0.0, atol=1e-12)
    np.testing.assert_allclose(
        renyi_gain(log_w.astype(np.float32), log_w.astype(np.float32), 0.1), 0.0, atol=1e-6
    )


@pytest.mark.parametrize("alpha", [0.1, 0.5, 0.9, 2.0])
def test_collapse_onto_one_of_two_equal_particles_gains_log_2(alpha):
    """Prior (1/2, 1/2), posterior (1, 0): sum w+^a w^(1-a) = 2^(a-1), so Psi = log 2."""
    prior = np.log([0.5, 0.5])
    post = np.array([0.0, -np.inf])
    assert renyi_divergence(post, prior, alpha) == pytest.approx(math.log(2.0))
    assert renyi_gain(post.astype(np.float32), prior.astype(np.float32), alpha) == pytest.approx(
        math.log(2.0), rel=1e-5
    )


@pytest.mark.parametrize("alpha", [0.1, 0.5, 0.9, 2.0])
def test_fast_gain_matches_the_reference_with_row_totals(alpha):
    rng = np.random.default_rng(1)
    prior = np.log(rng.dirichlet(np.ones(200) * 0.3, size=(3, 5)))
    post = prior + rng.normal(0.0, 2.0, prior.shape)
    expected = renyi_divergence(post, prior, alpha)
    # the rollout hands over max-shifted log-weights and their log totals
    post_shift = (post - post.max(-1, keepdims=True)).astype(np.float32)
    prior_shift = (prior - prior.max(-1, keepdims=True)).astype(np.float32)
    got = renyi_gain(post_shift, prior_shift, alpha,
                     post_log_total=logsumexp(post_shift), prior_log_total=logsumexp(prior_shift))
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-6)
    scratch = np.empty_like(post_shift)
    again = renyi_gain(post_shift, prior_shift, alpha, scratch,
                       logsumexp(post_shift), logsumexp(prior_shift))
    np.testing.assert_array_equal(got, again)


def test_fast_gain_underflow_rows_are_redone_exactly():
    """The posterior sits on a particle whose prior weight is e^-300: no exp underflow to 0."""
    prior = np.zeros(10, np.float32)
    prior[3] = -300.0
    post = np.full(10, -np.inf, np.float32)
    post[3] = 0.0
    total = float(logsumexp(prior))
    expected = renyi_divergence(post.astype(np.float64), prior.astype(np.float64), 0.1)
    got = renyi_gain(post[None], prior[None], 0.1, prior_log_total=total)
    assert np.isfinite(got).all()
    assert got[0] == pytest.approx(expected, rel=1e-6)
    assert expected == pytest.approx(300.0 + total, rel=1e-3)  # ~ -log w_prior(3)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 60),
    alpha=st.sampled_from([0.05, 0.1, 0.3, 0.7, 0.95]),
    scale=st.floats(0.0, 50.0),
)
def test_gain_is_non_negative_finite_and_matches_reference(seed, n, alpha, scale):
    rng = np.random.default_rng(seed)
    prior = np.log(rng.dirichlet(np.ones(n)))
    post = prior + scale * rng.normal(size=n)
    post -= logsumexp(post)
    got = renyi_gain(post.astype(np.float32)[None], prior.astype(np.float32)[None], alpha)
    ref = renyi_divergence(post[None], prior[None], alpha)
    assert np.isfinite(got).all() and got[0] >= 0.0
    assert got[0] == pytest.approx(ref[0], rel=1e-3, abs=1e-5)


def test_bad_alpha():
    for alpha in (0.0, 1.0, -0.5, math.nan):
        with pytest.raises(ValueError):
            renyi_divergence(np.zeros(2), np.zeros(2), alpha)


def test_turn_cost():
    h = np.radians([0.0, 90.0, 180.0, 270.0, 10.0])
    np.testing.assert_allclose(turn_cost(h, 0.0), [0.0, 0.5, 1.0, 0.5, 10 / 180])
    # wraps across north: 350 deg -> 10 deg is a 20 deg turn
    assert turn_cost(np.radians([10.0]), math.radians(350.0))[0] == pytest.approx(20 / 180)
