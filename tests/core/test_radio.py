"""Radio model against hand-computed values."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.radio import RadioModel


def test_paper_defaults():
    r = RadioModel()
    assert (r.p0_db, r.d0_m, r.path_loss_exponent, r.noise_var) == (-7.0, 1.0, 1.5, 6.25)


def test_power_without_antenna_gain_matches_path_loss():
    r = RadioModel(front_back_db=0.0)
    # 3-4-5 triangle: tag 400 m east, vehicle at 300 m altitude -> 500 m
    p = r.power_db(np.array([400.0, 0.0]), np.array([0.0, 0.0, 300.0]), 0.0)
    assert p == pytest.approx(-7.0 - 15.0 * math.log10(500.0))
    # 100 m -> -7 - 30 = -37 dB
    assert r.power_db(np.array([0.0, 100.0]), np.zeros(3), 0.0) == pytest.approx(-37.0)


def test_antenna_gain_front_back_and_directly_below():
    r = RadioModel(front_back_db=3.0)
    rx = np.array([0.0, 0.0, 0.0])
    ahead = r.power_db(np.array([0.0, 100.0]), rx, 0.0)  # heading north, tag north
    behind = r.power_db(np.array([0.0, -100.0]), rx, 0.0)
    side = r.power_db(np.array([100.0, 0.0]), rx, 0.0)
    assert ahead == pytest.approx(-37.0)
    assert behind == pytest.approx(-40.0)
    assert side == pytest.approx(-38.5)
    # heading east makes the east tag the one ahead
    assert r.power_db(np.array([100.0, 0.0]), rx, math.pi / 2) == pytest.approx(-37.0)
    # directly below at 50 m: gain vanishes (cos elev = 0), finite
    below = r.power_db(np.array([0.0, 0.0]), np.array([0.0, 0.0, 50.0]), 1.234)
    assert below == pytest.approx(-7.0 - 15.0 * math.log10(50.0))
    # at the antenna: clamped distance, finite
    assert np.isfinite(r.power_db(np.zeros(2), np.zeros(3), 0.0))


def test_broadcasting_particles_by_actions():
    r = RadioModel()
    tags = np.random.default_rng(0).uniform(-500, 500, (1000, 2))
    rx = np.zeros((8, 1, 3))
    yaw = np.linspace(0, 2 * np.pi, 8, endpoint=False)[:, None]
    assert r.power_db(tags[None], rx, yaw).shape == (8, 1000)


def test_detection_probability_and_likelihood():
    r = RadioModel(sensitivity_db=-60.0, detection_spread_db=2.0, pd_max=0.9)
    assert r.detection_probability(np.array(-60.0)) == pytest.approx(0.45)
    assert r.detection_probability(np.array(-40.0)) == pytest.approx(0.9)
    assert r.detection_probability(np.array(-80.0)) < 1e-20
    ll = r.log_likelihood(-50.0, np.array(-50.0))
    assert ll == pytest.approx(-0.5 * math.log(2 * math.pi * 6.25))
    assert r.log_likelihood(-45.0, np.array(-50.0)) == pytest.approx(ll - 2.0)


def test_noisy_measurement_statistics():
    r = RadioModel()
    rng = np.random.default_rng(3)
    z = r.measure(np.full(200_000, -50.0), rng)
    assert z.mean() == pytest.approx(-50.0, abs=0.03)
    assert z.std() == pytest.approx(2.5, rel=0.01)
    det = r.detect(np.full(200_000, -60.0), rng)
    assert det.mean() == pytest.approx(0.475, abs=0.005)


def test_invalid_parameters_rejected():
    with pytest.raises(ValueError):
        RadioModel(noise_std_db=0.0)
    with pytest.raises(ValueError):
        RadioModel(pd_max=1.5)
