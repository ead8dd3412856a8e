"""The planner worker: turns a MissionCore PlanRequest into a decision as the flight log
records it.

A flight runs it in the controller's single planner thread, replay (analysis) in its own
loop; it keeps one core Planner per method (each with its reusable workspace), so switching
method in flight costs nothing after the first plan. It lives below both (no asyncio here).

A decision has two forms: the core's `PlanResult` (arrays, inside the planner) and the flight
log's `io.records.Plan`, which the log, the snapshots, the UI, analysis and replay all use.
Frame: ENU inside; headings are compass degrees.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mexgen_gcs.config.mission import Mission
from mexgen_gcs.core.mission_core import PlanRequest
from mexgen_gcs.core.planner import Planner, PlanResult
from mexgen_gcs.io.records import Plan


class MissionPlanner:
    """One Planner per method, built lazily for a mission. Not thread-safe (one thread)."""

    def __init__(self, mission: Mission) -> None:
        self.mission = mission
        self.radio = mission.radio_model()
        self.area = mission.search_area()
        self._planners: dict[str, Planner] = {}

    def planner(self, method: str) -> Planner:
        if method not in self._planners:
            self._planners[method] = Planner(self.mission.planner_config(method), self.radio,
                                             self.area)
        return self._planners[method]

    def plan(self, request: PlanRequest, method: str, rng: np.random.Generator) -> Plan:
        result = self.planner(method).plan(request.beliefs, request.vehicle, rng)
        return plan_record(request.t, result, request.vehicle.xyz_m)


def plan_record(t: float, r: PlanResult, vehicle_xyz_m: Any) -> Plan:
    """The flight log's record of a decision (rewards of pruned headings as None), validated
    by its type on the way."""
    timing = {k: 1e3 * float(v) for k, v in r.timing_s.items()}
    timing["total"] = 1e3 * float(r.total_s)
    east, north = (float(v) for v in vehicle_xyz_m[:2])
    return Plan(
        t=float(t), type="plan", method=r.method, targets=list(r.target_ids),
        headings_deg=[float(h) for h in r.headings_deg],
        rewards=[float(x) if math.isfinite(x) else None for x in r.rewards],
        chosen_heading_deg=float(r.heading_deg), timing_ms=timing,
        vehicle_en_m=(east if math.isfinite(east) else None,
                      north if math.isfinite(north) else None),
        all_pruned=bool(r.all_pruned),
        alts_m=None if r.alts_m is None else [float(a) for a in r.alts_m],
        chosen_alt_m=r.alt_m)
