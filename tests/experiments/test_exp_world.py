"""The experiment world: point-mass vehicle, truth trajectories, radio draws."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.paths import vehicle_paths
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.errors import MexgenError
from mexgen_gcs.experiments.scenario import MODELS, scenario
from mexgen_gcs.experiments.world import PointMass, RadioWorld, make_truth, truth_for


@settings(max_examples=60, deadline=None)
@given(
    v0=st.tuples(st.floats(-15, 15), st.floats(-15, 15)),
    heading_deg=st.floats(0, 359.9),
    dt_s=st.floats(0.05, 3.0),
    n=st.integers(1, 8),
)
def test_point_mass_flies_the_planner_path_model(v0: tuple[float, float], heading_deg: float,
                                                 dt_s: float, n: int) -> None:
    """Holding a heading, the point mass is where core.paths says the planner expects it,
    whatever the step size (the step is exact)."""
    pm = PointMass(10.0, -20.0, 50.0, max_speed_m_s=15.0, max_accel_m_s2=4.0)
    pm.v_east_m_s, pm.v_north_m_s = v0
    h = math.radians(heading_deg)
    expected = vehicle_paths(np.array([10.0, -20.0]), np.array(v0), np.array([h]), 15.0, 4.0,
                             np.array([n * dt_s]))[0, 0]
    for _ in range(n):
        pm.step(15.0 * math.sin(h), 15.0 * math.cos(h), heading_deg, dt_s)
    assert pm.east_m == pytest.approx(expected[0], abs=1e-6)
    assert pm.north_m == pytest.approx(expected[1], abs=1e-6)
    assert pm.alt_m == 50.0
    assert pm.yaw_deg == pytest.approx(heading_deg % 360.0)


def test_point_mass_limits_speed_and_acceleration() -> None:
    pm = PointMass(0.0, 0.0, 50.0, max_speed_m_s=15.0, max_accel_m_s2=4.0)
    pm.step(0.0, 100.0, 0.0, 1.0)  # asks 100 m/s north: 4 m/s after 1 s
    assert (pm.v_east_m_s, pm.v_north_m_s) == pytest.approx((0.0, 4.0))
    assert pm.north_m == pytest.approx(2.0)
    for _ in range(10):
        pm.step(0.0, 100.0, 0.0, 1.0)
    assert math.hypot(pm.v_east_m_s, pm.v_north_m_s) == pytest.approx(15.0)
    with pytest.raises(ValueError):
        PointMass(0.0, 0.0, 50.0, max_speed_m_s=0.0, max_accel_m_s2=4.0)


@pytest.mark.parametrize("kind", ["follow", "localise"])
@pytest.mark.parametrize("model", MODELS)
def test_truth_is_initialised_as_the_paper_says(kind: str, model: str) -> None:
    sc = scenario(kind, model)  # type: ignore[arg-type]
    truth = make_truth(sc, np.random.default_rng(3))
    states = truth.states
    assert states.shape == (sc.steps + 1, sc.n_tags, 4)
    # positions uniform in the initial search space
    assert np.all(np.abs(states[0, :, :2]) <= sc.initial_half_m)
    speed0 = np.hypot(states[0, :, 2], states[0, :, 3])
    if sc.truth_motion in ("rw", "static"):
        assert np.all(speed0 == 0.0)
    else:
        lo, hi = sc.truth_speed_m_s
        assert np.all((speed0 >= lo) & (speed0 <= hi))
    if sc.truth_motion == "cv-ift":
        assert np.all((truth.turn_rates_deg_s >= 10.0) & (truth.turn_rates_deg_s <= 15.0))
        assert set(np.unique(truth.modes)) <= {0, 1, 2}
    else:
        assert np.all(truth.turn_rates_deg_s == 0.0)
    # every object stays inside the search area for min_inside_s
    n_inside = math.ceil(sc.min_inside_s / sc.pulse_period_s)
    assert np.all(np.abs(states[: n_inside + 1, :, :2]) < sc.area_half_m)


def test_cv_ift_truth_turns_at_its_own_rate() -> None:
    """In a turn mode the heading changes by the object's own drawn rate per second."""
    sc = scenario("localise", "cv-ift")
    truth = make_truth(replace(sc, truth_accel_std_m_s2=0.0), np.random.default_rng(5))
    heading = np.unwrap(np.arctan2(truth.states[:, :, 3], truth.states[:, :, 2]), axis=0)
    turn = np.degrees(np.diff(heading, axis=0))  # (K, n_tags), ENU CCW positive
    sign = np.array([0.0, 1.0, -1.0])[truth.modes[1:]]
    np.testing.assert_allclose(turn, sign * truth.turn_rates_deg_s, atol=1e-6)
    assert np.any(truth.modes == 1) and np.any(truth.modes == 2) and np.any(truth.modes == 0)


def test_truth_depends_on_the_start_only() -> None:
    sc = scenario("localise", "cv", quick=True)
    a, b, c = truth_for(sc, 1, 0), truth_for(sc, 1, 0), truth_for(sc, 1, 1)
    assert a.digest() == b.digest() != c.digest()
    assert truth_for(sc, 2, 0).digest() != a.digest()


def test_truth_gives_up_when_containment_is_impossible() -> None:
    # 650 s at >= 2.5 m/s is >= 1.6 km, longer than the diagonal of a 1 km square
    sc = replace(scenario("localise", "cv"), area_half_m=500.0)
    with pytest.raises(MexgenError, match="stays inside"):
        make_truth(sc, np.random.default_rng(0), max_tries=200)


def test_radio_draws_do_not_depend_on_the_vehicle() -> None:
    """Common random numbers: two receivers in different places consume the radio stream
    identically, so the same noise reaches every method."""
    radio = RadioModel(clutter_rate=0.5)
    a = RadioWorld(radio, 4, np.random.default_rng(9))
    b = RadioWorld(radio, 4, np.random.default_rng(9))
    tags = np.array([[0.0, 0.0], [300.0, 0.0], [0.0, -300.0], [5000.0, 5000.0]])
    for k in range(50):
        za = a.pulse(tags, np.array([0.0, 0.0, 50.0]), 0.0)
        zb = b.pulse(tags, np.array([800.0 + k, -900.0, 50.0]), 2.0)
        assert [len(z) for z in za] != [] and len(za) == len(zb) == 4
    assert a.rng.bit_generator.state == b.rng.bit_generator.state


def test_radio_detects_near_tags_with_the_model_noise() -> None:
    radio = RadioModel(clutter_rate=0.0)
    world = RadioWorld(radio, 1, np.random.default_rng(1))
    rx = np.array([0.0, 0.0, 50.0])
    tag = np.array([[30.0, 40.0]])
    zs = [world.pulse(tag, rx, 0.0)[0] for _ in range(4000)]
    hits = np.array([z[0] for z in zs if z])
    p = float(radio.power_db(tag[0], rx, 0.0))
    assert len(hits) / len(zs) == pytest.approx(radio.detection_probability(np.array(p)),
                                               abs=0.02)
    assert hits.mean() == pytest.approx(p, abs=0.15)
    assert hits.std() == pytest.approx(radio.noise_std_db, rel=0.05)
