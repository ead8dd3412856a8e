"""Planner-in-the-loop replay: re-run the filters on a log's recorded detections and
telemetry, and at every recorded plan ask the planner what the recorded method and another
method would choose from the replayed belief.

Frame: local ENU metres about home; headings are compass degrees (0 north, clockwise).

The replay rebuilds the flight's MissionCore from the log header's mission with the flight's
seed (the same generator tree as ``mission.run.fly_mission``), feeds it the detections in log
order, runs one filter cadence per logged pulse (the estimate records' times; tags whose
record says ``missed`` were listened for), and the receiver pose of a missed detection is the
track interpolated at the pulse. The planner gets the recorded targets, the vehicle position
of the plan record, the altitude and velocity from the track and the yaw of the nearest pose.
The replayed belief is close to the recorded one but not bit-identical (missed-detection
poses are interpolated), so the replayed choice of the recorded method is shown next to the
recorded choice as a fidelity check.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.core.generators import METHODS
from mexgen_gcs.core.mission_core import MissionCore, PlanRequest
from mexgen_gcs.core.planner import TagBelief, VehicleState
from mexgen_gcs.io.plans import MissionPlanner
from mexgen_gcs.io.records import Plan


def default_other_method(recorded: str) -> str:
    """The method to compare against when none is given: PIM for MexGen, else MexGen."""
    return "pim" if recorded == "mexgen" else "mexgen"


@dataclass(frozen=True, slots=True)
class ReplayStep:
    """One recorded plan and what the replay says about it."""

    t: float
    after_s: float
    targets: tuple[str, ...]
    recorded_method: str
    recorded_heading_deg: float
    recorded_all_pruned: bool
    replayed_heading_deg: float
    """The recorded method re-planned on the replayed belief."""
    method: str
    method_heading_deg: float
    """What ``method`` chooses on the replayed belief."""
    method_rewards: tuple[float | None, ...]
    """None where the heading was pruned."""
    headings_deg: tuple[float, ...]
    estimate_gap_m: float | None
    """Largest distance between the replayed and recorded estimates of the targets."""

    @property
    def method_agrees(self) -> bool:
        return _same_heading(self.method_heading_deg, self.recorded_heading_deg)

    @property
    def replay_agrees(self) -> bool:
        return _same_heading(self.replayed_heading_deg, self.recorded_heading_deg)


def _same_heading(a: float, b: float) -> bool:
    return abs((a - b + 180.0) % 360.0 - 180.0) < 1e-6


@dataclass(frozen=True, slots=True)
class _Pulse:
    t: float
    listening: tuple[str, ...] | None


def _timeline(flight: FlightData, t_reset: float) -> list[tuple[float, int, object]]:
    """(t, order, item) for detections (0), plans (1) and pulses (2), time-ordered."""
    items: list[tuple[float, int, object]] = []
    det = flight.detections
    for i in np.flatnonzero(det.t >= t_reset):
        items.append((float(det.t[i]), 0, int(i)))
    for p in flight.plans:
        if p.t >= t_reset - 1e-6:
            items.append((p.t, 1, p))
    pulses: dict[float, dict[str, str]] = {}
    for tid, series in flight.estimates.items():
        for t, upd in zip(series.t.tolist(), series.update, strict=True):
            pulses.setdefault(t, {})[tid] = upd
    for t, updates in pulses.items():
        heard = tuple(tid for tid, u in updates.items() if u in ("missed", "detection"))
        items.append((t, 2, _Pulse(t, heard if heard else None)))
    items.sort(key=lambda x: (x[0], x[1]))
    return items


def replay(flight: FlightData, method: str, *, seed: int | None = None,
           progress: Callable[[int, int], None] | None = None) -> list[ReplayStep]:
    """Replay a flight and compare ``method`` with the recorded planner at every plan.

    ``seed``: of the replay's random draws; default the flight's seed (so the filters draw
    like the flight's did). Cost: one filter cadence per logged pulse plus one or two plans
    per recorded plan.
    """
    if method not in METHODS:
        raise ValueError(f"unknown planner method {method!r}; expected one of {METHODS}")
    mission = flight.mission
    base_seed = seed if seed is not None else (flight.seed if flight.seed is not None else 0)
    rng = np.random.default_rng(base_seed)
    core = mission.mission_core(rng.spawn(1)[0])
    plan_rng = rng.spawn(1)[0]
    t_reset = flight.t_airborne if flight.t_airborne is not None else flight.t_start
    core.reset_clock(t_reset)
    planner = MissionPlanner(mission)
    track = flight.track
    det = flight.detections
    steps: list[ReplayStep] = []
    n_plans = len(flight.plans)
    for _t, kind, item in _timeline(flight, t_reset):
        if kind == 0:
            i = int(item)  # type: ignore[call-overload]
            tag = str(det.tag[i])
            rx = det.rx_enu_m[i]
            if tag not in core.filters or not (np.all(np.isfinite(rx))
                                               and math.isfinite(det.rssi_db[i])):
                continue
            yaw = det.rx_yaw_deg[i]
            core.add_detection(tag, float(det.rssi_db[i]), rx,
                               math.radians(yaw) if math.isfinite(yaw) else 0.0)
        elif kind == 2:
            assert isinstance(item, _Pulse)
            pos = track.position_at(item.t)
            core.pulse(item.t, pos, math.radians(track.yaw_at(item.t)), item.listening)
        else:
            assert isinstance(item, Plan)
            step = _plan_step(flight, core, planner, item, method, plan_rng.spawn(1)[0])
            if step is not None:
                steps.append(step)
            if progress is not None:
                progress(len(steps), n_plans)
    return steps


def _plan_step(flight: FlightData, core: MissionCore, planner: MissionPlanner,
               rec: Plan, method: str, rng: np.random.Generator) -> ReplayStep | None:
    targets = tuple(t for t in rec.targets if t in core.filters)
    if not targets:
        return None
    track = flight.track
    e, n = rec.vehicle_en_m
    if e is None or n is None:
        e, n = (float(x) for x in track.position_at(rec.t)[:2])
    up = float(track.position_at(rec.t)[2])
    vehicle = VehicleState(np.array([e, n, up]), track.velocity_at(rec.t),
                           math.radians(track.yaw_at(rec.t)))
    beliefs = []
    for tid in targets:
        f = core.filters[tid]
        states, modes, offset, exponent, cov = f.sample_planning(core.planning_particles,
                                                                 core.rng)
        beliefs.append(TagBelief(tid, states, modes, core.motion, float(f.existence), offset,
                                 exponent, f.planning_noise(), cov))
    request = PlanRequest(rec.t, vehicle, tuple(beliefs))
    method_rng, = rng.spawn(1)
    replayed = planner.plan(request, rec.method, rng)
    other = replayed if method == rec.method else planner.plan(request, method, method_rng)
    gap: float | None = None
    for tid in targets:
        series = flight.estimates.get(tid)
        j = series.index_at(rec.t) if series is not None else None
        if series is None or j is None:
            continue
        mean = core.filters[tid].estimate().mean
        d = math.hypot(float(mean[0]) - series.east_m[j], float(mean[1]) - series.north_m[j])
        gap = d if gap is None else max(gap, d)
    return ReplayStep(
        t=rec.t, after_s=float(flight.since_airborne(rec.t)), targets=targets,
        recorded_method=rec.method, recorded_heading_deg=rec.chosen_heading_deg,
        recorded_all_pruned=rec.all_pruned, replayed_heading_deg=replayed.chosen_heading_deg,
        method=method, method_heading_deg=other.chosen_heading_deg,
        method_rewards=tuple(other.rewards), headings_deg=tuple(other.headings_deg),
        estimate_gap_m=gap)


def replay_table(steps: Sequence[ReplayStep], method: str) -> str:
    """The replay as a fixed-width text table with a summary line."""
    rec_methods = sorted({s.recorded_method for s in steps}) or ["-"]
    rec_name = "/".join(rec_methods)
    head = (f"{'t+ (s)':>8}  {'targets':<10} {'recorded ' + rec_name:>16} "
            f"{'replay ' + rec_name:>14} {method:>8}  {'agree':<5} {'est. gap (m)':>12}")
    lines = [head, "-" * len(head)]
    for s in steps:
        gap = "-" if s.estimate_gap_m is None else f"{s.estimate_gap_m:.1f}"
        pruned = "*" if s.recorded_all_pruned else " "
        lines.append(
            f"{s.after_s:8.1f}  {','.join(s.targets):<10} {s.recorded_heading_deg:15.0f}{pruned} "
            f"{s.replayed_heading_deg:14.0f} {s.method_heading_deg:8.0f}  "
            f"{'yes' if s.method_agrees else 'no':<5} {gap:>12}")
    n = len(steps)
    if n:
        agree = sum(s.method_agrees for s in steps)
        same = sum(s.replay_agrees for s in steps)
        lines.append("-" * len(head))
        lines.append(f"{method} chose the recorded heading in {agree}/{n} plans "
                     f"({100.0 * agree / n:.0f}%); the replayed {rec_name} reproduced it in "
                     f"{same}/{n} ({100.0 * same / n:.0f}%).")
        lines.append("Headings in compass degrees; * = every action was pruned (heading to the "
                     "area centre); est. gap = replayed vs recorded target estimate.")
    else:
        lines.append("(no plans in this log)")
    return "\n".join(lines)
