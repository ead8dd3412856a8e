"""The rollout's detect/miss expectation against plain float64 references: today's single-branch
reward when every pulse is detected (pD = 1), and the module's equations ("pooled", "branches")
at the edge of detection."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.generators import BeliefView, MexGen, MonteCarlo, PredictedIdealMeasurement
from mexgen_gcs.core.likelihood import detection_table
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.paths import action_headings_rad, vehicle_paths
from mexgen_gcs.core.planner import TagBelief
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reward import logsumexp, renyi_divergence
from mexgen_gcs.core.rollout import rollout_gains

N = 1008  # a multiple of the rollout's padding: the reference needs no padding
STEPS, STEP_S, DISCOUNT, ALPHA = 8, 1.0, 0.95, 0.1
ALWAYS_HEARD = RadioModel(pd_max=1.0, sensitivity_db=-300.0)
FIELD = RadioModel()  # mission defaults: 3 dB front/back, -60 dB, 2 dB spread, pd_max 0.95
GENERATORS = {"pim": PredictedIdealMeasurement(), "mexgen": MexGen(128), "mc": MonteCarlo(4)}


def beliefs(centres, spread, seed=0):
    rng = np.random.default_rng(seed)
    model = make_motion_model("cv", accel_std_m_s2=0.1, speed_min_m_s=2.5, speed_max_m_s=3.0)
    out = []
    for i, c in enumerate(centres):
        states, modes = model.initial(rng.normal(c, spread, (N, 2)), rng)
        out.append(TagBelief(f"T{i + 1}", states, modes, model))
    return out


def paths_for(n_headings=8, speed=15.0):
    times = STEP_S * np.arange(1.0, STEPS + 1.0)
    headings = action_headings_rad(n_headings)
    return vehicle_paths(np.zeros(3), np.zeros(2), headings, speed, 4.0, times), headings


def reference(bel, paths, headings, radio, gen, rng, rule):
    """The rollout in float64, step by step as the equations read. ``rule``: "today" (the
    collapsed outcome before issue 12: PIM pD >= 0.5, MexGen majority of samples (= p >= 0.5
    for the stratified sampler), MC its sample), "pooled" or "branches"."""
    table = detection_table(radio)
    n_tags, n_act, n_roll = len(bel), len(headings), gen.rollouts
    xy = np.empty((STEPS, n_tags, 1, 1, N, 2))
    for i, b in enumerate(bel):  # the rollout's order of random draws: predict every step first
        state, mode = b.states, b.modes
        for k in range(STEPS):
            state, mode = b.motion.propagate(state, mode, STEP_S, rng)
            xy[k, i, 0, 0] = state[:, :2]
    yaw = headings[None, :, None]
    log_w = np.full((n_tags, n_act, n_roll, N), -math.log(N))  # normalised, float64
    value = np.zeros((n_tags, n_act, n_roll))
    for k in range(STEPS):
        rx = np.empty((1, n_act, 1, 3))
        rx[..., :2] = paths[k][None, :, None, :]
        rx[..., 2] = 50.0
        power = radio.power_db(xy[k], rx[..., None, :], yaw[..., None]).astype(np.float32)
        log_pd = table.log_pd(power).astype(np.float64)
        log_miss = table.log_miss(power).astype(np.float64)
        view = BeliefView(
            weights=np.exp(log_w - log_w.max(-1, keepdims=True)).astype(np.float32),
            positions_m=xy[k], power_db=power, log_pd=log_pd.astype(np.float32),
            mean_power=lambda p, rx=rx: radio.power_db(p, rx, yaw),
            detection_probability=radio.detection_probability,
            noise_std_db=radio.noise_std_db)
        meas = gen.generate(view, rng)
        p = meas.p_detect.astype(np.float64)[..., None]
        z = meas.z_db.astype(np.float64)[..., None]
        l_det = log_pd - (z - power) ** 2 / (2.0 * radio.noise_var)

        def post(log_lik, prior=log_w):
            a = prior + log_lik
            return a - logsumexp(a)[..., None]

        if rule == "today":
            detected = p >= 0.5 if not isinstance(gen, MonteCarlo) else p > 0.0
            new = post(np.where(detected, l_det, log_miss))
            gain = renyi_divergence(new, log_w, ALPHA)
        elif rule == "pooled":
            new = post(p * l_det + (1.0 - p) * log_miss)
            gain = renyi_divergence(new, log_w, ALPHA)
        else:
            plus, minus = post(l_det), post(log_miss)
            p = p[..., 0]
            gain = p * renyi_divergence(plus, log_w, ALPHA) + (1.0 - p) * renyi_divergence(
                minus, log_w, ALPHA)
            with np.errstate(divide="ignore"):
                new = np.logaddexp(np.log(p)[..., None] + plus, np.log1p(-p)[..., None] + minus)
        value += DISCOUNT**k * gain
        log_w = new
    return value.mean(axis=2)


def rollout(bel, paths, headings, radio, gen, rng, pooled):
    timing = dict.fromkeys(("predict", "measure", "update", "reward"), 0.0)
    return rollout_gains(bel, paths, 50.0, headings, radio, detection_table(radio), gen,
                         STEP_S, DISCOUNT, ALPHA, rng, timing, pooled=pooled)


@pytest.mark.parametrize("method", GENERATORS)
@pytest.mark.parametrize("pooled", [True, False])
def test_with_every_pulse_detected_the_expectation_is_todays_reward(method, pooled):
    """pD = 1 everywhere: p = 1 for PIM and MexGen, MC samples detections only, and both
    outcome rules reduce to the single detected branch the planner used before."""
    bel = beliefs([(300.0, 100.0), (-200.0, 400.0)], 120.0)
    paths, headings = paths_for()
    gen = GENERATORS[method]
    got = rollout(bel, paths, headings, ALWAYS_HEARD, gen, np.random.default_rng(1), pooled)
    want = reference(bel, paths, headings, ALWAYS_HEARD, gen, np.random.default_rng(1), "today")
    assert np.all(want > 0.0)
    np.testing.assert_allclose(got, want, rtol=2e-3)


@pytest.mark.parametrize("method", ["pim", "mexgen"])
@pytest.mark.parametrize("rule", ["pooled", "branches"])
def test_at_the_edge_of_detection_the_rollout_computes_its_equations(method, rule):
    """A tag 2.5-3 km away, mission-default radio (pD 0.2-0.8 over the belief): the float32,
    vectorised rollout equals the float64 step-by-step equations of the module docstring."""
    bel = beliefs([(0.0, 2700.0), (2300.0, -1500.0)], 250.0, seed=3)
    paths, headings = paths_for()
    gen = GENERATORS[method]
    got = rollout(bel, paths, headings, FIELD, gen, np.random.default_rng(2), rule == "pooled")
    want = reference(bel, paths, headings, FIELD, gen, np.random.default_rng(2), rule)
    today = reference(bel, paths, headings, FIELD, gen, np.random.default_rng(2), "today")
    # MexGen's stratified counts jump where a stratum boundary crosses a particle, so float32
    # weights (the rollout's) against float64 (the reference's) may move one sample: 1 %
    np.testing.assert_allclose(got, want, rtol=1e-2)
    assert not np.allclose(want, today, rtol=0.05)  # the outcome's treatment matters here


def test_mc_outcomes_are_sampled_as_before_under_either_rule():
    """MC's p is its sampled outcome (0 or 1): both rules are its single sampled branch."""
    bel = beliefs([(0.0, 2700.0)], 250.0, seed=4)
    paths, headings = paths_for()
    gen = GENERATORS["mc"]
    want = reference(bel, paths, headings, FIELD, gen, np.random.default_rng(5), "today")
    for pooled in (True, False):
        got = rollout(bel, paths, headings, FIELD, gen, np.random.default_rng(5), pooled)
        np.testing.assert_allclose(got, want, rtol=2e-3)
