"""The rollout planner: direction choice, pruning, multi-tag, timing, reproducibility, errors,
numerical safety; and a smoke test of the planner benchmark (timing is never asserted)."""

import json
import math
import warnings
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.bench import planner as bench_planner
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.planner import (
    STAGES,
    Planner,
    PlannerConfig,
    TagBelief,
    VehicleState,
    plan,
)
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import PulseNoise
from mexgen_gcs.errors import ConfigError, PlannerError
from mexgen_gcs.io.plans import plan_record

METHODS = ["pim", "mexgen", "mc"]
BIG_AREA = SearchArea.rectangle(-1000, 1000, -1000, 1000)
HOVER = VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0)
# Detection range ~340 m at 50 m: a belief 350-450 m away is only heard by flying to it.
SHORT_RANGE = RadioModel(sensitivity_db=-45.0)


def cluster(centre, spread=40.0, n=1000, seed=0, motion="static", tag_id="T1"):
    rng = np.random.default_rng(seed)
    model = make_motion_model(motion, rw_std_m_per_sqrt_s=0.5)
    states, modes = model.initial(rng.normal(centre, spread, (n, 2)), rng)
    return TagBelief(tag_id, states, modes, model)


def small_config(method="mexgen", **kw):
    base = dict(method=method, samples=64, mc_rollouts=4, lookahead_s=8.0)
    return PlannerConfig(**{**base, **kw})


# -- decisions --------------------------------------------------------------------------------


@pytest.mark.parametrize("heading_deg", [90.0, 0.0, 225.0])
@pytest.mark.parametrize("method", ["pim", "mexgen"])
def test_picks_the_clearly_best_direction(method, heading_deg):
    h = math.radians(heading_deg)
    centre = 350.0 * np.array([math.sin(h), math.cos(h)])  # heard in about half the steps
    for seed in range(3):
        belief = cluster(centre, seed=seed)
        result = plan([belief], HOVER, BIG_AREA, SHORT_RANGE, PlannerConfig(method=method),
                      np.random.default_rng(seed))
        assert result.heading_deg == heading_deg
        assert result.rewards[result.chosen] > np.sort(result.rewards)[-2] * 1.2


def test_mc_picks_the_clearly_best_direction_in_expectation():
    """MC-8 is noisy by design (the paper's point): its mean reward is best towards the tag, it
    chooses that heading in most plans and never strays more than one heading from it."""
    belief = cluster([450.0, 0.0])
    planner = Planner(PlannerConfig(method="mc"), SHORT_RANGE, BIG_AREA)
    rng = np.random.default_rng(0)
    results = [planner.plan([belief], HOVER, rng) for _ in range(10)]
    mean_rewards = np.mean([r.rewards for r in results], axis=0)
    assert planner.headings_rad[np.argmax(mean_rewards)] == pytest.approx(math.pi / 2)
    assert sum(r.heading_deg == 90.0 for r in results) >= 6
    assert all(abs(r.heading_deg - 90.0) <= 45.0 for r in results)


@pytest.mark.parametrize("method", METHODS)
def test_reproducible_by_seed(method):
    belief = cluster([200.0, 100.0], spread=120.0, motion="rw")
    cfg = small_config(method)
    a = plan([belief], HOVER, BIG_AREA, RadioModel(), cfg, np.random.default_rng(42))
    b = plan([belief], HOVER, BIG_AREA, RadioModel(), cfg, np.random.default_rng(42))
    c = plan([belief], HOVER, BIG_AREA, RadioModel(), cfg, np.random.default_rng(43))
    assert a.chosen == b.chosen
    np.testing.assert_array_equal(a.rewards, b.rewards)
    assert not np.array_equal(a.rewards, c.rewards)  # the motion noise differs


@pytest.mark.parametrize("method", METHODS)
def test_stage_timings_present_and_positive(method):
    result = plan([cluster([100.0, 0.0])], HOVER, BIG_AREA, RadioModel(), small_config(method),
                  np.random.default_rng(0))
    assert set(result.timing_s) == set(STAGES)
    assert all(result.timing_s[s] > 0.0 for s in STAGES)
    assert result.total_s >= sum(result.timing_s.values())
    assert result.method == method


def test_all_tags_sum_their_rewards_and_tags_with_different_sizes_work():
    """PIM on static tags draws no random numbers: the "all" plan is exactly the sum (on one
    look-ahead: reach would stretch each single-tag plan to its own tag)."""
    b1 = cluster([300.0, 0.0], tag_id="T1")
    b2 = cluster([-100.0, 250.0], n=500, tag_id="T2", seed=1)
    b3 = cluster([0.0, -300.0], tag_id="T3", seed=2)
    planner = Planner(small_config("pim", reach=False), RadioModel(), BIG_AREA)
    rng = np.random.default_rng(0)
    each = [planner.plan([b], HOVER, rng).rewards for b in (b1, b2, b3)]
    together = planner.plan([b1, b2, b3], HOVER, rng)
    np.testing.assert_allclose(together.rewards, np.sum(each, axis=0), rtol=1e-5)
    assert together.target_ids == ("T1", "T2", "T3")


def test_action_cost_penalises_turning():
    belief = cluster([0.0, -450.0])  # due south
    cfg = PlannerConfig(method="pim", action_cost_weight=0.0)
    free = plan([belief], HOVER, BIG_AREA, SHORT_RANGE, cfg, np.random.default_rng(0))
    costly = plan([belief], HOVER, BIG_AREA, SHORT_RANGE,
                  PlannerConfig(method="pim", action_cost_weight=10.0), np.random.default_rng(0))
    assert free.heading_deg == 180.0
    # hovering with yaw north: turning south costs the full weight, north nothing
    np.testing.assert_allclose(free.rewards - costly.rewards,
                               10.0 * np.array([0, 45, 90, 135, 180, 135, 90, 45]) / 180)
    assert costly.heading_deg == 0.0


# -- pruning ----------------------------------------------------------------------------------


def test_near_an_edge_no_outbound_heading():
    area = SearchArea.rectangle(-500, 500, -500, 500)
    vehicle = VehicleState(np.array([0.0, 450.0, 50.0]), np.zeros(2), 0.0)
    belief = cluster([0.0, 600.0])  # the belief lies beyond the north edge
    for method in METHODS:
        result = plan([belief], vehicle, area, RadioModel(), small_config(method, lookahead_s=20),
                      np.random.default_rng(0))
        np.testing.assert_array_equal(result.pruned[[0, 1, 7]], True)  # N, NE, NW
        assert np.all(np.isneginf(result.rewards[result.pruned]))
        assert not result.pruned[result.chosen] and not result.all_pruned
        assert area.contains(result.paths_m[result.chosen]).all()


@settings(max_examples=20, deadline=None, derandomize=True)
@given(
    x=st.floats(-499.0, 499.0),
    y=st.floats(-499.0, 499.0),
    vx=st.floats(-12.0, 12.0),
    vy=st.floats(-12.0, 12.0),
)
def test_the_chosen_path_stays_inside_the_area(x, y, vx, vy):
    area = SearchArea.rectangle(-500, 500, -500, 500)
    vehicle = VehicleState(np.array([x, y, 50.0]), np.array([vx, vy]), 0.0)
    result = plan([cluster([0.0, 0.0], spread=300.0, n=100)], vehicle, area, RadioModel(),
                  small_config("pim", lookahead_s=6.0), np.random.default_rng(0))
    if result.all_pruned:
        centre_bearing = math.degrees(math.atan2(-x, -y)) % 360.0
        off = abs((result.heading_deg - centre_bearing + 180.0) % 360.0 - 180.0)
        assert off <= 22.5 + 1e-9
    else:
        assert area.contains(result.paths_m[result.chosen]).all()
        assert not result.pruned[result.chosen]


def test_outside_the_area_every_action_is_pruned_and_it_heads_for_the_centre():
    area = SearchArea.rectangle(-500, 500, -500, 500)
    vehicle = VehicleState(np.array([0.0, 700.0, 50.0]), np.zeros(2), 0.0)
    result = plan([cluster([0.0, 0.0])], vehicle, area, RadioModel(), small_config(),
                  np.random.default_rng(0))
    assert result.all_pruned and result.pruned.all()
    assert result.heading_deg == 180.0
    assert np.all(np.isneginf(result.rewards))
    record = plan_record(0.0, result, vehicle.xyz_m)
    assert record.rewards == [None] * 8 and record.all_pruned is True


# -- inputs, errors, numerical safety ---------------------------------------------------------


def test_zero_or_missing_particles_raise_planner_error():
    model = make_motion_model("static")
    empty = TagBelief("T9", np.empty((0, 4)), np.empty(0, np.int8), model)
    with pytest.raises(PlannerError, match=r"T9.*no particles"):
        plan([empty], HOVER, BIG_AREA, RadioModel(), small_config(), np.random.default_rng(0))
    with pytest.raises(PlannerError, match="no tag beliefs"):
        plan([], HOVER, BIG_AREA, RadioModel(), small_config(), np.random.default_rng(0))
    bad = TagBelief("T8", np.zeros((5, 3)), np.zeros(5, np.int8), model)
    with pytest.raises(PlannerError, match=r"\(N, 4\)"):
        plan([bad], HOVER, BIG_AREA, RadioModel(), small_config(), np.random.default_rng(0))
    nan = TagBelief("T7", np.full((5, 4), np.nan), np.zeros(5, np.int8), model)
    with pytest.raises(PlannerError, match="non-finite"):
        plan([nan], HOVER, BIG_AREA, RadioModel(), small_config(), np.random.default_rng(0))
    vehicle = VehicleState(np.zeros(2), np.zeros(2), 0.0)
    with pytest.raises(PlannerError, match="vehicle"):
        plan([cluster([0, 0])], vehicle, BIG_AREA, RadioModel(), small_config(),
             np.random.default_rng(0))


@pytest.mark.parametrize(
    "field,value",
    [("method", "best"), ("samples", 0), ("mc_rollouts", 0), ("step_s", 0.0),
     ("lookahead_s", 0.5), ("discount", 0.0), ("alpha", 1.0), ("n_headings", 0),
     ("speed_m_s", 0.0), ("max_accel_m_s2", -1.0), ("action_cost_weight", -1.0),
     ("prune_horizon_s", 0.0)],
)
def test_config_validation(field, value):
    with pytest.raises(ConfigError, match=f"planner.{field}"):
        PlannerConfig(**{field: value})


@pytest.mark.parametrize("method", METHODS)
def test_no_nan_when_every_likelihood_underflows(method):
    """A belief 30 km away, a receiver that hears nothing but claims 0.01 dB noise: every
    particle's likelihood underflows, rewards stay finite and nothing warns."""
    radio = RadioModel(noise_std_db=0.01, sensitivity_db=-300.0, pd_max=1.0)
    far = cluster([30_000.0, 30_000.0], spread=5_000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = plan([far], HOVER, BIG_AREA, radio, small_config(method),
                      np.random.default_rng(0))
    assert np.all(np.isfinite(result.rewards)) and np.all(result.rewards >= 0.0)


def test_duck_typed_inputs_and_a_reused_planner():
    """The mission core's own belief/vehicle records work: only the attributes are read."""
    model = make_motion_model("rw")
    states, modes = model.initial(np.random.default_rng(0).normal(0, 100, (300, 2)),
                                  np.random.default_rng(1))
    belief = SimpleNamespace(tag_id="T1", states=states, modes=modes, motion=model,
                             existence=0.8)
    vehicle = SimpleNamespace(xyz_m=np.array([10.0, 0.0, 50.0]), v_xy_m_s=np.array([3.0, 0.0]),
                              yaw_rad=1.0)
    planner = Planner(small_config("mexgen"), RadioModel(), BIG_AREA)
    first = planner.plan([belief], vehicle, np.random.default_rng(3))
    again = planner.plan([belief], vehicle, np.random.default_rng(3))
    np.testing.assert_array_equal(first.rewards, again.rewards)
    record = plan_record(12.5, first, vehicle.xyz_m).to_dict()
    json.dumps(record, allow_nan=False)  # JSON-ready for the flight log
    assert record["targets"] == ["T1"] and len(record["headings_deg"]) == 8
    assert record["vehicle_en_m"] == [10.0, 0.0] and record["timing_ms"]["total"] > 0
    assert first.paths_m.shape == (8, 8, 2) and not first.paths_m.flags.writeable


# -- the benchmark (a smoke test: timing is measured, never asserted) -------------------------


def test_bench_planner_smoke(capsys):
    setting = bench_planner.Setting("tiny", 2, 64, "rw")
    robust = bench_planner.Setting("tiny robust", 1, 64, "static", robust=True)
    out = bench_planner.run(iterations=2, warmup=0, settings=(setting, robust))
    assert {"what", "machine", "results", "ratios"} <= set(out)
    assert [r["method"] for r in out["results"]] == ["mexgen", "pim", "mc"] * 2
    assert [r["setting"] for r in out["results"]][3:] == ["tiny robust"] * 3
    for r in out["results"]:
        assert {"median_ms", "min_ms", "max_ms", "stages_median_ms"} <= set(r)
        assert set(r["stages_median_ms"]) == set(STAGES)
    assert out["ratios"]["mc8_over_mexgen"] > 0 and out["ratios"]["mexgen_over_pim"] > 0
    json.dumps(out)
    assert bench_planner.main(["--json", "--quick", "--iterations", "1", "--warmup", "0"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["results"][0]["setting"] == "1 tag"
    assert "MexGen / PIM" in bench_planner.table(out)


@pytest.mark.parametrize("method", ["pim", "mexgen"])
def test_the_planner_looks_where_the_filter_has_not_listened(method):
    """Under shadowing, a pulse where the filter has listened repeats its shadowing and tells
    little (core.radio_belief.PulseNoise): with the east already heard, flying west is worth
    more; without that memory the two are worth the same (the belief is symmetric)."""
    belief = cluster(np.zeros(2), spread=100.0, seed=1)
    x = np.arange(20.0, 420.0, 20.0)
    heard = np.array([(a, b) for a in x for b in np.arange(-200.0, 220.0, 20.0)])
    noise = PulseNoise(heard, np.full(len(heard), 3.0), 16.0, 15.25, 50.0)
    config = small_config(method, lookahead_s=20.0)
    east, west = 2, 6  # of the 8 compass headings
    plain = plan([belief], HOVER, BIG_AREA, RadioModel(), config, np.random.default_rng(0))
    assert plain.rewards[east] == pytest.approx(plain.rewards[west], rel=0.2)
    aware = plan([replace(belief, noise=noise)], HOVER, BIG_AREA, RadioModel(), config,
                 np.random.default_rng(0))
    assert aware.rewards[east] < 0.5 * aware.rewards[west]
    assert aware.headings_deg[aware.chosen] not in (45.0, 90.0, 135.0)


def test_uncertain_offsets_make_every_pulse_noisier():
    """The offsets' and exponents' spread is noise to the planner: less to gain everywhere."""
    belief = cluster(np.array([0.0, 300.0]), spread=60.0, seed=2)
    n = belief.states.shape[0]
    known = replace(belief, offset_db=np.zeros(n), exponent=np.full(n, 1.5))
    unsure = replace(known, radio_cov=np.array([16.0, 0.0, 0.0625]))
    config = small_config("mexgen", lookahead_s=20.0)
    a = plan([known], HOVER, BIG_AREA, RadioModel(), config, np.random.default_rng(0))
    b = plan([unsure], HOVER, BIG_AREA, RadioModel(), config, np.random.default_rng(0))
    assert np.all(b.rewards < 0.8 * a.rewards)
    assert a.heading_deg == b.heading_deg == 0.0  # still towards the tag


@pytest.mark.parametrize("method", METHODS)
def test_toward_target_adds_the_heading_at_the_estimate_scored_alike(method):
    """A belief at a bearing between two fixed headings: the extra action points at it, every
    generator scores it like the others, and with it the planner flies (nearly) straight at
    the belief rather than 11 deg or more off it."""
    h = math.radians(112.0)
    belief = cluster(350.0 * np.array([math.sin(h), math.cos(h)]), seed=1)
    plain = plan([belief], HOVER, BIG_AREA, SHORT_RANGE, small_config(method),
                 np.random.default_rng(0))
    extra = plan([belief], HOVER, BIG_AREA, SHORT_RANGE,
                 small_config(method, toward_target=True), np.random.default_rng(0))
    assert plain.headings_deg.shape == (8,) and extra.headings_deg.shape == (9,)
    bearing = math.degrees(math.atan2(*belief.states[:, :2].mean(axis=0)))
    assert extra.headings_deg[8] == pytest.approx(bearing % 360.0)
    assert np.all(np.isfinite(extra.rewards))
    assert abs(extra.heading_deg - bearing) < abs(plain.heading_deg - bearing)
