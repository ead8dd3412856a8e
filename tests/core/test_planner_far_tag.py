"""The planner at the edge of detection (issue 12): with the mission-default radio a tag 1.5-2 km
away is approached, not kept at the edge of the receiver's range; and the look-ahead reaches it."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.planner import Planner, PlannerConfig, TagBelief, VehicleState
from mexgen_gcs.core.radio import RadioModel

AREA = SearchArea.rectangle(-4000, 4000, -4000, 4000)
FIELD = RadioModel(front_back_db=3.0, sensitivity_db=-60.0, detection_spread_db=2.0,
                   pd_max=0.95)  # the mission defaults, spelled out


def far_belief(dist_m, bearing_deg, spread_m=150.0, seed=0, n=1000):
    """A moving (CV, 2.5-3 m/s) tag's belief centred dist_m away on a compass bearing."""
    b = math.radians(bearing_deg)
    centre = dist_m * np.array([math.sin(b), math.cos(b)])
    rng = np.random.default_rng(seed)
    model = make_motion_model("cv", accel_std_m_s2=0.1, speed_min_m_s=2.5, speed_max_m_s=3.0)
    states, modes = model.initial(rng.normal(centre, spread_m, (n, 2)), rng)
    return TagBelief("T1", states, modes, model)


def off_deg(a, b):
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.mark.parametrize("method", ["mexgen", "pim"])
@pytest.mark.parametrize("dist_m", [1500.0, 1750.0, 2000.0])
def test_a_far_tag_is_approached(method, dist_m):
    """Before issue 12 both chose the heading directly away (rewards of N..NW for a tag to the
    SE: 4.0, 1.5, 0.9, 0.8 (towards), 0.8, 1.5, 4.5, 6.4 (away), x 1e-3)."""
    for bearing, speed, v_xy, spread in ((135.0, 15.0, (0.0, 0.0), 150.0),
                                         (30.0, 10.0, (0.0, 0.0), 300.0),
                                         (250.0, 15.0, (15.0, 0.0), 100.0)):
        belief = far_belief(dist_m, bearing, spread, seed=int(bearing))
        vehicle = VehicleState(np.array([0.0, 0.0, 50.0]), np.array(v_xy), math.pi / 2)
        planner = Planner(PlannerConfig(method=method, speed_m_s=speed), FIELD, AREA)
        result = planner.plan([belief], vehicle, np.random.default_rng(1))
        assert off_deg(result.heading_deg, bearing) <= 45.0, (bearing, result.rewards)


def test_the_look_ahead_reaches_the_nearest_belief():
    cfg = PlannerConfig(method="pim", speed_m_s=15.0, lookahead_s=20.0, max_lookahead_s=200.0)
    planner = Planner(cfg, FIELD, AREA)
    hover = VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0)
    rng = np.random.default_rng(0)
    near = planner.plan([far_belief(200.0, 90.0)], hover, rng)
    assert near.lookahead_s == pytest.approx(20.0)
    assert np.linalg.norm(near.paths_m[2, -1]) == pytest.approx(300.0 - 28.125, abs=1.0)
    far = planner.plan([far_belief(1800.0, 90.0), far_belief(2400.0, 0.0)], hover, rng)
    mean_dist = float(np.linalg.norm(far_belief(1800.0, 90.0).states[:, :2].mean(axis=0)))
    assert far.lookahead_s == pytest.approx(mean_dist / 15.0, rel=1e-6)  # the nearer one
    assert far.paths_m.shape == near.paths_m.shape  # as many steps: the same cost
    east = far.paths_m[2]  # heading 90: straight at the nearer tag
    assert np.linalg.norm(east[-1]) == pytest.approx(mean_dist - 28.0, abs=2.0)  # accel. 4 m/s2
    capped = planner.plan([far_belief(3900.0, 0.0)], hover, rng)
    assert capped.lookahead_s == pytest.approx(200.0)
    fixed = Planner(PlannerConfig(method="pim", speed_m_s=15.0, reach=False), FIELD, AREA)
    assert fixed.plan([far_belief(1800.0, 90.0)], hover, rng).lookahead_s == pytest.approx(20.0)


def test_pruning_keeps_the_configured_horizon_when_the_look_ahead_is_stretched():
    """Near the area's edge a stretched look-ahead does not prune more: a heading is pruned
    when its path leaves the area within prune_horizon_s (the configured 20 s)."""
    area = SearchArea.rectangle(-2000, 2000, -2000, 2000)
    vehicle = VehicleState(np.array([0.0, 1850.0, 50.0]), np.zeros(2), 0.0)
    planner = Planner(PlannerConfig(method="mexgen", samples=64, speed_m_s=15.0), FIELD, area)
    result = planner.plan([far_belief(1700.0, 180.0)], vehicle, np.random.default_rng(0))
    assert result.lookahead_s > 100.0
    np.testing.assert_array_equal(result.pruned, [True, True, False, False, False, False,
                                                  False, True])
    assert result.heading_deg == 180.0
    # beyond the pruning horizon a stretched path is held at the boundary, not flown past it
    assert area.contains(result.paths_m[~result.pruned].reshape(-1, 2)).all()
    east = result.paths_m[2]
    assert east[-1, 0] < 2000.0 and east[-1, 0] > 2000.0 - 1.5 * 15.0 * result.lookahead_s / 20
    assert np.array_equal(east[-1], east[-2])  # held
