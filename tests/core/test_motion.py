"""Motion models: sample moments against closed forms, IMM occupancy, determinism by seed."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.motion import (
    ConstantTurnRate,
    ConstantVelocity,
    CvIft,
    RandomWalk,
    _transition_for,
    make_motion_model,
    simulate,
)

N = 100_000


def _run(model, state, mode, dt, steps, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        state, mode = model.propagate(state, mode, dt, rng)
    return state, mode


def test_random_walk_variance_grows_linearly():
    model = RandomWalk(std_m_per_sqrt_s=2.0)
    s, _ = _run(model, np.zeros((N, 4)), np.zeros(N, np.int8), 0.5, 20)  # t = 10 s
    assert s[:, :2].mean(axis=0) == pytest.approx([0, 0], abs=0.1)
    assert s[:, :2].var(axis=0) == pytest.approx([40.0, 40.0], rel=0.02)
    assert np.all(s[:, 2:] == 0)


def test_static_tag_never_moves():
    s0 = np.tile([10.0, -5.0, 0.0, 0.0], (5, 1))
    s, _ = _run(make_motion_model("static"), s0, np.zeros(5, np.int8), 1.0, 50)
    np.testing.assert_array_equal(s, s0)


def test_constant_velocity_mean_and_covariance_match_dwna():
    q, dt, steps = 0.3, 1.0, 10
    model = ConstantVelocity(accel_std_m_s2=q)
    s0 = np.tile([0.0, 0.0, 3.0, -1.0], (N, 1))
    s, _ = _run(model, s0, np.zeros(N, np.int8), dt, steps)
    t = dt * steps
    assert s[:, 0].mean() == pytest.approx(3.0 * t, abs=0.1)
    assert s[:, 1].mean() == pytest.approx(-1.0 * t, abs=0.1)
    # closed-form DWNA covariance after `steps` steps, per axis
    f = np.array([[1.0, dt], [0.0, 1.0]])
    qm = q * q * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    p = np.zeros((2, 2))
    for _ in range(steps):
        p = f @ p @ f.T + qm
    assert s[:, 0].var() == pytest.approx(p[0, 0], rel=0.03)
    assert s[:, 2].var() == pytest.approx(p[1, 1], rel=0.03)
    assert np.cov(s[:, 0], s[:, 2])[0, 1] == pytest.approx(p[0, 1], rel=0.05)


def test_constant_turn_closes_a_circle():
    w = math.radians(12.0)
    model = ConstantTurnRate(turn_rate_rad_s=w, accel_std_m_s2=0.0)
    s0 = np.array([[0.0, 0.0, 5.0, 0.0]])
    period = 2 * math.pi / w  # 30 s
    s, _ = _run(model, s0, np.zeros(1, np.int8), period / 60, 60)
    np.testing.assert_allclose(s, s0, atol=1e-9)
    # a quarter turn left (CCW) of an eastbound tag ends heading north, radius v / w
    s, _ = _run(model, s0, np.zeros(1, np.int8), period / 4, 1)
    r = 5.0 / w
    np.testing.assert_allclose(s[0], [r, r, 0.0, 5.0], atol=1e-9)
    # negative rate turns right
    right = ConstantTurnRate(turn_rate_rad_s=-w, accel_std_m_s2=0.0)
    s, _ = _run(right, s0, np.zeros(1, np.int8), period / 4, 1)
    np.testing.assert_allclose(s[0], [r, -r, 0.0, -5.0], atol=1e-9)


def test_turn_rate_per_object_broadcasts():
    rates = np.radians([10.0, 15.0])
    model = ConstantTurnRate(turn_rate_rad_s=rates, accel_std_m_s2=0.0)
    s, _ = _run(model, np.tile([0.0, 0, 5, 0], (2, 1)), np.zeros(2, np.int8), 1.0, 3)
    headings = np.degrees(np.arctan2(s[:, 3], s[:, 2]))
    np.testing.assert_allclose(headings, [30.0, 45.0], atol=1e-9)


def test_imm_mode_occupancy_converges_to_stationary_distribution():
    model = CvIft(accel_std_m_s2=0.0)
    pi = model.stationary_distribution()
    np.testing.assert_allclose(pi, [0.9, 0.05, 0.05], atol=1e-12)
    rng = np.random.default_rng(5)
    mode = np.zeros(N, np.int8)  # all start in CV
    for _ in range(200):
        mode = model.switch(mode, 1.0, rng)
    occupancy = np.bincount(mode, minlength=3) / N
    np.testing.assert_allclose(occupancy, pi, atol=0.005)
    # one step from CV follows the first row of the matrix
    one = model.switch(np.zeros(N, np.int8), 1.0, rng)
    np.testing.assert_allclose(np.bincount(one, minlength=3) / N, [0.975, 0.0125, 0.0125],
                               atol=0.002)


def test_imm_fractional_step_composes():
    model = CvIft()
    rng = np.random.default_rng(9)
    m = np.zeros(N, np.int8)
    m2 = model.switch(model.switch(m, 0.5, rng), 0.5, rng)
    m1 = model.switch(m, 1.0, rng)
    np.testing.assert_allclose(np.bincount(m2, minlength=3) / N,
                               np.bincount(m1, minlength=3) / N, atol=0.004)


def test_imm_speed_is_preserved_without_noise():
    model = make_motion_model("cv-ift", accel_std_m_s2=0.0, speed_min_m_s=2.5, speed_max_m_s=3.0)
    rng = np.random.default_rng(1)
    s, m = model.initial(np.zeros((1000, 2)), rng)
    traj, modes = simulate(model, s, m, 1.0, 100, rng)
    speeds = np.hypot(traj[..., 2], traj[..., 3])
    np.testing.assert_allclose(speeds[-1], speeds[0], rtol=1e-9)
    assert speeds.min() >= 2.5 and speeds.max() <= 3.0
    assert traj.shape == (101, 1000, 4) and modes.shape == (101, 1000)


def test_same_seed_same_trajectory_and_inputs_untouched():
    model = make_motion_model("cv-ift")
    s0 = np.tile([0.0, 0, 3, 0], (10, 1))
    m0 = np.zeros(10, np.int8)
    a = simulate(model, s0, m0, 1.0, 30, np.random.default_rng(42))
    b = simulate(model, s0, m0, 1.0, 30, np.random.default_rng(42))
    np.testing.assert_array_equal(a[0], b[0])
    assert np.all(s0[:, 2] == 3) and np.all(m0 == 0)


def test_unknown_model_name():
    with pytest.raises(ValueError, match="unknown motion model"):
        make_motion_model("teleport")  # type: ignore[arg-type]


def _reference_propagate(model, state, mode, dt, rng):
    """The models' equations in numpy, drawing as numpy would (mode uniforms, then (n, 2)
    accelerations)."""
    if isinstance(model, RandomWalk):
        out = state.copy()
        out[..., 2:] = 0.0
        out[..., :2] += rng.normal(0.0, model.std_m_per_sqrt_s * math.sqrt(dt),
                                   size=out[..., :2].shape)
        return out, mode
    if isinstance(model, CvIft):
        cum = _transition_for(model.transition, dt / model.switch_period_s)  # matrix power
        u = rng.random(mode.shape)
        mode = (u[..., None] >= cum[mode, :-1]).sum(axis=-1).astype(np.int8)
        omega = np.array([0.0, 1.0, -1.0])[mode] * model.turn_rate_rad_s
    elif isinstance(model, ConstantTurnRate):
        omega = np.broadcast_to(model.turn_rate_rad_s, state.shape[:-1])
    else:
        omega = np.zeros(state.shape[:-1])
    small = np.abs(omega) < 1e-9
    safe = np.where(small, 1.0, omega)
    s, c = np.sin(omega * dt), np.cos(omega * dt)
    a = np.where(small, dt, s / safe)
    b = np.where(small, 0.0, (1.0 - c) / safe)
    vx, vy = state[..., 2], state[..., 3]
    out = np.stack([state[..., 0] + a * vx - b * vy, state[..., 1] + b * vx + a * vy,
                    c * vx - s * vy, s * vx + c * vy], axis=-1)
    acc = rng.normal(0.0, model.accel_std_m_s2, size=out[..., :2].shape)
    out[..., :2] += 0.5 * dt * dt * acc
    out[..., 2:] += dt * acc
    return out, mode


@pytest.mark.parametrize("name", ["rw", "cv", "ctra", "cv-ift", "ctra-rates", "cv-ift-rates"])
def test_compiled_propagate_is_the_numpy_equations_with_the_same_draws(name):
    if name.endswith("-rates"):
        base = make_motion_model(name.removesuffix("-rates"))
        rates = np.radians(np.linspace(-15.0, 15.0, 300))
        model = (ConstantTurnRate(turn_rate_rad_s=rates) if base.n_modes == 1
                 else CvIft(turn_rate_rad_s=rates))
    else:
        model = make_motion_model(name)
    rng = np.random.default_rng(4)
    state, mode = make_motion_model("cv-ift").initial(rng.uniform(-100, 100, (300, 2)), rng)
    ours, ref = (state, mode), (state, mode)
    for _ in range(5):
        ours = model.propagate(*ours, 0.7, r1 := np.random.default_rng(len(name)))
        ref = _reference_propagate(model, *ref, 0.7, r2 := np.random.default_rng(len(name)))
        assert r1.random() == r2.random()  # the same numbers drawn
        np.testing.assert_allclose(ours[0], ref[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(ours[1], ref[1])


@pytest.mark.parametrize("name", ["static", "rw", "cv", "ctra", "cv-ift", "cv-mismatch"])
def test_predicted_positions_are_repeated_propagation_with_the_same_draws(name):
    """The planner's one-call look-ahead equals propagating step by step from the same
    generator state, exactly, and leaves the generator where step by step would."""
    from mexgen_gcs.core.motion import predict_positions

    model = make_motion_model(name)
    rng0 = np.random.default_rng(5)
    state, mode = model.initial(rng0.uniform(-100, 100, (300, 2)), rng0)
    a, b = np.random.default_rng(9), np.random.default_rng(9)
    got = predict_positions(model, state, mode, 0.7, 12, a)
    s, m = state, mode
    for k in range(12):
        s, m = model.propagate(s, m, 0.7, b)
        np.testing.assert_array_equal(got[k], s[:, :2])
    assert a.random() == b.random()
