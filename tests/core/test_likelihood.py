"""The planner's measurement update: detection table, likelihood grid, Bayes update."""

import math
import warnings

import numpy as np
import pytest
from scipy.special import log_ndtr

from mexgen_gcs.core.likelihood import (
    LOG_FLOOR,
    bayes_update,
    detection_table,
    log_likelihood,
)
from mexgen_gcs.core.radio import RadioModel


def _normalised(log_w: np.ndarray) -> np.ndarray:
    x = np.asarray(log_w, np.float64)
    return x - np.log(np.sum(np.exp(x - x.max(-1, keepdims=True)), -1, keepdims=True)) - x.max(
        -1, keepdims=True
    )


def test_table_matches_the_radio_detection_model():
    radio = RadioModel()
    table = detection_table(radio)
    assert detection_table(radio) is table  # cached per model
    p = np.linspace(-80.0, 0.0, 4001, dtype=np.float32)
    pd = radio.detection_probability(p.astype(np.float64))
    np.testing.assert_allclose(table.pd(p), pd, atol=2e-3)
    near = np.abs(p - radio.sensitivity_db) <= 5 * radio.detection_spread_db
    np.testing.assert_allclose(table.log_pd(p)[near], np.log(pd[near]), atol=0.01)
    np.testing.assert_allclose(table.log_miss(p), np.log1p(-pd), atol=0.01)
    out = np.empty_like(p)
    assert table.log_pd(p, out=out) is out


@pytest.mark.parametrize("pd_max", [0.0, 0.95, 1.0])
def test_table_is_finite_everywhere_even_for_degenerate_pd(pd_max):
    table = detection_table(RadioModel(pd_max=pd_max))
    p = np.array([-1e6, -500.0, -60.0, 0.0, 300.0, 1e6], dtype=np.float32)
    for f in (table.log_pd, table.log_miss, table.pd):
        v = f(p)
        assert np.all(np.isfinite(v)) and v.dtype == np.float32
    assert np.all(table.log_pd(p) >= LOG_FLOOR)
    # far below the sensitivity: log pD follows log Phi until the clamp at -40 spreads
    r = RadioModel()
    x = -20.0
    got = detection_table(r).log_pd(np.float32(r.sensitivity_db + x * r.detection_spread_db))
    assert got == pytest.approx(math.log(r.pd_max) + log_ndtr(x), abs=0.05)


def test_log_likelihood_detection_and_miss_rows():
    radio = RadioModel()
    table = detection_table(radio)
    rng = np.random.default_rng(0)
    power = rng.uniform(-70.0, -30.0, (3, 1, 50)).astype(np.float32)
    log_pd = table.log_pd(power)
    z = np.array([[-50.0], [-40.0], [-55.0]], dtype=np.float32)
    det = np.array([[True], [False], [True]])
    ll = log_likelihood(z, det, power, log_pd, table, radio.noise_var)
    assert ll.shape == (3, 1, 50) and ll.dtype == np.float32
    p64 = power.astype(np.float64)
    exact_det = np.log(radio.detection_probability(p64)) + radio.log_likelihood(z[..., None], p64)
    exact_miss = np.log1p(-radio.detection_probability(p64))
    for r in (0, 2):  # equal up to a constant per row
        d = ll[r, 0] - exact_det[r, 0]
        assert np.ptp(d) < 0.05
    np.testing.assert_allclose(ll[1, 0], exact_miss[1, 0], atol=0.01)


def test_broadcast_path_equals_direct_path_up_to_row_constants():
    """MC rollouts share one power grid per action: the fast expansion is the same update."""
    radio = RadioModel()
    table = detection_table(radio)
    rng = np.random.default_rng(1)
    power = rng.uniform(-60.0, -30.0, (2, 1, 64)).astype(np.float32)
    log_pd = table.log_pd(power)
    z = rng.uniform(-55.0, -35.0, (2, 8)).astype(np.float32)
    det = rng.random((2, 8)) < 0.7
    fast = log_likelihood(z, det, power, log_pd, table, radio.noise_var)  # (2, 8, 64)
    for r in range(8):
        direct = log_likelihood(z[:, r : r + 1], det[:, r : r + 1], power, log_pd, table,
                                radio.noise_var)
        np.testing.assert_allclose(_normalised(fast[:, r]), _normalised(direct[:, 0]),
                                   atol=2e-3)


def test_bayes_update_normalises_and_keeps_rows_nothing_explains():
    rng = np.random.default_rng(2)
    log_w = np.log(rng.dirichlet(np.ones(40), size=3)).astype(np.float32)
    ll = rng.normal(0.0, 3.0, (3, 40)).astype(np.float32)
    ll[2] = -np.inf  # no particle explains this row's measurement
    expected = _normalised(log_w[:2] + ll[:2])
    upd = bayes_update(log_w, ll.copy())
    got = upd.log_weights - upd.log_total[:, None]
    np.testing.assert_allclose(got[:2], expected[:2], atol=1e-5)
    np.testing.assert_allclose(got[2], log_w[2], atol=1e-5)  # prior kept
    np.testing.assert_allclose(upd.weights.sum(-1), np.exp(upd.log_total), rtol=1e-5)
    assert np.all(upd.log_weights.max(-1) == 0.0)


def test_no_nan_when_every_likelihood_underflows():
    """A measurement far from every particle: all likelihoods below float64's range."""
    radio = RadioModel(noise_std_db=0.01)
    table = detection_table(radio)
    power = np.linspace(-90.0, -80.0, 100, dtype=np.float32)[None, None, :]
    log_pd = table.log_pd(power)
    z = np.array([[1.0e6]], dtype=np.float32)  # absurd, but finite
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ll = log_likelihood(z, np.array([[True]]), power, log_pd, table, radio.noise_var)
        assert np.all(np.exp(ll.astype(np.float64)) == 0.0)  # every likelihood underflows
        upd = bayes_update(np.full_like(ll, -math.log(100)), ll)
    assert np.all(np.isfinite(upd.log_weights[upd.weights > 0]))
    assert np.isfinite(upd.log_total).all()
    assert upd.weights.max() == 1.0
