"""The filter's compiled kernels equal the model's definitions (core.radio, scipy) and a small
numpy reference of the robust update (the equations of core.radio_belief, written out here)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.special import logsumexp, ndtr

from mexgen_gcs.core.filter_kernels import (
    GH_NODES,
    GH_WEIGHTS,
    classic_update,
    correlated_miss,
    detection,
    geometry,
    miss_moments,
    phi_upper,
    radio_params,
    robust_update,
)
from mexgen_gcs.core.radio import RadioModel

RADIO = RadioModel()


def test_geometry_matches_the_radio_model() -> None:
    rng = np.random.default_rng(0)
    radio = RadioModel(front_back_db=4.0, min_distance_m=2.0, d0_m=1.5)
    p = radio_params(radio)
    tag = rng.uniform(-300, 300, (500, 2))
    tag[:5] = 0.0  # right below the receiver
    for rx_z in (0.0, 0.5, 60.0):
        rx = np.array([0.0, 0.0, rx_z])
        yaw = float(rng.uniform(0, 2 * math.pi))
        ours = np.array([geometry(t[0], t[1], 0.0, 0.0, rx_z, math.sin(yaw), math.cos(yaw), p)
                         for t in tag])
        log_term, gain = radio.geometry(tag, rx, yaw)
        np.testing.assert_allclose(ours[:, 0], log_term, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(ours[:, 1], gain, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("pd_max", [1.0, 0.95, 0.999999, 0.3])
def test_detection_matches_the_probit_formula_in_both_tails(pd_max: float) -> None:
    """pD and 1 - pD against scipy's probit, each to full relative precision in its small
    tail (x from -37 to 40 spreads), and the certain-detection shortcut (x >= 12)."""
    radio = RadioModel(sensitivity_db=-120.0, detection_spread_db=2.0, pd_max=pd_max)
    p = radio_params(radio)
    mean = np.concatenate([np.linspace(-194.0, -40.0, 2000), [-96.0, -80.0, -40.0]])
    var = np.random.default_rng(1).uniform(0.0, 0.2, mean.size)
    var[-3:] = 0.0  # x = 12, 20, 40: the shortcut
    ours = np.array([detection(float(m), float(v), p) for m, v in zip(mean, var, strict=True)])
    x = (mean + 120.0) / np.sqrt(4.0 + var)
    assert x.min() < -36.0 and x.max() == 40.0
    floor = 1.0 - min(pd_max, 1.0 - 1e-12)
    np.testing.assert_allclose(ours[:, 0], pd_max * ndtr(x), rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(ours[:, 1], floor + pd_max * ndtr(-x), rtol=1e-12,
                               atol=1.1e-12 if pd_max == 1.0 else 0.0)  # floor not added x<0


@pytest.mark.parametrize("n_z", [0, 1, 3])
def test_classic_update_is_bayes_rule_with_the_radio_model(n_z: int) -> None:
    rng = np.random.default_rng(n_z)
    radio = RadioModel(clutter_rate=0.05, sensitivity_db=-50.0)
    states = np.column_stack([rng.uniform(-500, 500, (1000, 2)), rng.normal(size=(1000, 2))])
    rx, yaw = np.array([30.0, -20.0, 40.0]), 1.1
    z = rng.uniform(-60.0, -30.0, n_z)
    log_w0 = rng.normal(size=1000)
    log_w0 -= np.log(np.exp(log_w0).sum())
    log_w = log_w0.copy()
    log_mean_l, ess = classic_update(states, rx, yaw, z, log_w, radio_params(radio))
    power = radio.power_db(states[:, :2], rx, yaw)
    pd = radio.detection_probability(power)
    lik = 1 - pd
    for zj in z:
        lik = lik + pd * np.exp(radio.log_likelihood(zj, power)) / radio.clutter_density
    post = np.exp(log_w0) * lik
    np.testing.assert_allclose(log_mean_l, math.log(post.sum()), rtol=1e-12)
    np.testing.assert_allclose(np.exp(log_w), post / post.sum(), rtol=1e-10, atol=1e-300)
    assert ess == pytest.approx(1.0 / float(np.sum((post / post.sum()) ** 2)), rel=1e-10)


def test_classic_update_keeps_the_weights_when_every_particle_is_impossible() -> None:
    log_w = np.full(3, -np.inf)
    states = np.zeros((3, 4))
    total, ess = classic_update(states, np.zeros(3), 0.0, np.array([-40.0]), log_w,
                                radio_params(RADIO))
    assert total == -np.inf and math.isnan(ess)
    assert np.all(log_w == -np.inf)


def _robust_reference(radio, eps, states, mean, cov, level, rx, yaw, nb_poses, nb_z, beta, r2,
                      z, log_w, shadow_left=None, misses_k=0.0):
    """The robust update in numpy, straight from core.radio_belief's equations."""
    mean, cov = mean.copy(), cov.copy()
    xy = states[:, :2]
    lev = level.astype(int)
    b, r2n = beta[lev], r2[lev]  # (N, m), (N,)
    l0, g0 = radio.geometry(xy, rx, yaw)
    if nb_poses.shape[0]:
        lk, gk = radio.geometry(xy[:, None, :], nb_poses[None, :, :3], nb_poses[None, :, 3])
    else:
        lk = gk = np.zeros((xy.shape[0], 0))
    one = 1.0 - b.sum(axis=1)
    base = radio.p0_db * one + g0 - (b * gk).sum(axis=1)
    lt = l0 - (b * lk).sum(axis=1)
    z_t = z[None, :] - (b @ nb_z)[:, None]

    def whitened():
        sh = np.column_stack([cov[:, 0] * one + cov[:, 1] * lt, cov[:, 1] * one + cov[:, 2] * lt])
        m = base + one * mean[:, 0] + lt * mean[:, 1]
        return m, np.maximum(one * sh[:, 0] + lt * sh[:, 1], 0.0), sh

    m_w, v_w, _ = whitened()
    s = v_w + r2n
    pred = m_w + b @ nb_z  # the power predicted given the neighbours
    vp = np.maximum(s - radio.noise_var, 0.0)  # its variance less the receiver noise
    spread2 = radio.detection_spread_db**2
    pd = radio.pd_max * ndtr((pred - radio.sensitivity_db) / np.sqrt(spread2 + vp))
    e = z_t - m_w[:, None]
    # pD given z: the received power given the reported one is N(pred + vp/s e, vp R / s)
    pd_z = radio.pd_max * ndtr((pred[:, None] + (vp / s)[:, None] * e - radio.sensitivity_db)
                               / np.sqrt(spread2 + (vp * radio.noise_var / s)[:, None]))
    g_in = (1 - eps) * np.exp(-0.5 * e * e / s[:, None]) / np.sqrt(2 * np.pi * s[:, None]) * pd_z
    parts = (g_in + pd[:, None] * eps / (radio.clutter_max_db - radio.clutter_min_db)
             ) / radio.clutter_density
    lik = 1 - pd + parts.sum(axis=1)
    if z.size == 0 and misses_k > 0.0:
        lik = _correlated_miss_quadrature(radio, pred, vp, shadow_left[lev], misses_k)
    gains = g_in / radio.clutter_density / lik[:, None]
    mass = np.exp(log_w) @ gains
    for j in range(z.size):
        m_w, v_w, sh = whitened()
        s = v_w + r2n
        e = z_t[:, j] - m_w
        w = np.clip(gains[:, j], 0, 1)
        mean += (w * e / s)[:, None] * sh
        f = w / s - w * (1 - w) * e * e / (s * s)
        cov[:, 0] = np.maximum(cov[:, 0] - f * sh[:, 0] ** 2, 0.0)
        cov[:, 1] -= f * sh[:, 0] * sh[:, 1]
        cov[:, 2] = np.maximum(cov[:, 2] - f * sh[:, 1] ** 2, 0.0)
    if z.size == 0:
        m_w, v_w, sh = whitened()
        shift, dvar = _miss_quadrature(radio, pred, v_w, vp - v_w)
        narrows = dvar < 0.0  # (a miss that would widen the Gaussian leaves it: the kernel)
        shift, dvar = np.where(narrows, shift, 0.0), np.where(narrows, dvar, 0.0)
        shift, dvar = shift / (1.0 + misses_k), dvar / (1.0 + misses_k)
        mean += (shift / v_w)[:, None] * sh
        f = -dvar / (v_w * v_w)
        cov[:, 0] = np.maximum(cov[:, 0] - f * sh[:, 0] ** 2, 0.0)
        cov[:, 1] -= f * sh[:, 0] * sh[:, 1]
        cov[:, 2] = np.maximum(cov[:, 2] - f * sh[:, 1] ** 2, 0.0)
    post = np.exp(log_w) * lik
    return mean, cov, math.log(post.sum()), post / post.sum(), mass


def _correlated_miss_quadrature(radio, pred, vp, shadow, k):
    """E[a(s)^(k+1)] / E[a(s)^k], s ~ N(0, shadow), by 200-node Gauss-Hermite quadrature."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(200)
    pd_max = min(radio.pd_max, 1.0 - 1e-12)
    tau = np.sqrt(radio.detection_spread_db**2 + np.maximum(vp - shadow, 0.0))[..., None]
    s = np.sqrt(shadow)[..., None] * nodes
    a = (1.0 - pd_max) + pd_max * ndtr(-(pred[..., None] + s - radio.sensitivity_db) / tau)
    return (weights * a ** (k + 1.0)).sum(axis=-1) / (weights * a**k).sum(axis=-1)


def _miss_quadrature(radio, mean, q, rest):
    """(shift of the mean, change of the variance) of u ~ N(mean, q) (...) given a miss, by
    Gauss-Hermite quadrature of N(u) (1 - pD(u + r)), r ~ N(0, rest) integrated out."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(160)
    du = np.sqrt(q)[..., None] * nodes
    pd_max = min(radio.pd_max, 1.0 - 1e-12)
    t = np.sqrt(radio.detection_spread_db**2 + rest)[..., None]
    lik = (1.0 - pd_max) + pd_max * ndtr(-(mean[..., None] + du - radio.sensitivity_db) / t)
    z = (weights * lik).sum(axis=-1)
    shift = (weights * lik * du).sum(axis=-1) / z
    var = (weights * lik * du * du).sum(axis=-1) / z - shift * shift
    return shift, var - q


@pytest.mark.parametrize(("n_nb", "n_z", "eps", "misses_k"),
                         [(0, 1, 0.05, 0.0), (4, 1, 0.05, 0.0), (4, 2, 0.0, 0.0),
                          (3, 0, 0.05, 0.0), (3, 0, 0.05, 3.5)])
def test_robust_update_matches_the_numpy_equations(n_nb: int, n_z: int, eps: float,
                                                   misses_k: float) -> None:
    rng = np.random.default_rng(10 * n_nb + n_z)
    radio = RadioModel(sensitivity_db=-55.0)
    n, n_levels = 999, 3
    states = np.column_stack([rng.uniform(-400, 400, (n, 2)), np.zeros((n, 2))])
    mean = np.column_stack([rng.normal(0, 3, n), rng.uniform(1.2, 2.5, n)])
    a, c = rng.uniform(1, 9, n), rng.uniform(0.01, 0.1, n)
    cov = np.column_stack([a, rng.uniform(-0.5, 0.5, n) * np.sqrt(a * c), c])
    level = (np.arange(n) % n_levels).astype(np.int8)
    rx, yaw = np.array([50.0, 20.0, 45.0]), 2.0
    nb_poses = np.column_stack([rng.uniform(0, 100, (n_nb, 2)), np.full(n_nb, 45.0),
                                rng.uniform(0, 6, n_nb)])
    nb_z = rng.uniform(-60, -40, n_nb)
    beta = np.ascontiguousarray(rng.uniform(0, 0.2, (n_levels, n_nb)))
    beta[0] = 0.0  # a level without shadowing
    r2 = rng.uniform(5.0, 20.0, n_levels)
    z = rng.uniform(-60.0, -40.0, n_z)
    log_w = rng.normal(size=n)
    log_w -= np.log(np.exp(log_w).sum())
    shadow_left = np.maximum(r2 - radio.noise_var - 2.0, 0.0)
    ref = _robust_reference(radio, eps, states, mean, cov, level, rx, yaw, nb_poses, nb_z, beta,
                            r2, z, log_w, shadow_left, misses_k)
    total, mass, s1, s2 = robust_update(states, mean, cov, level, rx, yaw, nb_poses, nb_z, beta,
                                        r2, shadow_left, misses_k, z, log_w,
                                        radio_params(radio, eps))
    quad = 1.0 if n_z else 100.0  # a miss's reference is a quadrature
    if misses_k:  # and the kernel's correlated miss a 16-node one
        assert total == pytest.approx(ref[2], rel=1e-4)
        np.testing.assert_allclose(np.exp(log_w), ref[3], rtol=1e-3, atol=1e-300)
        np.testing.assert_allclose(mean, ref[0], rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(cov, ref[1], rtol=1e-7, atol=1e-10)
        return
    np.testing.assert_allclose(mean, ref[0], rtol=1e-10 * quad, atol=1e-12 * quad)
    np.testing.assert_allclose(cov, ref[1], rtol=1e-9 * quad, atol=1e-12 * quad)
    assert total == pytest.approx(ref[2], rel=1e-11)
    np.testing.assert_allclose(np.exp(log_w), ref[3], rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(mass, ref[4], rtol=1e-9, atol=1e-300)
    w = ref[3]
    lev = np.arange(n) % n_levels
    ess = np.array([w[lev == k].sum() ** 2 / (w[lev == k] ** 2).sum() for k in range(n_levels)])
    np.testing.assert_allclose(s1 * s1 / s2, ess, rtol=1e-10)


@pytest.mark.parametrize("pd_max", [0.3, 0.95, 1.0])
def test_a_miss_moves_the_gaussian_as_bayes_rule_does(pd_max: float) -> None:
    """The moment-matched posterior of the explained power u after a missed pulse, against
    quadrature: from pulses that could not have been heard (no change) to pulses that
    should have been (u pulled down, its spread shrunk), 1 - pd_max of misses unexplained."""
    radio = RadioModel(sensitivity_db=-60.0, detection_spread_db=2.0, pd_max=pd_max)
    p = radio_params(radio)
    rng = np.random.default_rng(3)
    q = rng.uniform(0.5, 60.0, 400)
    rest = rng.uniform(0.0, 20.0, 400)
    x = np.linspace(-8.0, 3.0 if pd_max == 1.0 else 8.0, 400)  # quadrature's reach
    mean = -60.0 + x * np.sqrt(4.0 + rest + q)
    ours = np.array([miss_moments(m, qq, r, detection(m, qq + r, p)[1], p)
                     for m, qq, r in zip(mean, q, rest, strict=True)])
    shift, dvar = _miss_quadrature(radio, mean, q, rest)
    np.testing.assert_allclose(ours[:, 0] * q, shift, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(ours[:, 1] * q * q, dvar, rtol=1e-7, atol=1e-9)
    assert np.all(ours[:, 0] <= 0.0)  # (the spread may grow: a lost pulse or a weak tag)
    k = int(np.argmin(np.abs(x - 1.5)))  # a miss where a pulse was likely: a weaker power
    assert pd_max < 0.9 or ours[k, 0] * q[k] < -0.1 * np.sqrt(q[k])
    assert miss_moments(-300.0, 10.0, 0.0, 1.0, p) == (0.0, 0.0)  # never audible
    assert miss_moments(-50.0, 0.0, 0.0, 0.5, p) == (0.0, 0.0)  # nothing unknown


def test_robust_update_counts_the_detection_of_a_strong_pulse_once() -> None:
    """At the edge of detection, with variation the detection and the reported power share
    (here 3 dB model error), the detected pulses are the strong ones. The update's pD given z
    keeps the range posterior honest: its 95 % interval holds the tag in about 95 % of 200
    repeated listenings, where pD of the prediction (the selection counted twice) puts the
    tag ~40 m too near and covers it in ~60 % (measured when this test was written)."""
    radio = RadioModel(front_back_db=0.0, sensitivity_db=-46.0, pd_max=0.95)
    p = radio_params(radio)
    x = np.linspace(100.0, 1000.0, 451)  # candidate ranges east of the receiver
    n = x.size
    states = np.column_stack([x, np.zeros((n, 3))])
    rx = np.array([0.0, 0.0, 50.0])
    x_true, me_std = 400.0, 3.0
    m_true = float(radio.power_db(np.array([x_true, 0.0]), rx, 0.0))  # -46.1: the edge
    r2 = np.array([radio.noise_var + me_std**2])
    rng = np.random.default_rng(1)
    inside, means = 0, []
    for _ in range(200):
        log_w = np.full(n, -math.log(n))
        mean = np.tile([0.0, radio.path_loss_exponent], (n, 1))  # (b, n) known exactly
        cov = np.zeros((n, 3))
        for _ in range(60):
            power = m_true + rng.normal(0.0, me_std)  # the received power, shared
            heard = rng.random() < float(radio.detection_probability(np.array(power)))
            z = np.array([power + rng.normal(0.0, radio.noise_std_db)]) if heard else np.empty(0)
            robust_update(states, mean, cov, np.zeros(n, np.int8), rx, 0.0, np.zeros((0, 4)),
                          np.zeros(0), np.zeros((1, 0)), r2, np.zeros(1), 0.0, z, log_w, p)
        cdf = np.cumsum(np.exp(log_w))
        inside += x[np.searchsorted(cdf, 0.025)] <= x_true <= x[np.searchsorted(cdf, 0.975)]
        means.append(float(np.exp(log_w) @ x))
    assert inside / 200 >= 0.9
    assert abs(np.mean(means) - x_true) < 20.0


def test_misses_in_one_shadowed_patch_count_once_for_a_weak_place_not_a_strong_one() -> None:
    """A miss given k earlier misses that share its shadowing (4 dB): against quadrature;
    k = 0 is the marginal 1 - pD; near the threshold the next miss is nearly certain once
    a few have said the patch is weak, while a place that should be heard whatever the
    shadowing keeps paying about 1 - pd_max for every miss."""
    radio = RadioModel(sensitivity_db=-60.0, detection_spread_db=2.0, pd_max=0.95)
    p = radio_params(radio)
    shadow, vp = 16.0, 16.0 + 9.0
    pred = np.linspace(-80.0, -30.0, 51)

    def cm(m: float, k: float) -> float:
        return correlated_miss(m, vp, shadow, k, detection(m, vp, p)[1], p)

    for k, reach in ((0.0, 51), (0.5, 51), (3.0, 51), (12.0, 41)):
        # 16 nodes against 200: 12 misses within 5 %; past 20 dB above the threshold they
        # would need a shadowing beyond the 16 nodes' 6.6 sigma, and there a particle pays
        # 1 - pd_max a miss, as without the correction (it is long dead)
        ours = np.array([cm(m, k) for m in pred[:reach]])
        ref = _correlated_miss_quadrature(radio, pred[:reach], np.full(reach, vp),
                                          np.full(reach, shadow), k)
        np.testing.assert_allclose(ours, ref, rtol=2e-3 if k < 5 else 5e-2, atol=1e-6)
    marginal = np.array([detection(m, vp, p)[1] for m in pred])
    np.testing.assert_allclose([cm(m, 0.0) for m in pred], marginal,
                               rtol=1e-6)
    at_threshold = [cm(-60.0, k) for k in (0.0, 3.0, 12.0)]
    assert at_threshold[0] == pytest.approx(0.5 * 0.95 + 0.05, rel=1e-3)
    assert at_threshold[0] < at_threshold[1] < at_threshold[2] and at_threshold[2] > 0.9
    loud = [cm(-20.0, k) for k in (0.0, 12.0)]
    assert loud[1] == pytest.approx(0.05, rel=0.05) and loud[0] == pytest.approx(0.05, rel=1e-3)
    hover = [cm(m, 2000.0) for m in (-90.0, -60.0, -20.0)]
    assert all(0.05 <= h <= 1.0 for h in hover)  # hundreds of misses in one place: no NaN


def test_the_tabulated_upper_tail_is_phi_within_2e_9() -> None:
    x = np.linspace(-10.0, 10.0, 200_001)
    ours = np.array([phi_upper(v) for v in x])
    np.testing.assert_allclose(ours, ndtr(-x), rtol=0.0, atol=2e-9)
    assert phi_upper(-9.0) == 1.0 and phi_upper(9.0) < 1e-16  # Phi(-+8.5) beyond 8.5
    assert np.all(np.diff(ours) <= 1e-15)  # never rises: a(s) stays monotone


@pytest.mark.parametrize("pd_max", [0.95, 0.6, 1.0])
def test_a_correlated_miss_is_its_16_node_quadrature_where_it_takes_the_shortcuts(
        pd_max: float) -> None:
    """The early-outs (the marginal where the tilted mean is bounded within 1e-4 of it) and
    the tabulated Phi against the same 16-node quadrature in numpy with erfc, on the log
    scale, across the threshold and far beyond it, for up to 400 earlier misses."""
    radio = RadioModel(sensitivity_db=-60.0, detection_spread_db=2.0, pd_max=pd_max)
    p = radio_params(radio)
    pred = np.linspace(-130.0, 10.0, 281)
    for shadow, extra, k in itertools.product((1.0, 4.0, 16.0), (0.0, 9.0),
                                              (0.5, 3.0, 12.0, 60.0, 400.0)):
        vp = shadow + extra
        tau = math.sqrt(4.0 + extra)
        f = p.miss_floor
        a = f + p.pd_max * ndtr(-(pred[:, None] + math.sqrt(shadow) * GH_NODES + 60.0) / tau)
        log_w = np.log(GH_WEIGHTS) + k * np.log(a)
        ref = np.exp(logsumexp(log_w + np.log(a), axis=1) - logsumexp(log_w, axis=1))
        ours = np.array([correlated_miss(m, vp, shadow, k, detection(m, vp, p)[1], p)
                         for m in pred])
        np.testing.assert_allclose(ours, ref, rtol=3e-4, atol=1e-12,
                                   err_msg=f"shadow {shadow} extra {extra} k {k}")
