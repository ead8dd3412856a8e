"""Altitude actions (``PlannerConfig.altitudes_m``, the mission's ``flight.min_alt_m``): every
heading scored at each altitude by the same generator, the climb in the rollout, the choice in
the plan and its log record, and the mission file's bounds."""

import math
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.config import MissionFileError, load_mission
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.planner import (
    Planner,
    PlannerConfig,
    TagBelief,
    VehicleState,
    altitude_paths_m,
)
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.experiments.world import PointMass
from mexgen_gcs.io.plans import plan_record

AREA = SearchArea.rectangle(-1000, 1000, -1000, 1000)


def belief(centre, spread, n=1000, seed=0):
    rng = np.random.default_rng(seed)
    model = make_motion_model("static", rw_std_m_per_sqrt_s=0.5)
    states, modes = model.initial(rng.normal(centre, spread, (n, 2)), rng)
    return TagBelief("T1", states, modes, model)


def test_altitude_paths_climb_at_the_rate_then_hold():
    z = altitude_paths_m(50.0, np.array([50.0, 20.0, 60.0]), 2.0, np.array([1.0, 5.0, 20.0]))
    np.testing.assert_allclose(z, [[50, 48, 52], [50, 40, 60], [50, 20, 60]])


@pytest.mark.parametrize("method", ["pim", "mexgen", "mc"])
def test_every_heading_is_scored_at_every_altitude(method):
    cfg = PlannerConfig(method=method, samples=64, mc_rollouts=4, lookahead_s=8.0,
                        altitudes_m=(50.0, 20.0))
    r = Planner(cfg, RadioModel(), AREA).plan(
        [belief((150.0, 0.0), 40.0)], VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0),
        np.random.default_rng(1))
    assert r.headings_deg.shape == r.alts_m.shape == r.rewards.shape == (16,)
    np.testing.assert_allclose(r.alts_m, [50.0] * 8 + [20.0] * 8)
    np.testing.assert_allclose(r.headings_deg[:8], r.headings_deg[8:])
    assert r.alt_m == r.alts_m[r.chosen]
    rec = plan_record(1.0, r, np.array([0.0, 0.0, 50.0]))
    assert rec.alts_m == [float(a) for a in r.alts_m] and rec.chosen_alt_m == r.alt_m


def test_without_altitudes_the_plan_is_the_papers():
    cfg = PlannerConfig(samples=64, lookahead_s=8.0)
    r = Planner(cfg, RadioModel(), AREA).plan(
        [belief((150.0, 0.0), 40.0)], VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0),
        np.random.default_rng(1))
    assert r.alts_m is None and r.alt_m is None and r.headings_deg.shape == (8,)
    assert plan_record(1.0, r, np.zeros(3)).chosen_alt_m is None


def test_a_tag_close_below_is_worth_descending_for():
    """A tight belief 60 m east, the vehicle at 50 m: the same heading scores more from 15 m
    (the pass shows a sharper peak of power), so the plan flies east and descends."""
    cfg = PlannerConfig(samples=256, lookahead_s=10.0, altitudes_m=(50.0, 15.0), speed_m_s=10.0)
    planner = Planner(cfg, RadioModel(path_loss_exponent=1.5), AREA)
    for seed in range(3):
        r = planner.plan([belief((60.0, 0.0), 25.0, seed=seed)],
                         VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0),
                         np.random.default_rng(seed))
        east_high, east_low = r.rewards[2], r.rewards[10]  # heading 90 at 50 m and at 15 m
        assert math.isclose(r.headings_deg[2], 90.0) and math.isclose(r.headings_deg[10], 90.0)
        assert east_low > east_high
        assert r.alt_m == 15.0


def test_point_mass_follows_the_down_velocity():
    v = PointMass(0.0, 0.0, 50.0, 15.0, 4.0)
    v.step(0.0, 0.0, 0.0, 2.0, v_down_m_s=2.0)
    assert v.alt_m == pytest.approx(46.0)


def test_min_alt_above_alt_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "m.yaml"
    text = (Path(__file__).resolve().parents[2] / "missions" / "demo.yaml").read_text("utf-8")
    assert "flight:\n" in text
    path.write_text(text.replace("flight:\n", "flight:\n  min_alt_m: 80\n", 1), encoding="utf-8")
    with pytest.raises(MissionFileError) as err:
        load_mission(path)
    assert "flight.min_alt_m" in str(err.value) and "min_alt_m <= alt_m" in str(err.value)
    assert str(path) in str(err.value)
    path.write_text(text.replace("flight:\n", "flight:\n  min_alt_m: 20\n", 1), encoding="utf-8")
    m = load_mission(path)
    assert m.planner_config("mexgen").altitudes_m == (m.flight.alt_m, 20.0)
