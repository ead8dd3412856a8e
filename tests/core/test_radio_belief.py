"""The Rao-Blackwellised radio unknowns: recovered from a survey, robust to bad pulses,
honest about shadowing that repeats, and the classic model when nothing is unknown."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import BernoulliFilter, FilterConfig
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import (
    SHADOW_NEIGHBOURS,
    PulseNoise,
    RadioUncertainty,
    ShadowMemory,
    shadow_conditioning,
)
from mexgen_gcs.core.resampling import systematic_resample

RADIO = RadioModel()
AREA = SearchArea.rectangle(-600, 600, -600, 600)
UNKNOWN = RadioUncertainty(p0_std_db=4.0, path_loss_exponent_std=0.3, outlier_prob=0.05)
TAG = np.array([120.0, -80.0])


def _survey(k: int) -> tuple[np.ndarray, float]:
    """Circles about the tag at radii 500 m down to 30 m, 30 m above it: a calibration survey
    (from outside in, as a survey approaches a tag it has not found yet)."""
    radius = (500.0, 250.0, 120.0, 60.0, 30.0)[(k // 300) % 5]
    ang = k * 10.0 / radius
    pos = TAG + radius * np.array([math.sin(ang), math.cos(ang)])
    return np.array([pos[0], pos[1], 30.0]), (ang + math.pi / 2) % (2 * math.pi)


def _fly(offset_db: float, exponent: float, seed: int, outlier_rate: float = 0.0,
         steps: int = 1500, unknowns: RadioUncertainty = UNKNOWN,
         jump_db: float = 30.0) -> BernoulliFilter:
    truth = RadioModel(p0_db=RADIO.p0_db + offset_db, path_loss_exponent=exponent)
    f = BernoulliFilter(make_motion_model("static"), RADIO, AREA,
                        FilterConfig(radio_unknowns=unknowns), np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 100)
    for k in range(steps):
        rx, yaw = _survey(k)
        p = truth.power_db(TAG, rx, yaw)
        z = [float(truth.measure(p, rng))] if truth.detect(np.array(p), rng) else []
        if z and rng.random() < outlier_rate:
            z = [z[0] + jump_db]
        f.predict(1.0)
        f.update(np.array(z), rx, yaw)
    return f


@pytest.mark.parametrize(("offset_db", "exponent", "seed"),
                         [(4.0, 1.9, 0), (-5.0, 1.3, 1), (2.0, 2.1, 2)])
def test_a_survey_recovers_the_tags_offset_and_exponent(offset_db, exponent, seed):
    est = _fly(offset_db, exponent, seed).estimate()
    assert est.p0_offset_db == pytest.approx(offset_db, abs=1.0)
    assert est.path_loss_exponent == pytest.approx(exponent, abs=0.15)
    assert math.dist(est.mean[:2], TAG) < 15.0


@pytest.mark.parametrize("jump_db", [-12.0, 30.0])
def test_five_percent_outliers_do_not_move_the_estimate(jump_db):
    """5 % of the pulses off by a deep fade (-12 dB) or wildly (+30 dB): the estimate holds."""
    clean = _fly(3.0, 1.7, 4).estimate()
    dirty = _fly(3.0, 1.7, 4, outlier_rate=0.05, jump_db=jump_db).estimate()
    assert dirty.p0_offset_db == pytest.approx(3.0, abs=1.0)
    assert dirty.path_loss_exponent == pytest.approx(1.7, abs=0.15)
    assert math.dist(dirty.mean[:2], TAG) < 15.0
    assert dirty.radius_m < 1.5 * clean.radius_m


def test_shadowing_heard_again_adds_little():
    """Detections from one spot repeat its shadowing: they share a memory cell, and a new
    detection there, conditioned on the cell's mean, has almost only the receiver noise left."""
    mem = ShadowMemory()
    rx = np.array([10.0, 0.0, 50.0])
    for k in range(30):
        mem.add(float(k), rx + np.array([k * 0.1, 0.0, 0.0]), 0.0, -50.0 + k % 3)
    assert mem.count == 1 and mem.n[0] == 30 and mem.z_db[0] == pytest.approx(-49.0)
    idx, d = mem.neighbours(40.0, rx[:2], 50.0)
    beta, r2 = shadow_conditioning(mem, idx, d, np.array([16.0, 0.0]), np.array([6.25, 4.0]),
                                   50.0)
    assert beta[0].sum() == pytest.approx(16.0 / (16.0 + 6.25 / 30), abs=1e-6)
    assert r2[0] == pytest.approx(6.25 + 16.0 * (6.25 / 30) / (16.0 + 6.25 / 30))
    assert np.all(beta[1] == 0.0) and r2[1] == 4.0  # no shadowing: nothing to condition on
    # another heading is another cell (the antenna pattern differs); far away: no neighbours
    mem.add(41.0, rx, math.pi, -55.0)
    assert mem.count == 2
    assert mem.neighbours(40.0, np.array([900.0, 0.0]), 50.0)[0].size == 0


def test_hovering_does_not_pretend_to_know_the_offset():
    """Hovering in one place under 4 dB static shadowing: the offset and the shadowing there
    are confounded, so the offset's variance must stay near the shadowing variance instead of
    shrinking like 1/N as independent pulses would make it."""
    unc = RadioUncertainty(p0_std_db=6.0, shadowing_std_db=(4.0,))
    f = BernoulliFilter(make_motion_model("static"), RADIO, AREA, FilterConfig(
        radio_unknowns=unc, n_particles=500), np.random.default_rng(0))
    rng = np.random.default_rng(1)
    rx = np.array([TAG[0] + 40.0, TAG[1], 50.0])
    for _ in range(300):
        p = RADIO.power_db(TAG, rx, 0.0)
        f.predict(1.0)
        f.update(np.array([float(RADIO.measure(p, rng))]), rx, 0.0)
    b = f.radio_belief
    assert b is not None
    w = np.exp(f.log_w)
    var_b = float(w @ b.cov[:, 0])
    assert var_b > 0.5 * 16.0 * 36.0 / (16.0 + 36.0)


def _star(k: int) -> tuple[np.ndarray, float]:
    """Straight passes through a point 20 m from the tag on eight headings, 400 m either side
    at 10 m/s and 50 m up: the tag ahead, abeam and behind in turn, so the front-to-back
    ratio shows apart from the range."""
    heading = (k // 80) % 8 * math.pi / 4 + 0.3
    along = -400.0 + 10.0 * (k % 80)
    d = np.array([math.sin(heading), math.cos(heading)])
    pos = TAG + np.array([20.0, 0.0]) + along * d
    return np.array([pos[0], pos[1], 50.0]), heading


def _star_flight(world: RadioModel, unknowns: RadioUncertainty, seed: int) -> BernoulliFilter:
    f = BernoulliFilter(make_motion_model("static"), RADIO, AREA,
                        FilterConfig(radio_unknowns=unknowns, n_particles=1000),
                        np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 100)
    for k in range(1280):
        rx, yaw = _star(k)
        p = world.power_db(TAG, rx, yaw)
        f.predict(1.0)
        f.update(np.array([float(world.measure(p, rng))] if world.detect(np.array(p), rng)
                          else []), rx, yaw)
    return f


@pytest.mark.parametrize(("front_back_db", "seed"), [(7.0, 0), (0.0, 1)])
def test_a_survey_recovers_the_antennas_front_to_back_ratio(front_back_db, seed):
    """The world's antenna loses 7 dB (or nothing) towards the tail, the mission's model 3:
    theta's third entry c, half the change, is learnt from passes on eight headings."""
    f = _star_flight(RadioModel(front_back_db=front_back_db),
                     RadioUncertainty(p0_std_db=4.0, front_back_std_db=4.0), seed)
    b = f.radio_belief
    assert b is not None and b.mean.shape[1] == 3 and b.cov.shape[1] == 6
    w = np.exp(f.log_w)
    c = float(w @ b.mean[:, 2])
    assert 2.0 * c == pytest.approx(front_back_db - RADIO.front_back_db, abs=1.0)
    est = f.estimate()
    assert est.p0_offset_db == pytest.approx(0.0, abs=1.0)
    assert math.dist(est.mean[:2], TAG) < 15.0


def test_a_front_to_back_ratio_known_to_a_nanodecibel_is_the_two_unknown_filter():
    """theta = (b, n, c) with c's prior std 1e-9 dB makes the same weights and (b, n) beliefs
    as theta = (b, n): the three-unknown kernel adds a regressor and nothing else."""
    world = RadioModel()
    a = _star_flight(world, UNKNOWN, 5)
    b = _star_flight(world, RadioUncertainty(p0_std_db=4.0, path_loss_exponent_std=0.3,
                                             outlier_prob=0.05, front_back_std_db=1e-9), 5)
    assert a.radio_belief is not None and b.radio_belief is not None
    np.testing.assert_allclose(b.log_w, a.log_w, atol=1e-9)
    np.testing.assert_allclose(b.radio_belief.mean[:, :2], a.radio_belief.mean, atol=1e-9)
    np.testing.assert_allclose(b.radio_belief.cov[:, :3], a.radio_belief.cov, atol=1e-9)


def test_nothing_unknown_is_the_classic_filter():
    a = BernoulliFilter(make_motion_model("static"), RADIO, AREA, FilterConfig(),
                        np.random.default_rng(3))
    assert a.radio_belief is None and a.n_levels == 1
    b = BernoulliFilter(make_motion_model("static"), RADIO, AREA,
                        FilterConfig(radio_unknowns=UNKNOWN), np.random.default_rng(3))
    assert b.radio_belief is not None


def test_roughness_levels_keep_their_particles_and_share_the_weight():
    unc = RadioUncertainty(p0_std_db=2.0, shadowing_std_db=(0.0, 4.0), model_error_std_db=(0.0,))
    f = BernoulliFilter(make_motion_model("static"), RADIO, AREA,
                        FilterConfig(radio_unknowns=unc, n_particles=600),
                        np.random.default_rng(0))
    rng = np.random.default_rng(2)
    for k in range(400):
        rx, yaw = _survey(k)
        p = RADIO.power_db(TAG, rx, yaw)
        f.predict(1.0)
        f.update(np.array([float(RADIO.measure(p, rng))]), rx, yaw)
    assert f.n_resamples > 0
    levels = f.radio_belief.level
    assert np.bincount(levels).tolist() == [300, 300]  # resampling never moves a slot's level
    w = np.exp(f.log_w)
    smooth = float(w[levels == 0].sum())
    assert smooth > 0.9  # the data (no shadowing) favour the smooth level


def test_shadow_conditioning_solves_the_gaussian_process_equations():
    """beta = (C + R / n)^-1 c and r^2 = s + R - c' beta (Cholesky in the kernel) against
    numpy's solve, for several cells of several pulses and several hypotheses."""
    rng = np.random.default_rng(3)
    mem = ShadowMemory()
    for k in range(40):
        mem.add(float(k), np.array([*rng.uniform(0, 120, 2), 40.0]), 0.0, -50.0)
    idx, d = mem.neighbours(40.0, np.array([60.0, 60.0]), 50.0)
    assert idx.size == SHADOW_NEIGHBOURS and mem.n[idx].max() >= 1
    shadow, noise = np.array([16.0, 4.0, 0.0]), np.array([6.25, 15.25, 6.25])
    beta, r2 = shadow_conditioning(mem, idx, d, shadow, noise, 50.0)
    p = mem.poses[idx, :2]
    dd = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    for lev in range(2):
        cmat = shadow[lev] * np.exp(-dd / 50.0) + np.diag(noise[lev] / mem.n[idx])
        c = shadow[lev] * np.exp(-d / 50.0)
        ref = np.linalg.solve(cmat, c)
        np.testing.assert_allclose(beta[lev], ref, rtol=1e-9, atol=1e-12)
        assert r2[lev] == pytest.approx(shadow[lev] + noise[lev] - c @ ref, rel=1e-12)
    assert np.all(beta[2] == 0.0) and r2[2] == 6.25


def test_a_pulse_where_the_filter_has_listened_tells_the_planner_little():
    """Far from every cell: the marginal sigma_s^2 + R and no neighbours' part; beside one
    cell: the one-cell Gaussian-process formulas with the cell as centroid; the weight c
    grows towards 1 as the cell fills; without shadowing nothing is conditioned."""
    s, r, big = 16.0, 15.25, 31.25
    one = PulseNoise(np.array([[10.0, 0.0]]), np.array([1.0]), s, r, 50.0)
    r2, c, centre = one.conditioning(np.array([[500.0, 0.0], [0.0, 0.0]]))
    assert r2[0] == pytest.approx(big) and c[0] == 0.0 and tuple(centre[0]) == (500.0, 0.0)
    rho = math.exp(-10.0 / 50.0)
    beta = s * rho / (s + r)
    assert c[1] == pytest.approx(beta) and r2[1] == pytest.approx(big - s * rho * beta)
    np.testing.assert_allclose(centre[1], (10.0, 0.0))
    _, c_full, _ = PulseNoise(np.array([[10.0, 0.0]]), np.array([20.0]), s, r, 50.0
                              ).conditioning(np.zeros(2))
    assert beta < c_full < rho
    x = np.linspace(-100.0, 100.0, 11)
    grid = np.array([(a, b) for a in x for b in x])
    smooth = PulseNoise(grid, np.ones(len(grid)), 0.0, r, 50.0).conditioning(grid[:5])
    np.testing.assert_allclose(smooth[0], r)
    assert np.all(smooth[1] == 0.0)
    # shapes: (..., 2) -> (...), (...), (..., 2)
    assert [a.shape for a in one.conditioning(np.zeros((3, 4, 2)))] == [(3, 4), (3, 4),
                                                                        (3, 4, 2)]


def test_the_planner_noise_follows_the_filters_roughness_and_memory():
    f = _fly(0.0, RADIO.path_loss_exponent, 1, steps=300,
             unknowns=RadioUncertainty(p0_std_db=4.0, shadowing_std_db=(4.0,),
                                       model_error_std_db=(3.0,)))
    noise = f.planning_noise()
    assert noise is not None and noise.cells_xy.shape[0] == f.shadow_memory.count > 0
    assert noise.shadow_var == 16.0 and noise.noise_var == RADIO.noise_var + 9.0
    r2, c, _ = noise.conditioning(noise.cells_xy[:20])  # where it has listened
    assert np.all(r2 < 16.0 + noise.noise_var) and np.all(c > 0.5)
    far = noise.conditioning(TAG + 2000.0)
    assert far[0] == pytest.approx(16.0 + noise.noise_var) and far[1] == 0.0
    classic = BernoulliFilter(make_motion_model("static"), RADIO, AREA, FilterConfig(),
                              np.random.default_rng(0))
    assert classic.planning_noise() is None


def test_pulse_noise_is_the_vecchia_conditioning_on_the_nearest_cells():
    """The kernel's band scan and insertion list against a brute-force numpy reference."""
    rng = np.random.default_rng(5)
    cells = rng.uniform(-500, 500, (300, 2))
    n = rng.integers(1, 5, 300).astype(float)
    s, r, dist = 16.0, 15.25, 50.0
    rx = rng.uniform(-700, 700, (200, 2))
    ref = []
    for p in rx:
        d = np.hypot(*(cells - p).T)
        idx = np.flatnonzero(d < -dist * math.log(0.02))
        if idx.size == 0:
            ref.append((s + r, 0.0, *p))
            continue
        idx = idx[np.argsort(d[idx])[:SHADOW_NEIGHBOURS]]
        c = cells[idx]
        cmat = s * np.exp(-np.hypot(*(c[:, None] - c[None, :]).transpose(2, 0, 1)) / dist)
        cvec = s * np.exp(-d[idx] / dist)
        beta = np.linalg.solve(cmat + np.diag(r / n[idx]), cvec)
        ref.append((s + r - cvec @ beta, beta.sum(), *(beta @ c / beta.sum())))
    r2, c, centre = PulseNoise(cells, n, s, r, dist).conditioning(rx)
    ref = np.array(ref)
    np.testing.assert_allclose(r2, ref[:, 0], rtol=1e-10)
    np.testing.assert_allclose(c, ref[:, 1], rtol=1e-10, atol=1e-12)
    has = ref[:, 1] != 0.0
    np.testing.assert_allclose(centre[has], ref[has, 2:], rtol=1e-9)
    np.testing.assert_allclose(centre[~has], rx[~has])


def test_the_planner_gets_each_particles_mean_unknowns_and_their_spread():
    """Means, not draws: with a draw per particle, pulses far from the tag told particles
    apart by their drawn offsets alone. Their uncertainty goes to the planner's noise."""
    f = _fly(3.0, RADIO.path_loss_exponent, 2, steps=200)
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    states, _, offset, exponent, cov = f.sample_planning(500, rng_a)
    idx = systematic_resample(f.log_w, 500, rng_b)
    np.testing.assert_array_equal(states, f.states[idx])
    np.testing.assert_array_equal(offset, f.radio_belief.mean[idx, 0])
    np.testing.assert_array_equal(exponent, np.maximum(f.radio_belief.mean[idx, 1], 0.1))
    np.testing.assert_allclose(cov, f.radio_belief.cov[idx].mean(axis=0))
    assert cov[0] > 0.0 and cov[2] > 0.0


def test_the_memory_counts_earlier_misses_by_their_shadowing_correlation() -> None:
    """Misses within CELL_M share a cell; K at a place is sum n_j exp(-d_j / L) over the
    cells, and for a moving tag only cells used within the horizon count."""
    mem = ShadowMemory()
    assert mem.misses_near(0.0, np.zeros(2), 50.0) == 0.0
    for t in range(3):
        mem.add_miss(float(t), np.array([1.0 * t, 0.0]))  # one cell (within 5 m)
    mem.add_miss(3.0, np.array([50.0, 0.0]))
    assert mem.miss_count == 2
    assert mem.misses_near(3.0, np.zeros(2), 50.0) == pytest.approx(3.0 + math.exp(-1.0))
    far = mem.misses_near(3.0, np.array([1000.0, 0.0]), 50.0)
    assert far < 1e-7
    for t in range(70):  # the arrays grow
        mem.add_miss(4.0 + t, np.array([0.0, 10.0 * t + 100.0]))
    assert mem.miss_count == 72
    moving = ShadowMemory(horizon_s=10.0)
    moving.add_miss(0.0, np.zeros(2))
    moving.add_miss(20.0, np.array([100.0, 0.0]))
    assert moving.misses_near(20.0, np.zeros(2), 50.0) == pytest.approx(math.exp(-2.0))
