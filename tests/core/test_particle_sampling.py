"""Particle index samplers: right distribution, zero weights never drawn, every shape."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.particle_sampling import (
    iid_indices,
    row_cdf,
    stratified_counts,
    stratified_indices,
)

SAMPLERS = [stratified_indices, iid_indices]


def _weights(rng: np.random.Generator, rows: int, n: int) -> np.ndarray:
    w = rng.random((rows, n)) ** 6  # very uneven
    w[:, rng.random(n) < 0.3] = 0.0  # and some exact zeros
    w[:, 0] += 1e-3  # every row keeps a positive sum
    return w


@pytest.mark.parametrize("sampler", SAMPLERS)
@pytest.mark.parametrize("n", [1, 7, 16, 1000, 1003])
def test_draw_frequencies_match_weights(sampler, n):
    rng = np.random.default_rng(n)
    w = _weights(rng, 3, n)
    draws = 60_000
    idx = sampler(w, draws, rng)
    assert idx.shape == (3, draws) and idx.dtype.kind == "i"
    for r in range(3):
        p = w[r] / w[r].sum()
        freq = np.bincount(idx[r], minlength=n) / draws
        assert np.all(freq[p == 0.0] == 0.0), "a zero-weight particle was drawn"
        # binomial standard error (iid; stratified is tighter), plus slack for tiny p
        se = np.sqrt(p * (1 - p) / draws)
        assert np.all(np.abs(freq - p) <= 5 * se + 3.0 / draws)


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_batch_shape_scale_invariance_and_no_mutation(sampler):
    rng = np.random.default_rng(1)
    w = rng.random((2, 3, 4, 50)).astype(np.float32)
    before = w.copy()
    a = sampler(w, 5, np.random.default_rng(7))
    b = sampler(w * 9.0, 5, np.random.default_rng(7))
    assert a.shape == (2, 3, 4, 5)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(w, before)
    assert a.min() >= 0 and a.max() < 50


def test_one_particle_with_all_the_weight_is_always_drawn():
    w = np.zeros((4, 100))
    w[np.arange(4), [0, 17, 63, 99]] = 1.0
    rng = np.random.default_rng(0)
    for sampler in SAMPLERS:
        idx = sampler(w, 64, rng)
        assert np.all(idx == np.array([0, 17, 63, 99])[:, None])


def test_stratified_draws_are_sorted_and_have_lower_variance_than_iid():
    rng = np.random.default_rng(3)
    n, m, reps = 200, 32, 2000
    w = rng.random(n)
    h = rng.normal(0.0, 5.0, n)
    w_rows = np.broadcast_to(w, (reps, n))
    s = stratified_indices(w_rows, m, rng)
    i = iid_indices(w_rows, m, rng)
    assert np.all(np.diff(s, axis=-1) >= 0)
    exact = np.sum(w * h) / w.sum()
    # both unbiased; stratification reduces the variance of the sample mean
    assert abs(h[s].mean() - exact) < 0.1 and abs(h[i].mean() - exact) < 0.1
    assert h[s].mean(axis=-1).var() < h[i].mean(axis=-1).var()


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 300),
    draws=st.integers(1, 600),
    total=st.floats(0.0, 1.0),
)
def test_stratified_counts_respect_the_implicit_none_outcome(seed, n, draws, total):
    rng = np.random.default_rng(seed)
    mass = rng.random((2, n))
    mass *= total / mass.sum(axis=-1, keepdims=True)
    counts = stratified_counts(mass, draws, rng)
    assert counts.shape == (2, n) and np.all(counts >= 0)
    # stratified: the number of particle draws is within 1 of its expectation
    assert np.all(np.abs(counts.sum(axis=-1) - draws * total) <= 1.0 + 1e-6 * draws)


def test_row_cdf_matches_cumsum():
    rng = np.random.default_rng(5)
    for n in (3, 16, 100, 1001):
        w = rng.random((4, n))
        np.testing.assert_allclose(row_cdf(w, normalise=False), np.cumsum(w, axis=-1),
                                   rtol=1e-5)
        cdf = row_cdf(w)
        assert np.all(cdf[:, -1] == 1.0)


def test_bad_arguments():
    with pytest.raises(ValueError):
        stratified_indices(np.ones((2, 0)), 3, np.random.default_rng(0))
    with pytest.raises(ValueError):
        iid_indices(np.ones(4), 0, np.random.default_rng(0))
