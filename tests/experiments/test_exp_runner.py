"""One run in process: determinism, pairing, the recorded metrics."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.runner import COLUMNS, TIMING_COLUMNS, RunSpec, run_one
from mexgen_gcs.experiments.scenario import MODELS, mission_for, scenario, scenario_from_settings
from mexgen_gcs.experiments.world import truth_for


def _numbers(row: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in row.items() if k not in TIMING_COLUMNS}


def test_a_run_is_a_pure_function_of_its_spec() -> None:
    spec = RunSpec(scenario("localise", "cv-ift", quick=True), "mexgen", 4, 1, 2)
    a, b = run_one(spec), run_one(spec)
    assert _numbers(a.row) == _numbers(b.row)
    for k in a.series:
        np.testing.assert_array_equal(a.series[k], b.series[k])
    assert tuple(a.row) == COLUMNS


def test_methods_see_the_same_truth_and_radio_seeds() -> None:
    """Paired comparisons: the truth of a (start, rep) is the same for every method, the
    repetitions of a start share it, other starts differ."""
    sc = scenario("localise", "cv", quick=True)
    rows = {(m, s, r): run_one(RunSpec(sc, m, 0, s, r)).row
            for m in ("pim", "mc8", "mexgen") for s in (0, 1) for r in (0, 1)}
    for s in (0, 1):
        digests = {rows[(m, s, r)]["truth_digest"] for m in ("pim", "mc8", "mexgen")
                   for r in (0, 1)}
        assert digests == {truth_for(sc, 0, s).digest()}
    assert rows[("pim", 0, 0)]["truth_digest"] != rows[("pim", 1, 0)]["truth_digest"]
    # the repetitions differ in radio noise and the GCS's draws
    assert _numbers(rows[("mexgen", 0, 0)]) != _numbers(rows[("mexgen", 0, 1)])


def test_localise_run_records_success_error_and_time() -> None:
    # generous limit on a quick setting so that the tags get localised
    sc = replace(scenario("localise", "rw", quick=True), duration_s=400.0, min_inside_s=400.0)
    res = run_one(RunSpec(sc, "mexgen", 0, 0, 0))
    row = res.row
    assert row["scenario"] == "localise" and row["preset"] == "quick"
    n_loc = int(row["n_localised"])
    per_tag = row["errors_m"].split(";")
    assert len(per_tag) == 4 and sum(e != "" for e in per_tag) == n_loc
    if row["success"] == "1":
        assert n_loc == 4
        assert float(row["time_s"]) == float(row["sim_s"]) <= 400.0
        assert max(float(t) for t in row["localised_t_s"].split(";")) == float(row["time_s"])
    else:
        assert row["time_s"] == "" and float(row["sim_s"]) == 400.0
    assert n_loc >= 1
    errs = [float(e) for e in per_tag if e]
    assert float(row["error_m"]) == pytest.approx(np.mean(errs))
    # the per-tag error at localisation is the series' error at that pulse
    t = res.series["t_s"]
    for j, (e, tl) in enumerate(zip(per_tag, row["localised_t_s"].split(";"), strict=True)):
        if e:
            i = int(np.flatnonzero(t == float(tl))[0])
            assert res.series["error_m"][i, j] == pytest.approx(float(e), rel=1e-5)
    assert row["error_mean_m"] == row["trace_mean_m2"] == ""
    assert int(row["plans"]) >= 1 and int(row["detections"]) > 0


def test_follow_run_records_error_and_trace_every_pulse() -> None:
    sc = scenario("follow", "cv-ift", quick=True)
    res = run_one(RunSpec(sc, "pim", 0, 0, 0))
    s = res.series
    n = sc.steps
    assert s["t_s"].shape == (n,) and s["error_m"].shape == (n, 1)
    np.testing.assert_array_equal(s["t_s"], np.arange(1, n + 1))
    assert np.all(np.isfinite(s["error_m"])) and np.all(s["trace_m2"] > 0)
    assert float(res.row["error_mean_m"]) == pytest.approx(float(s["error_m"].mean()), rel=1e-5)
    assert float(res.row["error_final_m"]) == pytest.approx(float(s["error_m"][-1, 0]), rel=1e-5)
    assert res.row["success"] == ""
    # the vehicle stays at its altitude and within its top speed
    v = np.diff(s["vehicle_en_m"], axis=0)
    assert np.all(np.hypot(v[:, 0], v[:, 1]) <= sc.speed_m_s + 1e-3)


@pytest.mark.parametrize("model", MODELS)
def test_the_filter_assumes_the_scenario_model(model: str) -> None:
    m = mission_for(scenario("localise", model), "mexgen")  # type: ignore[arg-type]
    expected = {"rw": "rw", "cv": "cv", "cv-ift": "cv-ift", "cv-ift-mismatch": "cv-mismatch"}
    assert m.filter.motion == expected[model]
    assert m.planner.lookahead_s == 20.0 and m.planner.samples == 512
    assert m.flight.speed_m_s == 15.0 and m.flight.max_accel_m_s2 == 4.0
    assert m.flight.alt_m == 50.0
    assert m.localisation.radius_m == 50.0 and m.localisation.confidence == 0.95
    f = mission_for(scenario("follow", model), "mc8")  # type: ignore[arg-type]
    assert f.planner.method == "mc" and f.planner.mc_rollouts == 8
    assert f.planner.lookahead_s == 10.0 and f.planner.replan_interval_s == 5.0


@pytest.mark.parametrize("kind", ["follow", "localise"])
@pytest.mark.parametrize("quick", [False, True])
def test_stored_settings_give_back_the_scenario(kind: str, quick: bool) -> None:
    for model in MODELS:
        sc = replace(scenario(kind, model, quick), front_back_db=0.0)  # type: ignore[arg-type]
        stored = json.loads(json.dumps(sc.describe()))  # as in experiment.json
        assert scenario_from_settings(stored) == sc
    with pytest.raises(ConfigError, match="unknown scenario settings"):
        scenario_from_settings({**stored, "wind_m_s": 3.0})


def test_unknown_names_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="unknown model"):
        scenario("localise", "ctra")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="unknown method"):
        mission_for(scenario("localise", "rw"), "mc16")


@pytest.mark.slow
@pytest.mark.parametrize("method", ["pim", "mc8", "mexgen"])
def test_paper_settings_localise_random_walk_tags(method: str) -> None:
    """At the paper's settings every method localises four random-walk tags well within the
    1000 s limit (50 of 50 runs each in docs/experiments.md), about 20 m off."""
    sc = scenario("localise", "rw")
    for start in range(2):
        row = run_one(RunSpec(sc, method, 0, start, 0)).row
        assert row["success"] == "1", row
        assert float(row["time_s"]) < 400.0
        assert float(row["error_m"]) < 60.0
