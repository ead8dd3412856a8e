"""Reality profiles: the matched world is the mission's model; each departure does what its
documentation says (checked statistically where it is random)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reality import PROFILES, ShadowingField, profile

RADIO = RadioModel()


def _poses(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    tag_xy = rng.uniform(-500, 500, (n, 2))
    rx = np.column_stack([rng.uniform(-500, 500, (n, 2)), np.full(n, 50.0)])
    yaw = rng.uniform(0, 2 * math.pi, n)
    return tag_xy, rx, yaw


def test_matched_world_is_the_mission_model():
    world = profile("matched").realise(RADIO, 4, np.random.default_rng(0))
    tag_xy, rx, yaw = _poses(np.random.default_rng(1), 400)
    tags = np.arange(400) % 4
    np.testing.assert_allclose(world.mean_power_db(tags, tag_xy, rx, yaw),
                               RADIO.power_db(tag_xy, rx, yaw), atol=1e-9)
    power, _, rssi = world.pulse(tags, tag_xy, rx, yaw, np.random.default_rng(2))
    np.testing.assert_allclose(power, RADIO.power_db(tag_xy, rx, yaw), atol=1e-9)
    resid = rssi - power
    assert stats.kstest(resid / RADIO.noise_std_db, "norm").pvalue > 1e-3


def test_profiles_are_named_and_sourced():
    assert set(PROFILES) == {"matched", "tx-power", "path-loss", "antenna", "shadowing",
                             "fading", "terrain", "compass", "field"}
    assert all(p.source for p in PROFILES.values())
    with pytest.raises(ValueError, match="expected one of"):
        profile("swamp")


def test_worlds_are_reproducible_by_seed_and_draw_a_fixed_count():
    a = profile("field").realise(RADIO, 4, np.random.default_rng(5))
    b = profile("field").realise(RADIO, 4, np.random.default_rng(5))
    np.testing.assert_array_equal(a.tx_offset_db, b.tx_offset_db)
    assert a.path_loss_exponent == b.path_loss_exponent
    # a pulse draws the same numbers whatever the profile: the generators stay in step
    tag_xy, rx, yaw = _poses(np.random.default_rng(1), 4)
    for name in PROFILES:
        rng = np.random.default_rng(9)
        profile(name).realise(RADIO, 4, np.random.default_rng(3)).pulse(
            np.arange(4), tag_xy, rx, yaw, rng)
        assert rng.random() == pytest.approx(_after_one_pulse())


def _after_one_pulse() -> float:
    rng = np.random.default_rng(9)
    rng.standard_normal((4, 2))
    rng.random(4)
    rng.normal(size=4)
    return float(rng.random())


def test_departures_have_their_documented_ranges():
    offsets = np.concatenate([profile("tx-power").realise(RADIO, 4, np.random.default_rng(s))
                              .tx_offset_db for s in range(200)])
    assert offsets.min() >= -6.0 and offsets.max() <= 6.0 and offsets.std() > 3.0
    n = [profile("path-loss").realise(RADIO, 1, np.random.default_rng(s)).path_loss_exponent
         for s in range(200)]
    assert min(n) >= 1.2 and max(n) <= 2.2
    h = np.concatenate([profile("terrain").realise(RADIO, 4, np.random.default_rng(s))
                        .tag_height_m for s in range(100)])
    assert h.min() >= -30.0 and h.max() <= 30.0 and h.std() > 15.0
    bias = [profile("compass").realise(RADIO, 1, np.random.default_rng(s)).compass_bias_rad
            for s in range(200)]
    assert max(abs(math.degrees(b)) for b in bias) <= 10.0


def test_antenna_profile_matches_the_issue_example_ahead_and_behind():
    world = profile("antenna").realise(RADIO, 1, np.random.default_rng(0))
    # a distant tag straight ahead / behind the nose (the pattern's pointing is 20 deg)
    ant = world.antenna
    ahead = float(ant.gain_db(np.array(1.0), np.radians(20.0)))
    behind = float(ant.gain_db(np.array(1.0), np.radians(200.0)))
    two_lobe = 0.75 * (math.cos(math.radians(40.0)) - 1.0)
    assert ahead == pytest.approx(2.0 + two_lobe)  # +2 dB ahead (the model says 0)
    assert behind == pytest.approx(-2.0 + two_lobe)  # -2 dB behind (the model says -3)
    assert float(ant.gain_db(np.array(0.0), np.radians(200.0))) == 0.0  # straight below


def test_shadowing_has_the_stated_std_and_exponential_correlation():
    std, dist = 4.0, 50.0
    a, b = [], []
    for s in range(400):
        f = ShadowingField.draw(1, std, dist, np.random.default_rng(s))
        u = np.random.default_rng(1000 + s).uniform(-300, 300, 2)
        a.append(float(f.at(0, u)))
        b.append(float(f.at(0, u + np.array([dist, 0.0]))))
    a_, b_ = np.array(a), np.array(b)
    # std within a 99 % chi-square interval of 4 dB
    lo, hi = stats.chi2.ppf([0.005, 0.995], len(a_) - 1)
    var = a_.var(ddof=1)
    assert (len(a_) - 1) * var / hi <= std**2 <= (len(a_) - 1) * var / lo
    # correlation at one correlation distance: exp(-1) = 0.37, Fisher-z 99 % interval
    r = np.corrcoef(a_, b_)[0, 1]
    half = 2.576 / math.sqrt(len(a_) - 3)
    assert math.tanh(math.atanh(r) - half) <= math.exp(-1.0) <= math.tanh(math.atanh(r) + half)


def test_rician_fading_keeps_the_mean_power_and_spreads_it():
    world = profile("fading").realise(RADIO, 1, np.random.default_rng(0))
    g = world.fading_db((200_000,), np.random.default_rng(1))
    lin = 10.0 ** (g / 10.0)
    assert lin.mean() == pytest.approx(1.0, abs=0.01)
    assert 2.5 < g.std() < 4.0  # K = 6 dB: about 3.3 dB per pulse
