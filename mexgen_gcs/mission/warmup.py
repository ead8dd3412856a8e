"""Compile the flight's kernels before the flight needs them.

The filter, planner and guidance run compiled kernels (:mod:`core.jit`), compiled on first use
and then kept in numba's on-disk cache. A first use in flight would stop the asyncio loop (and
the setpoint stream) for as long as the compile takes, so preflight calls :func:`warm_up`
first, before anything is armed: it runs every kernel a mission can reach on a throwaway copy
of the mission's decision core with its own generator (the mission's random stream is
untouched): a pulse with a detection, one with misses, one with no radio, a resample, a plan
with every planner method (the operator may switch in flight) and a guidance setpoint.

Measured on this project's 2-core machine for missions/demo.yaml (robust estimator, MexGen,
PIM and MC-8): 10.4 s with an empty cache (another process busy on the other core), 0.07 s
once the cache holds the kernels.
Frame: ENU metres about the mission home.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from mexgen_gcs.core.generators import METHODS
from mexgen_gcs.core.mission_core import MissionCore
from mexgen_gcs.core.planner import Planner, VehicleState
from mexgen_gcs.mission.guidance import velocity_setpoint
from mexgen_gcs.mission.planning import planner_config


def warm_up(mission: Any) -> float:
    """Run every kernel of a flight of ``mission`` once; returns the wall seconds it took."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    area = mission.search_area()
    core = MissionCore(
        mission.tag_ids, mission.filter_motion_model(), mission.radio_model(), area,
        mission.filter_config(), rng, kind=mission.kind, target_rule=mission.planner.target,
        follow_tag=mission.follow.tag if mission.follow is not None else None,
        planning_particles=mission.planner.n_particles, tag_priors=mission.tag_radio_priors(),
        report_rule=mission.report_rule())
    centre = np.asarray(area.centre_m, dtype=np.float64)
    rx = np.array([centre[0], centre[1], float(mission.flight.alt_m)])
    core.add_detection(mission.tag_ids[0], -50.0, rx, 0.0)
    core.pulse(1.0, rx, 0.0, listening=mission.tag_ids)  # a detection, and misses
    core.pulse(2.0, rx, 0.0, listening=None)  # no radio: predict only
    for f in core.filters.values():
        f.resample()
    vehicle = VehicleState(rx, np.zeros(2), 0.0)
    request = core.plan_request(2.0, vehicle)
    if request is not None:  # the core planner, as the flight's planner worker runs it
        radio = mission.radio_model()
        for method in METHODS:
            Planner(planner_config(mission, method), radio, area).plan(
                request.beliefs, request.vehicle, rng)
    velocity_setpoint(0.0, float(mission.flight.speed_m_s), (float(rx[0]), float(rx[1])),
                      float(rx[2]), float(rx[2]), area, 0.0)
    return time.perf_counter() - t0
