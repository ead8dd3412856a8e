"""The mission's planner worker: turns a MissionCore PlanRequest into a logged decision.

Runs in the controller's single planner thread; it keeps one core Planner per method (each
with its reusable workspace), so switching method in flight costs nothing after the first plan.
Frame: ENU inside; headings are compass degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mexgen_gcs.core.generators import method_name
from mexgen_gcs.core.mission_core import PlanRequest
from mexgen_gcs.core.planner import Planner, PlannerConfig, PlanResult


@dataclass(frozen=True, slots=True)
class PlanOutcome:
    """A plan flattened to plain values for the log, snapshots and the UI."""

    t: float
    method: str
    targets: tuple[str, ...]
    headings_deg: tuple[float, ...]
    rewards: tuple[float, ...]
    """Expected reward per heading; -inf where pruned."""
    chosen_heading_deg: float
    all_pruned: bool
    timing_ms: dict[str, float]


def planner_config(mission: Any, method: str) -> PlannerConfig:
    p = mission.planner
    return PlannerConfig(
        method=method_name(method), samples=p.samples, mc_rollouts=p.mc_rollouts,
        lookahead_s=p.lookahead_s,
        step_s=p.step_s, discount=p.discount, alpha=p.alpha, speed_m_s=mission.flight.speed_m_s,
        max_accel_m_s2=mission.flight.max_accel_m_s2, action_cost_weight=p.action_cost_weight)


class MissionPlanner:
    """One Planner per method, built lazily for a mission. Not thread-safe (one thread)."""

    def __init__(self, mission: Any) -> None:
        self.mission = mission
        self.radio = mission.radio_model()
        self.area = mission.search_area()
        self._planners: dict[str, Planner] = {}

    def planner(self, method: str) -> Planner:
        if method not in self._planners:
            self._planners[method] = Planner(planner_config(self.mission, method), self.radio,
                                             self.area)
        return self._planners[method]

    def plan(self, request: PlanRequest, method: str, rng: np.random.Generator) -> PlanOutcome:
        result = self.planner(method).plan(request.beliefs, request.vehicle, rng)
        return outcome(request.t, result)


def outcome(t: float, r: PlanResult) -> PlanOutcome:
    timing = {k: 1e3 * v for k, v in r.timing_s.items()}
    timing["total"] = 1e3 * r.total_s
    return PlanOutcome(
        t=t, method=r.method, targets=r.target_ids,
        headings_deg=tuple(float(h) for h in r.headings_deg),
        rewards=tuple(float(x) if math.isfinite(x) else -math.inf for x in r.rewards),
        chosen_heading_deg=r.heading_deg, all_pruned=r.all_pruned, timing_ms=timing)
