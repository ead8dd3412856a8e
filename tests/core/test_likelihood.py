"""The detection table the planner's kernels read."""

import math

import numpy as np
import pytest
from scipy.special import log_ndtr

from mexgen_gcs.core.likelihood import LOG_FLOOR, detection_table
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
