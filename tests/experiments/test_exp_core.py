"""The experiments measure what flies: a run's MissionCore comes from the flight's own
constructor (``config.Mission.mission_core``), per-tag radio priors included; only the prior
and birth region (the scenario's initial search space) and the tight reading differ."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import yaml

from mexgen_gcs.config import dump_resolved, parse_mission
from mexgen_gcs.config.mission import Mission
from mexgen_gcs.experiments import runner
from mexgen_gcs.experiments.runner import RunSpec, run_one
from mexgen_gcs.experiments.scenario import mission_for, scenario


def test_a_run_builds_the_flights_core_from_its_mission(monkeypatch):
    sc = replace(scenario("localise", "static", quick=True), duration_s=5.0)
    data = dump_resolved(mission_for(sc, "mexgen"))
    data["tags"][0]["p0_db"] = data["radio"]["p0_db"] + 6.0  # a calibrated tag
    data["tags"][0]["p0_std_db"] = 1.5
    mission = parse_mission(yaml.safe_dump(data, sort_keys=False), "calibrated")
    monkeypatch.setattr(runner, "mission_for", lambda _sc, _method: mission)
    built = []
    real = Mission.mission_core

    def spy(self, rng, **kw):
        built.append((real(self, rng, **kw), kw))
        return built[-1][0]

    monkeypatch.setattr(Mission, "mission_core", spy)
    run_one(RunSpec(sc, "mexgen", 1, 0, 0))
    assert len(built) == 1
    run_core, kw = built[0]
    flight_core = mission.mission_core(np.random.default_rng(0))
    assert kw["area"].vertices_m.tolist() == sc.initial_area().vertices_m.tolist()
    first = mission.tag_ids[0]
    assert run_core.filters[first].tag_prior.offset_db == 6.0  # the runner once dropped it
    for tid in mission.tag_ids:
        assert run_core.filters[tid].tag_prior == flight_core.filters[tid].tag_prior
        assert run_core.filters[tid].config == flight_core.filters[tid].config
    for attr in ("tag_ids", "kind", "target_rule", "follow_tag", "planning_particles"):
        assert getattr(run_core, attr) == getattr(flight_core, attr), attr
    assert type(run_core.motion) is type(flight_core.motion)
    assert run_core.radio == flight_core.radio
