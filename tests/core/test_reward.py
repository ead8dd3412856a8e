"""Renyi divergence reward and the action (turn) cost."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.reward import renyi_divergence, turn_cost


def test_divergence_of_equal_beliefs_is_zero():
    log_w = np.log(np.random.default_rng(0).dirichlet(np.ones(30), size=4))
    np.testing.assert_allclose(renyi_divergence(log_w, log_w, 0.1), 0.0, atol=1e-12)


@pytest.mark.parametrize("alpha", [0.1, 0.5, 0.9, 2.0])
def test_collapse_onto_one_of_two_equal_particles_gains_log_2(alpha):
    """Prior (1/2, 1/2), posterior (1, 0): sum w+^a w^(1-a) = 2^(a-1), so Psi = log 2."""
    prior = np.log([0.5, 0.5])
    post = np.array([0.0, -np.inf])
    assert renyi_divergence(post, prior, alpha) == pytest.approx(math.log(2.0))


def test_bad_alpha():
    for alpha in (0.0, 1.0, -0.5, math.nan):
        with pytest.raises(ValueError):
            renyi_divergence(np.zeros(2), np.zeros(2), alpha)


def test_turn_cost():
    h = np.radians([0.0, 90.0, 180.0, 270.0, 10.0])
    np.testing.assert_allclose(turn_cost(h, 0.0), [0.0, 0.5, 1.0, 0.5, 10 / 180])
    # wraps across north: 350 deg -> 10 deg is a 20 deg turn
    assert turn_cost(np.radians([10.0]), math.radians(350.0))[0] == pytest.approx(20 / 180)
