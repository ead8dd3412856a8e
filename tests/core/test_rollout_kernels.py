"""The planner's compiled step equals the model's definitions: the power grid is
RadioModel.power_db, the update is Bayes' rule with the detect/miss likelihood of
core.rollout, and the gain is core.reward.renyi_divergence (the readable references)."""

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.jit import exp32, kernel, log32, max_lanes
from mexgen_gcs.core.likelihood import detection_table
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reward import logsumexp, renyi_divergence
from mexgen_gcs.core.rollout_kernels import grid_params, grid_step, update_step
from mexgen_gcs.core.workspace import Workspace

NONE = np.zeros((0, 0), np.float32)


def _grid(radio, xy, rx, yaw, offset=NONE, exponent=NONE, nb_c=NONE, nb_xy=NONE[None]):
    table = detection_table(radio)
    t, n = xy.shape[0], xy.shape[2]
    a = rx.shape[0]
    power = np.empty((t, a, n), np.float32)
    log_pd = np.empty_like(power)
    index = np.empty((t, a, n), np.int32)
    nb_power = np.full((t, a, n), np.nan, np.float32)
    params = grid_params(radio.p0_db, radio.path_loss_exponent, radio.d0_m, radio.front_back_db,
                         radio.min_distance_m, table.inv_step, table.offset)
    grid_step(xy, rx, yaw, offset, exponent, params, table.arrays(0.1).log_pd, nb_c, nb_xy,
              power, log_pd, index, nb_power)
    if nb_c.size:
        return power, log_pd, index, nb_power
    return power, log_pd, index


def _poses(rng, t=3, a=5, n=257):
    xy = rng.uniform(-800, 800, (t, 2, n)).astype(np.float32)
    xy[0, :, :3] = 0.0  # tags right under a receiver at the origin
    rx = np.zeros((a, 3), np.float32)
    rx[:, :2] = rng.uniform(-300, 300, (a, 2))
    rx[0] = (0.0, 0.0, 0.0)  # ... and at zero height: the distance clamp
    rx[1:, 2] = 50.0
    yaw = rng.uniform(0, 2 * np.pi, a).astype(np.float32)
    return xy, rx, yaw


@pytest.mark.parametrize(
    "radio",
    [
        RadioModel(),
        RadioModel(front_back_db=0.0),
        RadioModel(d0_m=10.0, p0_db=-20.0, path_loss_exponent=2.7, front_back_db=6.0),
        RadioModel(min_distance_m=5.0),
    ],
)
def test_grid_is_the_radio_model(radio):
    xy, rx, yaw = _poses(np.random.default_rng(0))
    power, log_pd, index = _grid(radio, xy, rx, yaw)
    expected = radio.power_db(xy.transpose(0, 2, 1)[:, None].astype(np.float64),
                              rx[None, :, None].astype(np.float64),
                              yaw[None, :, None].astype(np.float64))
    np.testing.assert_allclose(power, expected, atol=1e-4)
    # the same entry, or its neighbour where rounding differs (the table step is 0.005 dB)
    np.testing.assert_allclose(log_pd, detection_table(radio).log_pd(power), atol=1e-3)
    assert index.min() >= 0


def test_grid_with_per_particle_offsets_and_exponents():
    radio = RadioModel(d0_m=2.0)
    rng = np.random.default_rng(1)
    xy, rx, yaw = _poses(rng, t=2)
    offset = rng.normal(0.0, 4.0, (2, xy.shape[2])).astype(np.float32)
    exponent = rng.uniform(1.2, 2.2, (2, xy.shape[2])).astype(np.float32)
    power, _, _ = _grid(radio, xy, rx, yaw, offset, exponent)
    log_term, gain = radio.geometry(xy.transpose(0, 2, 1)[:, None].astype(np.float64),
                                    rx[None, :, None].astype(np.float64),
                                    yaw[None, :, None].astype(np.float64))
    expected = radio.p0_db + offset[:, None] + exponent[:, None] * log_term + gain
    np.testing.assert_allclose(power, expected, atol=2e-4)
    # the power from the shadowing neighbours' centroid, where they have weight
    nb_c = np.array([[0.0, 0.7, 0.0, 1.0, 0.3]] * 2, np.float32)
    nb_xy = (rx[None, :, :2] + rng.uniform(-80, 80, (2, rx.shape[0], 2))).astype(np.float32)
    again, _, _, nb_power = _grid(radio, xy, rx, yaw, offset, exponent, nb_c, nb_xy)
    np.testing.assert_array_equal(again, power)
    centre = np.concatenate([nb_xy, rx[None, :, 2:].repeat(2, 0)], axis=-1)
    log_term, gain = radio.geometry(xy.transpose(0, 2, 1)[:, None].astype(np.float64),
                                    centre[:, :, None].astype(np.float64),
                                    yaw[None, :, None].astype(np.float64))
    expected = radio.p0_db + offset[:, None] + exponent[:, None] * log_term + gain
    has = nb_c != 0
    np.testing.assert_allclose(nb_power[has], expected[has], atol=2e-4)
    assert np.all(np.isnan(nb_power[~has]))  # not computed where the weight is 0


def test_float32_exp_and_log_are_float32_accurate():
    @kernel
    def apply(x, out_exp, out_log, lanes):
        for i in range(x.shape[0]):
            out_exp[i] = exp32(-x[i])
            out_log[i] = log32(x[i])
        return max_lanes(out_log, lanes)

    rng = np.random.default_rng(2)
    x = np.concatenate([10.0 ** rng.uniform(-6, 6, 5000), [1.0, 87.0, 87.5, np.inf]])
    x = x.astype(np.float32)
    e, lg = np.empty_like(x), np.empty_like(x)
    top = apply(x, e, lg, np.empty(16, np.float32))
    ref = np.exp(-x.astype(np.float64))
    normal = ref > 1.2e-38
    np.testing.assert_allclose(e[normal], ref[normal], rtol=2e-7)
    assert np.all(e[x > 87.3] == 0.0)  # below float32's range (and exp(-inf)): exactly 0
    finite = np.isfinite(x)
    np.testing.assert_allclose(lg[finite], np.log(x[finite].astype(np.float64)), atol=3e-7,
                               rtol=2e-7)
    assert top == lg.max()


# -- the update step ------------------------------------------------------------------------

def _noise(radio, shape):
    """Per (tag, action) noise variances: the receiver's, and larger ones (PulseNoise)."""
    return radio.noise_var * (1.0 + np.arange(shape[0] * shape[1]).reshape(shape[:2]) % 3)


def _reference(power, log_pd, table, z, p, log_w, radio, alpha, pooled, nb=None):
    """core.rollout's equations in float64 numpy: per row (T, A, R) the carried normalised
    log-weights and the gain. nb: (c (T, A), q (T, A, N)) the shadowing neighbours' weight
    and the power from their centroid (core.radio_belief.PulseNoise)."""
    noise = _noise(radio, log_w.shape)
    pd = np.exp(log_pd.astype(np.float64))
    miss = np.exp(table.log_miss(power).astype(np.float64))
    prior = log_w - logsumexp(log_w)[..., None]
    out_lw = np.empty(log_w.shape)
    gains = np.empty(log_w.shape[:-1])
    for t, a, r in np.ndindex(*log_w.shape[:-1]):
        pr, pt = prior[t, a, r], float(p[t, a, r])
        zt, pw = z[t, a, r], power[t, a].astype(np.float64)
        if nb is not None and nb[0][t, a] != 0.0:  # z~ = z - c E[q], P~ = P - c q
            c, q = float(nb[0][t, a]), nb[1][t, a].astype(np.float64)
            zt, pw = zt - c * (np.exp(pr) @ q), pw - c * q
        det = np.log(pd[t, a]) - (zt - pw) ** 2 / (2 * noise[t, a])
        if pooled or pt == 0.0:
            ll = pt * det + (1 - pt) * np.log(miss[t, a]) if pt < 1 else det
            post = pr + ll
            post -= logsumexp(post)
            out_lw[t, a, r] = post
            gains[t, a, r] = renyi_divergence(post, pr, alpha)
            continue
        q = 1.0 - pt  # "branches": detected with weight p, missed with q
        post_d = pr + det - logsumexp(pr + det)
        post_m = pr + np.log(miss[t, a]) - logsumexp(pr + np.log(miss[t, a]))
        gains[t, a, r] = (pt * renyi_divergence(post_d, pr, alpha)
                          + q * renyi_divergence(post_m, pr, alpha))
        with np.errstate(divide="ignore"):  # q = 0 (p = 1): the detected branch alone
            out_lw[t, a, r] = np.logaddexp(np.log(pt) + post_d, np.log(q) + post_m)
    return out_lw, gains


def _run_update(power, log_pd, index, table, z, p, log_w, radio, alpha, pooled, nb=None):
    shape = log_w.shape
    nb_c, nb_power = (NONE, NONE[None]) if nb is None else nb
    lw32 = (log_w - log_w.max(-1, keepdims=True)).astype(np.float32)
    w32 = np.exp(lw32)
    log_total = logsumexp(lw32)
    out_lw, out_w = np.empty(shape, np.float32), np.empty(shape, np.float32)
    out_total, value = np.empty(shape[:-1]), np.zeros(shape[:-1])
    update_step(power, log_pd, index, z.astype(np.float32), p.astype(np.float32), lw32, w32,
                log_total, table.arrays(alpha).update, 0.5 / _noise(radio, shape), nb_c,
                nb_power, alpha, pooled, 1.0, out_lw, out_w, out_total, value)
    return out_lw, out_w, out_total, value


@pytest.mark.parametrize("conditioned", [False, True])
@pytest.mark.parametrize("pooled", [True, False])
@pytest.mark.parametrize("alpha", [0.1, 0.5, 2.0])
def test_update_is_bayes_rule_and_the_gain_is_the_renyi_divergence(pooled, alpha, conditioned):
    radio = RadioModel()
    table = detection_table(radio)
    rng = np.random.default_rng(3)
    xy, rx, yaw = _poses(rng, t=2, a=3, n=200)
    xy *= 0.2  # within detection range
    nb = None
    if conditioned:  # some rows conditioned on shadowing neighbours, some not
        nb_c = np.array([[0.0, 0.6, 0.95], [0.3, 0.0, 1.02]], np.float32)
        nb_xy = (rx[None, :, :2] + rng.uniform(-60, 60, (2, 3, 2))).astype(np.float32)
        power, log_pd, index, nb_power = _grid(radio, xy, rx, yaw, NONE, NONE, nb_c, nb_xy)
        nb = (nb_c, np.nan_to_num(nb_power))
    else:
        power, log_pd, index = _grid(radio, xy, rx, yaw)
    n_roll = 4  # rows share their action's grid, as MC rollouts do
    z = rng.uniform(-60.0, -35.0, (2, 3, n_roll))
    p = np.array([1.0, 0.0, 0.3, 0.8])[None, None, :] * np.ones((2, 3, 1))
    log_w = np.log(rng.dirichlet(np.ones(200) * 0.5, size=(2, 3, n_roll)))
    out_lw, out_w, out_total, value = _run_update(power, log_pd, index, table, z, p, log_w,
                                                  radio, alpha, pooled, nb)
    ref_lw, ref_gain = _reference(power, log_pd, table, z, p, log_w, radio, alpha, pooled, nb)
    got = out_lw.astype(np.float64) - out_total[..., None]
    np.testing.assert_allclose(got, ref_lw, atol=2e-3)
    np.testing.assert_allclose(value, ref_gain, rtol=2e-3, atol=1e-5)
    # linear and log agree (exp32 flushes what is below float32's normal range to 0)
    np.testing.assert_allclose(out_w, np.exp(out_lw), rtol=1e-5, atol=1.2e-38)
    assert np.all(out_lw.max(-1) <= 0.0) and np.all(value >= 0.0)


def test_gain_when_the_posterior_sits_on_a_particle_of_prior_weight_e_minus_300():
    """The float32 fast sum underflows: the row is redone exactly."""
    radio = RadioModel(noise_std_db=0.05)
    table = detection_table(radio)
    power = np.full((1, 1, 10), -70.0, np.float32)
    power[0, 0, 3] = -40.0
    log_pd = table.log_pd(power)
    index = np.zeros((1, 1, 10), np.int32)
    log_w = np.zeros((1, 1, 1, 10))
    log_w[..., 3] = -300.0
    z, p = np.full((1, 1, 1), -40.0), np.ones((1, 1, 1))
    _, _, _, value = _run_update(power, log_pd, index, table, z, p, log_w, radio, 0.1, True)
    _, ref = _reference(power, log_pd, table, z, p, log_w, radio, 0.1, True)
    assert np.isfinite(value).all()
    assert value[0, 0, 0] == pytest.approx(ref[0, 0, 0], rel=1e-4)
    assert ref[0, 0, 0] == pytest.approx(300.0 + math.log(9.0), rel=1e-3)


def test_no_nan_when_every_likelihood_underflows():
    """A measurement far from every particle: every likelihood below float64's range."""
    radio = RadioModel(noise_std_db=0.01)
    table = detection_table(radio)
    power = np.linspace(-90.0, -80.0, 96, dtype=np.float32)[None, None, :]
    log_pd = table.log_pd(power)
    index = np.zeros(power.shape, np.int32)
    log_w = np.full((1, 1, 1, 96), -math.log(96))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out_lw, out_w, out_total, value = _run_update(
            power, log_pd, index, table, np.full((1, 1, 1), 1.0e6), np.ones((1, 1, 1)), log_w,
            radio, 0.1, True)
    assert np.all(np.isfinite(out_lw[out_w > 0])) and np.isfinite(out_total).all()
    assert out_w.max() == 1.0 and np.isfinite(value).all()


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60),
       alpha=st.sampled_from([0.05, 0.1, 0.3, 0.7, 0.95]), p=st.floats(0.0, 1.0),
       pooled=st.booleans())
def test_update_matches_the_reference_on_any_belief(seed, n, alpha, p, pooled):
    radio = RadioModel()
    table = detection_table(radio)
    rng = np.random.default_rng(seed)
    power = rng.uniform(-75.0, -35.0, (1, 1, n)).astype(np.float32)
    log_pd = table.log_pd(power)
    index = np.clip((power * table.inv_step + table.offset).astype(np.int32), 0, None)
    log_w = np.log(rng.dirichlet(np.ones(n)))[None, None, None]
    z = np.full((1, 1, 1), rng.uniform(-70.0, -35.0))
    pp = np.full((1, 1, 1), p, np.float32).astype(np.float64)
    out_lw, _, out_total, value = _run_update(power, log_pd, index, table, z, pp, log_w, radio,
                                              alpha, pooled)
    ref_lw, ref_gain = _reference(power, log_pd, table, z, pp, log_w, radio, alpha, pooled)
    assert np.isfinite(value).all() and value[0, 0, 0] >= 0.0
    assert value[0, 0, 0] == pytest.approx(ref_gain[0, 0, 0], rel=5e-3, abs=1e-4)
    np.testing.assert_allclose(out_lw[0, 0, 0] - out_total[0, 0, 0], ref_lw[0, 0, 0], atol=5e-3)


def test_workspace_reuses_and_grows_buffers():
    ws = Workspace()
    a = ws.get("x", (4, 5))
    b = ws.get("x", (2, 3))
    assert np.shares_memory(a, b) and b.flags.c_contiguous
    c = ws.get("x", (10, 10))
    assert c.shape == (10, 10) and ws.nbytes == 400
    assert ws.get("i", (3,), np.int32).dtype == np.int32


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1),
       n=st.integers(1, 70).filter(lambda k: k % 16 != 0),
       alpha=st.floats(0.02, 10.0).filter(lambda a: abs(a - 1.0) > 0.05),
       p=st.floats(0.0, 1.0), pooled=st.booleans())
def test_padded_rows_match_the_reference_for_any_alpha(seed, n, alpha, p, pooled):
    """The particle axis padded to a multiple of 16 with zero-weight (-inf) entries, as
    core.rollout pads it: for alpha > 1 the exact Renyi sum must skip them, not meet them as
    alpha (-inf) + (1 - alpha) (-inf) = -inf + inf."""
    radio = RadioModel()
    table = detection_table(radio)
    rng = np.random.default_rng(seed)
    n_pad = -(-n // 16) * 16
    power = rng.uniform(-75.0, -35.0, (1, 1, n_pad)).astype(np.float32)
    power[..., n:] = power[..., :1]  # copies of particle 0, as core.rollout pads
    log_pd = table.log_pd(power)
    index = np.clip((power * table.inv_step + table.offset).astype(np.int32), 0, None)
    log_w = np.full((1, 1, 1, n_pad), -np.inf)
    log_w[..., :n] = np.log(rng.dirichlet(np.ones(n)))
    z = np.full((1, 1, 1), rng.uniform(-70.0, -35.0))
    pp = np.full((1, 1, 1), p, np.float32).astype(np.float64)
    out_lw, out_w, out_total, value = _run_update(power, log_pd, index, table, z, pp, log_w,
                                                  radio, alpha, pooled)
    ref_lw, ref_gain = _reference(power[..., :n], log_pd[..., :n], table, z, pp,
                                  log_w[..., :n], radio, alpha, pooled)
    assert np.isfinite(value).all() and value[0, 0, 0] >= 0.0
    assert value[0, 0, 0] == pytest.approx(ref_gain[0, 0, 0], rel=5e-3, abs=1e-4)
    np.testing.assert_allclose(out_lw[0, 0, 0, :n] - out_total[0, 0, 0], ref_lw[0, 0, 0],
                               atol=5e-3)
    assert np.all(out_w[..., n:] == 0.0)  # the padding keeps zero weight
