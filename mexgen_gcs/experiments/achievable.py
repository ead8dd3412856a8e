"""The best a filter can do: its uncertainty radius while the vehicle circles the true object.

Frame: local ENU metres about the area centre (x east, y north, z up); headings are compass
radians (0 = north, clockwise).

A localisation run succeeds when every tag's 95 % radius drops to the criterion (50 m, and the
tight 25 m reading). Whether that is reachable at all depends on the sensor, the object's motion
and the filter's motion model, not on the planner: :func:`circling_radius` flies the vehicle
on a circle about the *true* object (the most informative place to be, whatever the planner),
with the experiment's own world and a ``MissionCore`` configured from the run's mission, and
returns the filter's radius every pulse. If even that stays above the criterion, "success" is
out of reach by design; tests/experiments/test_exp_achievable.py checks it is not, per model.

The circle is flown at the scenario's speed, or slower where the acceleration limit forbids
it (centripetal v^2 / r <= max_accel), with the antenna heading along the track.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.mission_core import MissionCore
from mexgen_gcs.experiments.scenario import Scenario, mission_for
from mexgen_gcs.experiments.seeds import run_seeds
from mexgen_gcs.experiments.world import RadioWorld, truth_for

FloatArray = NDArray[np.float64]


def circling_radius(sc: Scenario, *, circle_m: float = 30.0, seconds: int = 400,
                    seed: int = 0, start: int = 0, tag: int = 0) -> FloatArray:
    """The filter's 95 % radius (m) at every pulse, (seconds,), while the vehicle circles the
    true position of object ``tag`` of the start at ``circle_m`` horizontal radius from t = 0
    (the filter starts from its prior over the initial search space). Cost: one filter pulse
    per second simulated (~1 ms)."""
    mission = mission_for(sc, "mexgen")
    truth = truth_for(sc, seed, start)
    seeds = run_seeds(seed, start, 0)
    tid = mission.tag_ids[tag]
    radio_model = mission.radio_model()
    core = MissionCore((tid,), mission.filter_motion_model(), radio_model, sc.initial_area(),
                       mission.filter_config(), np.random.default_rng(seeds.gcs), t0=0.0)
    radio = RadioWorld(radio_model, 1, np.random.default_rng(seeds.radio))
    speed = min(sc.speed_m_s, math.sqrt(sc.max_accel_m_s2 * circle_m))
    rate = speed / circle_m  # rad/s, counter-clockwise in ENU
    out = np.empty(seconds)
    for k in range(1, seconds + 1):
        t = k * sc.pulse_period_s
        xy = truth.states[min(k, truth.states.shape[0] - 1), tag, :2]
        angle = rate * t
        rx = np.array([xy[0] + circle_m * math.cos(angle), xy[1] + circle_m * math.sin(angle),
                       sc.alt_m])
        # counter-clockwise track direction (-sin, cos) east/north, as a compass heading
        yaw = math.atan2(-math.sin(angle), math.cos(angle)) % (2.0 * math.pi)
        for z in radio.pulse(xy[None], rx, yaw)[0]:
            core.add_detection(tid, z, rx, yaw)
        out[k - 1] = core.pulse(t, rx, yaw, [tid]).estimates[tid].radius_m
    return out
