"""Resampling kernels against the numpy statement of systematic resampling and roughening,
drawing the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.resampling import resample_roughen, systematic_resample


def _reference_indices(log_w: np.ndarray, n: int, u: float) -> np.ndarray:
    w = np.exp(log_w - log_w.max())
    cdf = np.cumsum(w) / w.sum()
    return np.minimum(np.searchsorted(cdf, (u + np.arange(n)) / n, side="right"), len(w) - 1)


@pytest.mark.parametrize("n", [1, 7, 1000, 2500])
def test_systematic_resample_is_searchsorted_on_the_cdf(n: int) -> None:
    log_w = np.random.default_rng(n).normal(0.0, 3.0, 1000)
    log_w[::7] = -np.inf
    ours = systematic_resample(log_w, n, np.random.default_rng(1))
    ref = _reference_indices(log_w, n, np.random.default_rng(1).random())
    np.testing.assert_array_equal(ours, ref)


@pytest.mark.parametrize("k", [0.0, 0.2])
def test_resample_roughen_gathers_and_jitters_as_numpy_would(k: float) -> None:
    rng = np.random.default_rng(5)
    m = 500
    log_w = rng.normal(0.0, 2.0, m)
    states = rng.normal(0.0, 50.0, (m, 4))
    states[:, 3] = 1.5  # a dimension with no spread stays put
    modes = rng.integers(0, 3, m).astype(np.int8)
    mean, cov = rng.normal(size=(m, 2)), rng.uniform(size=(m, 3))
    s, mo, me, co = states.copy(), modes.copy(), mean.copy(), cov.copy()
    log_mass = resample_roughen(log_w, s, mo, me, co, k, 4, np.random.default_rng(9))
    r = np.random.default_rng(9)
    idx = _reference_indices(log_w, m, r.random())
    ref = states[idx]
    if k > 0.0:
        sigma = k * (ref.max(axis=0) - ref.min(axis=0)) * m ** (-1.0 / 4)
        ref = ref + r.normal(size=ref.shape) * sigma
    np.testing.assert_allclose(s, ref, rtol=1e-13, atol=1e-12)
    assert np.all(s[:, 3] == 1.5)
    np.testing.assert_array_equal(mo, modes[idx])
    np.testing.assert_array_equal(me, mean[idx])
    np.testing.assert_array_equal(co, cov[idx])
    assert log_mass == pytest.approx(np.logaddexp.reduce(log_w), rel=1e-13)


def test_resample_roughen_of_impossible_particles_is_uniform() -> None:
    states = np.arange(12.0).reshape(3, 4)
    log_mass = resample_roughen(np.full(3, -np.inf), states, np.zeros(3, np.int8),
                                np.zeros((0, 2)), np.zeros((0, 3)), 0.0, 4,
                                np.random.default_rng(0))
    assert log_mass == -np.inf
    np.testing.assert_array_equal(states, np.arange(12.0).reshape(3, 4))


def test_roughening_moves_only_the_dimensions_the_motion_model_moves() -> None:
    """A static or random-walk tag (velocity columns zero): the positions are jittered (with
    the bandwidth of the full state, as tuned), the velocity columns never, and no draws are
    spent on them; the filter asks its motion model which columns move."""
    from mexgen_gcs.core.bernoulli import BernoulliFilter, FilterConfig
    from mexgen_gcs.core.motion import make_motion_model

    rng = np.random.default_rng(3)
    m = 400
    log_w = rng.normal(0.0, 1.0, m)
    states = np.zeros((m, 4))
    states[:, :2] = rng.normal(0.0, 30.0, (m, 2))
    s = states.copy()
    resample_roughen(log_w, s, np.zeros(m, np.int8), np.zeros((0, 2)), np.zeros((0, 3)), 0.2,
                     2, np.random.default_rng(9))
    r = np.random.default_rng(9)
    ref = states[_reference_indices(log_w, m, r.random())]
    sigma = 0.2 * (ref[:, :2].max(axis=0) - ref[:, :2].min(axis=0)) * m ** (-1.0 / 4)
    ref[:, :2] += r.normal(size=(m, 2)) * sigma
    np.testing.assert_allclose(s, ref, rtol=1e-13, atol=1e-12)
    assert np.all(s[:, 2:] == 0.0)
    area = SearchArea.rectangle(-100, 100, -100, 100)
    for name, dims in (("static", 2), ("rw", 2), ("cv", 4), ("cv-ift", 4)):
        f = BernoulliFilter(make_motion_model(name), RadioModel(), area,
                            FilterConfig(n_particles=50), np.random.default_rng(0))
        assert f._rough_dims == dims, name
