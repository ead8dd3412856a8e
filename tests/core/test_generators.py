"""Measurement generators: one contract for PIM, MexGen-M and MC-M, the linear-model identities,
and the paper's lemma (MexGen's expected error <= PIM's + sigma^2 / M) on bimodal beliefs."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.generators import (
    BeliefView,
    MexGen,
    MonteCarlo,
    PredictedIdealMeasurement,
    make_generator,
)
from mexgen_gcs.core.radio import RadioModel

GENERATORS = [
    PredictedIdealMeasurement(),
    MexGen(64),
    MexGen(64, stratified=False),
    MonteCarlo(8),
]
IDS = ["pim", "mexgen", "mexgen-iid", "mc"]


def linear_view(weights, positions, a=(0.3, -0.2), b=-40.0, noise_std=2.0, pd=1.0):
    """A view whose measurement function is linear, h(x) = a.x + b, with constant pD."""
    a = np.asarray(a)
    power = (positions @ a + b).astype(np.float32)
    with np.errstate(divide="ignore"):
        log_pd = np.full(power.shape, max(math.log(pd), -1e4) if pd > 0 else -1e4, np.float32)
    return BeliefView(
        weights=weights,
        positions_m=positions,
        power_db=power,
        log_pd=log_pd,
        mean_power=lambda p: p @ a + b,
        detection_probability=lambda p: np.full(np.shape(p), pd),
        noise_std_db=noise_std,
    )


def radio_view(weights, positions, radio, rx=(0.0, 0.0, 50.0), yaw=0.0):
    """A view of the radio model from one receiver pose."""
    rx = np.asarray(rx, np.float64)
    power = radio.power_db(positions, rx, yaw).astype(np.float32)
    with np.errstate(divide="ignore"):
        log_pd = np.maximum(np.log(radio.detection_probability(power.astype(np.float64))), -1e4)
    return BeliefView(
        weights=weights,
        positions_m=positions,
        power_db=power,
        log_pd=log_pd.astype(np.float32),
        mean_power=lambda p: radio.power_db(p, rx, yaw),
        detection_probability=radio.detection_probability,
        noise_std_db=radio.noise_std_db,
    )


def bimodal(rng, n=1000, centres=((-300.0, 0.0), (300.0, 0.0)), spread=30.0, frac=0.5):
    k = round(n * frac)
    return np.concatenate([
        rng.normal(centres[0], spread, (k, 2)),
        rng.normal(centres[1], spread, (n - k, 2)),
    ])


# -- the contract, for every generator --------------------------------------------------------


@pytest.mark.parametrize("gen", GENERATORS, ids=IDS)
def test_contract_shapes_types_and_reproducibility(gen):
    rng = np.random.default_rng(0)
    pos = rng.normal(0.0, 100.0, (50, 2))
    w = rng.dirichlet(np.ones(50), size=(2, 3, gen.rollouts)).astype(np.float32)
    view = linear_view(w, pos)
    before = (w.copy(), view.power_db.copy())
    a = gen.generate(view, np.random.default_rng(5))
    b = gen.generate(view, np.random.default_rng(5))
    assert a.z_db.shape == a.p_detect.shape == (2, 3, gen.rollouts)
    assert a.z_db.dtype == np.float32 and a.p_detect.dtype == np.float32
    assert np.all(np.isfinite(a.z_db))
    assert np.all((a.p_detect >= 0.0) & (a.p_detect <= 1.0))
    np.testing.assert_array_equal(a.z_db, b.z_db)
    np.testing.assert_array_equal(a.p_detect, b.p_detect)
    np.testing.assert_array_equal(w, before[0])
    np.testing.assert_array_equal(view.power_db, before[1])


@pytest.mark.parametrize("gen", GENERATORS, ids=IDS)
def test_weights_need_not_be_normalised(gen):
    rng = np.random.default_rng(1)
    pos = rng.normal(0.0, 100.0, (40, 2))
    w = rng.dirichlet(np.ones(40), size=4).astype(np.float32)
    a = gen.generate(linear_view(w, pos), np.random.default_rng(2))
    b = gen.generate(linear_view(w * 123.0, pos), np.random.default_rng(2))
    np.testing.assert_allclose(a.z_db, b.z_db, rtol=1e-5)
    np.testing.assert_allclose(a.p_detect, b.p_detect, rtol=1e-5)


def test_make_generator():
    assert isinstance(make_generator("pim"), PredictedIdealMeasurement)
    assert make_generator("mexgen", samples=7).samples == 7
    assert make_generator("mc", mc_rollouts=3).rollouts == 3
    with pytest.raises(ValueError):
        make_generator("nope")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        MexGen(0)
    with pytest.raises(ValueError):
        MonteCarlo(0)


# -- linear model: where the generators must agree --------------------------------------------


def test_pim_equals_the_expected_measurement_for_a_linear_model():
    rng = np.random.default_rng(3)
    pos = bimodal(rng, 500)
    w = rng.dirichlet(np.ones(500), size=6)
    view = linear_view(w, pos)
    out = PredictedIdealMeasurement().generate(view, rng)
    expected = w @ view.power_db.astype(np.float64)  # E[h(x)] = h(E[x]) when h is linear
    np.testing.assert_allclose(out.z_db, expected, rtol=1e-5)
    np.testing.assert_array_equal(out.p_detect, 1.0)


@pytest.mark.parametrize("stratified", [True, False])
def test_mexgen_converges_to_the_exact_expectation(stratified):
    rng = np.random.default_rng(4)
    pos = bimodal(rng, 400)
    w = rng.dirichlet(np.ones(400))
    view0 = linear_view(w, pos, noise_std=2.0)
    exact = float(w @ view0.power_db.astype(np.float64))
    sigma2 = float(w @ (view0.power_db - exact) ** 2) + 2.0**2  # predictive variance
    reps = 400
    rms = {}
    for m in (4, 64, 1024):
        view = linear_view(np.broadcast_to(w, (reps, 400)).astype(np.float32), pos, noise_std=2.0)
        z = MexGen(m, stratified).generate(view, np.random.default_rng(m)).z_db
        assert abs(z.mean() - exact) < 5 * math.sqrt(sigma2 / m / reps)  # unbiased
        rms[m] = math.sqrt(np.mean((z.astype(np.float64) - exact) ** 2))
        assert rms[m] <= 1.2 * math.sqrt(sigma2 / m)  # the lemma's epsilon = sigma^2 / M
    assert rms[1024] < rms[64] < rms[4]
    assert rms[1024] < 0.1 * rms[4]


def test_mc_draws_one_noisy_measurement_of_one_sampled_state():
    rng = np.random.default_rng(6)
    pos = bimodal(rng, 300)
    w = rng.dirichlet(np.ones(300))
    reps = 20_000
    view = linear_view(np.broadcast_to(w, (reps, 300)).astype(np.float32), pos, noise_std=2.0)
    z = MonteCarlo(1).generate(view, rng).z_db.astype(np.float64)
    p = view.power_db.astype(np.float64)
    mean = float(w @ p)
    var = float(w @ (p - mean) ** 2) + 4.0
    assert z.mean() == pytest.approx(mean, abs=5 * math.sqrt(var / reps))
    assert z.var() == pytest.approx(var, rel=0.05)  # the whole predictive spread, as the paper


# -- detection predictions against a direct computation --------------------------------------


def _edge_view(rng, n=400, reps=1):
    """A belief straddling the detection edge of the mission-default radio (pD 0.1-0.9)."""
    radio = RadioModel()
    pos = rng.normal((2900.0, 0.0), 400.0, (n, 2))
    w = rng.dirichlet(np.ones(n))
    view = radio_view(np.broadcast_to(w, (reps, n)).astype(np.float32), pos, radio)
    pd = radio.detection_probability(view.power_db.astype(np.float64))
    return radio, pos, w, view, pd


def test_pim_predicts_pd_at_the_mean_states_noiseless_power():
    """A bimodal belief, one mode heard surely, one seldom: PIM's pD is that of the point
    between them, not the belief's mean pD."""
    rng = np.random.default_rng(7)
    radio = RadioModel()
    pos = bimodal(rng, 400, centres=((300.0, 0.0), (4200.0, 0.0)), spread=30.0)
    w = np.full((1, 400), 1.0 / 400)
    view = radio_view(w.astype(np.float32), pos, radio)
    out = PredictedIdealMeasurement().generate(view, rng)
    power = radio.power_db(w[0] @ pos, np.array([0.0, 0.0, 50.0]), 0.0)
    assert out.z_db[0] == pytest.approx(power, abs=1e-3)
    assert out.p_detect[0] == pytest.approx(radio.detection_probability(power), abs=1e-5)
    mean_pd = float(w[0] @ radio.detection_probability(view.power_db.astype(np.float64)))
    assert 0.3 < mean_pd < 0.7
    assert out.p_detect[0] > mean_pd + 0.15


def test_stratified_mexgen_predicts_the_belief_mean_pd_exactly():
    """sum w pD / sum w, with pD from the planner's table (log_pd in the view)."""
    rng = np.random.default_rng(8)
    _, _, w, view, pd = _edge_view(rng, reps=3)
    out = MexGen(512).generate(view, rng)
    table_pd = np.exp(view.log_pd.astype(np.float64))
    np.testing.assert_allclose(out.p_detect, w @ table_pd, rtol=1e-5)
    np.testing.assert_allclose(out.p_detect, w @ pd, atol=2e-3)  # table vs scipy


def test_independent_mexgen_predicts_the_detected_fraction_of_its_samples():
    rng = np.random.default_rng(9)
    m, reps = 256, 2000
    _, _, w, view, _ = _edge_view(rng, reps=reps)
    p = MexGen(m, stratified=False).generate(view, rng).p_detect.astype(np.float64)
    assert set(np.unique(np.round(p * m, 3))) <= set(range(m + 1))  # a fraction of M
    exact = float(w @ np.exp(view.log_pd.astype(np.float64)))
    se = math.sqrt(exact * (1.0 - exact) / m)
    assert abs(p.mean() - exact) < 5 * se / math.sqrt(reps)
    assert p.std() == pytest.approx(se, rel=0.1)  # binomial spread of M samples


def test_mexgen_z_is_the_mean_of_the_detected_samples_only():
    """Half the particles can be heard (pD = 1), half cannot (pD = 0)."""
    rng = np.random.default_rng(8)
    pos = rng.normal(0.0, 50.0, (200, 2))
    heard = np.arange(200) < 100
    for stratified in (True, False):
        w = np.where(heard, 0.7 / 100, 0.3 / 100)[None, :].astype(np.float32)
        view = linear_view(w, pos, noise_std=1e-3)
        view = BeliefView(**{**{f: getattr(view, f) for f in view.__slots__},
                             "log_pd": np.where(heard, 0.0, -1e4).astype(np.float32)})
        out = MexGen(2048, stratified).generate(view, rng)
        # stratified: exact up to float32 rounding of the sums
        assert out.p_detect[0] == pytest.approx(0.7, abs=1e-6 if stratified else 0.05)
        p_heard = view.power_db[heard].astype(np.float64)
        se = p_heard.std() / math.sqrt(0.7 * 2048)
        assert out.z_db[0] == pytest.approx(p_heard.mean(), abs=5 * se)


def test_mc_outcome_is_sampled_and_its_frequency_is_the_belief_average_pd():
    rng = np.random.default_rng(9)
    pos = rng.normal(0.0, 50.0, (100, 2))
    w = rng.dirichlet(np.ones(100))
    pd = np.where(np.arange(100) < 40, 0.9, 0.1)
    reps = 20_000
    view = linear_view(np.broadcast_to(w, (reps, 100)).astype(np.float32), pos)
    view = BeliefView(**{**{f: getattr(view, f) for f in view.__slots__},
                         "log_pd": np.log(pd).astype(np.float32)})
    p = MonteCarlo(1).generate(view, rng).p_detect
    assert set(np.unique(p)) == {0.0, 1.0}
    assert p.mean() == pytest.approx(float(w @ pd), abs=0.015)


# -- the paper's lemma on a bimodal belief and the radio model --------------------------------


def _predictive(view, w):
    """Exact mean and variance of the predictive measurement (pD = 1)."""
    p = view.power_db.astype(np.float64)
    mean = float(w @ p)
    return mean, float(w @ (p - mean) ** 2) + view.noise_std_db**2


def test_lemma_bimodal_mexgen_near_the_variance_floor_pim_far_above():
    rng = np.random.default_rng(10)
    radio = RadioModel(pd_max=1.0, sensitivity_db=-300.0)  # every pulse heard
    pos = bimodal(rng, 1000, spread=30.0)  # clusters 600 m apart, receiver between them
    w = np.full(1000, 1e-3)
    # samples of the true predictive distribution: a state from the belief, then its noise
    n_truth = 200_000
    pick = rng.integers(0, 1000, n_truth)
    truth = radio.power_db(pos[pick], np.array([0.0, 0.0, 50.0]), 0.0) + rng.normal(
        0.0, radio.noise_std_db, n_truth
    )
    floor = truth.var()  # the MSE of the best possible prediction, E[z]

    def mse(z_hat):
        return np.mean((np.asarray(z_hat, np.float64)[..., None] - truth) ** 2, axis=-1)

    reps = 64
    view = radio_view(np.broadcast_to(w, (reps, 1000)).astype(np.float32), pos, radio)
    mex = MexGen(512).generate(view, np.random.default_rng(11)).z_db
    pim = PredictedIdealMeasurement().generate(radio_view(w[None], pos, radio), rng).z_db
    mexgen_ratio = float(mse(mex).mean() / floor)
    pim_ratio = float(mse(pim)[0] / floor)
    assert mexgen_ratio - 1.0 < 0.03  # within a few percent of the floor
    assert pim_ratio > 3.0  # several times larger
    # and the exact decomposition agrees with the sampled one
    mean, var = _predictive(view, w)
    assert floor == pytest.approx(var, rel=0.02)
    assert pim_ratio == pytest.approx(((pim[0] - mean) ** 2 + var) / var, rel=0.05)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    separation=st.floats(0.0, 800.0),
    spread=st.floats(1.0, 150.0),
    frac=st.floats(0.05, 0.95),
    rx_xy=st.tuples(st.floats(-500, 500), st.floats(-500, 500)),
    yaw_deg=st.floats(0.0, 360.0),
    m=st.sampled_from([8, 32, 128, 512]),
    stratified=st.booleans(),
)
def test_lemma_mexgen_expected_error_never_exceeds_pim_plus_sigma2_over_m(
    seed, separation, spread, frac, rx_xy, yaw_deg, m, stratified
):
    """E[MSE_MexGen] = sigma^2 + E[(z_hat - z_bar)^2] <= MSE_PIM + sigma^2 / M (paper lemma)."""
    rng = np.random.default_rng(seed)
    radio = RadioModel(pd_max=1.0, sensitivity_db=-300.0)
    half = separation / 2.0
    pos = bimodal(rng, 400, centres=((-half, 100.0), (half, -50.0)), spread=spread, frac=frac)
    w = rng.dirichlet(np.full(400, 5.0))
    rx = (rx_xy[0], rx_xy[1], 50.0)
    yaw = math.radians(yaw_deg)
    reps = 256
    view = radio_view(np.broadcast_to(w, (reps, 400)).astype(np.float32), pos, radio, rx, yaw)
    mean, var = _predictive(view, w)
    z = MexGen(m, stratified).generate(view, rng).z_db.astype(np.float64)
    mexgen_excess = float(np.mean((z - mean) ** 2))  # E[MSE] - sigma^2
    pim = PredictedIdealMeasurement().generate(radio_view(w[None], pos, radio, rx, yaw), rng)
    pim_excess = (float(pim.z_db[0]) - mean) ** 2  # MSE_PIM - sigma^2 (float32 rounding aside)
    # sampling tolerance: 256 draws of a variance estimate (~9% s.e. for iid draws)
    assert mexgen_excess <= pim_excess + 1.5 * var / m + 1e-4
