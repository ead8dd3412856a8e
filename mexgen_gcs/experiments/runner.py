"""One Monte Carlo run: the simulated world and the flight path's decision logic, in process.

Frame: local ENU metres about the area centre (x east, y north, z up); headings are compass
degrees (0 = north, clockwise).

The decision logic is the code a flight runs: a ``MissionCore`` built from the run's mission
(``scenario.mission_for``) by the flight's own constructor, ``config.Mission.mission_core``
(per-tag radio priors included), except that the filters' prior and births cover the
scenario's initial search space; the planner is
``core.planner.Planner`` with ``config.Mission.planner_config`` (what the flight's planner
worker builds); the setpoints come from ``core.guidance.velocity_setpoint`` (with the area guard).
Time is simulated: no sockets, no sleeping, no clock read for decisions. Cadence, as the
controller's: plan at t = 0 on the prior; every pulse period the vehicle flies the current
setpoint (recomputed every control period), the receiver measures every tag, the core runs
its pulse; every ``replan_interval_s`` (after that pulse) the core's plan request is planned
and the chosen heading flown until the next plan. The scenario's two planner settings the
mission schema lacks (``planner_reach``, ``planner_outcome``) are applied to the planner config.

Localisation is read twice from the same run: at the mission's radius (``localised_radius_m``,
Success / Time as the paper) and at ``tight_radius_m``. The run goes on after every tag is
localised at the first radius, the core's target rule now on the tags not yet within the
tight one, until they all are or the time limit; the decisions before the first completion
are those of a run that stops there.

``run_one`` is the task function of the process pool and of Dask workers: a pure function of
its ``RunSpec`` (the same spec gives the same row anywhere, wall times aside).
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.guidance import velocity_setpoint
from mexgen_gcs.core.mission_core import Localised, MissionCore
from mexgen_gcs.core.planner import Planner, VehicleState
from mexgen_gcs.experiments.scenario import Scenario, method_config, mission_for
from mexgen_gcs.experiments.seeds import run_seeds
from mexgen_gcs.experiments.world import PointMass, RadioWorld, reality_for, truth_for

FloatArray = NDArray[np.float64]

KEY_COLUMNS = ("model", "method", "start", "rep")
COLUMNS = (
    "scenario", "preset", "seed", "model", "method", "start", "rep", "truth_digest",
    "success", "time_s", "n_localised", "error_m", "errors_m", "localised_t_s",
    "error_mean_m", "error_final_m", "trace_mean_m2", "trace_final_m2",
    "sim_s", "wall_s", "cpu_s", "plans", "plan_ms_median", "detections",
    "radius_m", "tight_radius_m", "tight_success", "tight_time_s", "tight_n_localised",
    "tight_error_m", "tight_errors_m", "tight_localised_t_s",
    "radii_m", "inside", "tight_radii_m", "tight_inside",
    "final_radii_m", "final_errors_m",
)
"""runs.csv columns (format 4; format 3 had the first 36, format 2 the first 32, format 1 the
first 24). ``radii_m``: the 95 % radius each tag claimed when it was localised; ``inside``: how
many localised tags lay inside it (the coverage of the claim). ``final_radii_m``,
``final_errors_m``: every tag's 95 % radius and error at the end of the run, localised or not
(the estimate an operator is left with). Localise fills success..
localised_t_s and radius_m..tight_localised_t_s (the same at the tight radius), follow
error_mean_m..trace_final_m2; the rest is common. ``*errors_m`` and ``*localised_t_s`` hold one
value per tag, ';'-separated (empty where a tag was not localised)."""
TIMING_COLUMNS = ("wall_s", "cpu_s", "plan_ms_median")
"""Columns that measure the machine rather than the run (differ between repeats)."""


@dataclass(frozen=True, slots=True)
class RunSpec:
    """One run: a scenario, a method and the (start, repetition) seeds."""

    scenario: Scenario
    method: str
    seed: int
    start: int
    rep: int

    @property
    def key(self) -> tuple[str, str, int, int]:
        return (self.scenario.model, self.method, self.start, self.rep)


@dataclass(frozen=True, slots=True, eq=False)
class RunResult:
    """A finished run: its runs.csv row (strings) and its per-pulse series."""

    spec: RunSpec
    row: dict[str, str]
    series: dict[str, NDArray[np.float32]]
    """t_s (T,), vehicle_en_m (T, 2), error_m (T, n_tags), trace_m2 (T, n_tags)."""
    stages_s: dict[str, float] = field(default_factory=dict)
    """Process CPU seconds by stage: filter (detections and pulses), planner, world (the
    rest: truth, radio, vehicle, bookkeeping); for `bench experiment`, not in runs.csv."""


def run_one(spec: RunSpec) -> RunResult:
    """Simulate one run to its end (see the module docstring). Cost: about one filter pulse
    per tag per simulated second plus one plan per ``replan_interval_s``."""
    wall0, cpu0 = time.perf_counter(), time.process_time()
    sc = spec.scenario
    mission = mission_for(sc, spec.method)
    planner_method, _ = method_config(spec.method)
    truth = truth_for(sc, spec.seed, spec.start)
    seeds = run_seeds(spec.seed, spec.start, spec.rep)
    gcs = np.random.default_rng(seeds.gcs)
    radio_model = mission.radio_model()
    area = mission.search_area()
    core = mission.mission_core(
        gcs.spawn(1)[0], area=sc.initial_area(), t0=0.0,
        tight_radius_m=sc.tight_radius_m if sc.kind == "localise" else None)
    config = replace(mission.planner_config(planner_method), reach=sc.planner_reach,
                     outcome=sc.planner_outcome)  # type: ignore[arg-type]
    planner = Planner(config, radio_model, area)
    plan_rng = gcs.spawn(1)[0]
    radio = RadioWorld(radio_model, sc.n_tags, np.random.default_rng(seeds.radio),
                       reality_for(sc, radio_model, spec.seed, spec.start))
    vehicle = PointMass(0.0, 0.0, sc.alt_m, sc.speed_m_s, sc.max_accel_m_s2)
    tag_ids = core.tag_ids
    listening = list(tag_ids)

    heading_deg: float | None = None
    plan_s: list[float] = []
    cpu = time.process_time
    stage = {"filter": 0.0, "planner": 0.0}

    def replan(t: float) -> float | None:
        c0 = cpu()
        vs = VehicleState(vehicle.xyz_m, vehicle.v_xy_m_s, vehicle.yaw_rad)
        request = core.plan_request(t, vs)
        if request is None:
            stage["planner"] += cpu() - c0
            return heading_deg
        result = planner.plan(request.beliefs, request.vehicle, plan_rng.spawn(1)[0])
        plan_s.append(result.total_s)
        stage["planner"] += cpu() - c0
        return result.heading_deg

    heading_deg = replan(0.0)
    next_plan_t = sc.replan_interval_s
    n_sub = max(1, round(sc.pulse_period_s / sc.control_period_s))
    dt_sub = sc.pulse_period_s / n_sub
    steps = sc.steps
    t_s = np.zeros(steps)
    vehicle_en = np.zeros((steps, 2))
    error_m = np.full((steps, sc.n_tags), np.nan)
    trace_m2 = np.full((steps, sc.n_tags), np.nan)
    radius_m = np.full(sc.n_tags, np.nan)  # every tag's 95 % radius at the latest pulse
    localised_err: dict[str, float] = {}
    tight_err: dict[str, float] = {}
    claimed: dict[str, float] = {}
    tight_claimed: dict[str, float] = {}
    detections = 0
    done_t: float | None = None
    tight_t: float | None = None
    k = 0
    for k in range(1, steps + 1):
        t = k * sc.pulse_period_s
        for _ in range(n_sub):
            # the guard predicts the point mass exactly: its velocity, its acceleration limit
            # for speeding up and braking, no latency, the next command after dt_sub
            sp = velocity_setpoint(heading_deg, sc.speed_m_s, (vehicle.east_m, vehicle.north_m),
                                   vehicle.alt_m, sc.alt_m, area, vehicle.yaw_deg,
                                   (vehicle.v_east_m_s, vehicle.v_north_m_s),
                                   brake_m_s2=sc.max_accel_m_s2, latency_s=0.0, period_s=dt_sub)
            vehicle.step(sp.v_east_m_s, sp.v_north_m_s, sp.yaw_deg, dt_sub)
        tag_xy = truth.states[k, :, :2]
        rx_xyz, yaw_rad = vehicle.xyz_m, vehicle.yaw_rad
        heard = radio.pulse(tag_xy, rx_xyz, yaw_rad)
        c0 = cpu()
        for tid, zs in zip(tag_ids, heard, strict=True):
            for z in zs:
                core.add_detection(tid, z, rx_xyz, yaw_rad)
            detections += len(zs)
        report = core.pulse(t, rx_xyz, yaw_rad, listening)
        stage["filter"] += cpu() - c0
        i = k - 1
        t_s[i] = t
        vehicle_en[i] = rx_xyz[:2]
        for j, tid in enumerate(tag_ids):
            est = report.estimates[tid]
            error_m[i, j] = math.dist(est.mean[:2], tag_xy[j])
            trace_m2[i, j] = est.trace_pos_m2
            radius_m[j] = est.radius_m
        for rec in report.newly_localised:
            localised_err[rec.tag_id] = error_m[i, tag_ids.index(rec.tag_id)]
            claimed[rec.tag_id] = rec.estimate.radius_m
        for rec in report.newly_tight:
            tight_err[rec.tag_id] = error_m[i, tag_ids.index(rec.tag_id)]
            tight_claimed[rec.tag_id] = rec.estimate.radius_m
        if sc.kind == "localise" and done_t is None and core.all_localised():
            done_t = t
        if sc.kind == "localise" and core.all_tight():
            tight_t = t
        if done_t is not None and (tight_t is not None or core.tight_radius_m is None):
            break
        if t >= next_plan_t - 1e-9:
            heading_deg = replan(t)
            next_plan_t += sc.replan_interval_s
    n = k
    cpu_s = cpu() - cpu0
    stage["world"] = max(cpu_s - stage["filter"] - stage["planner"], 0.0)
    row = _row(spec, truth.digest(), core, (localised_err, claimed), done_t, error_m[:n],
               trace_m2[:n],
               sim_s=float(t_s[n - 1]), wall_s=time.perf_counter() - wall0,
               cpu_s=cpu_s, plan_s=plan_s, detections=detections)
    if sc.kind == "localise":
        row.update(_reading(core.tag_ids, core.tight, (tight_err, tight_claimed), tight_t,
                            "tight_"),
                   radius_m=_num(sc.localised_radius_m),
                   tight_radius_m=_num(sc.tight_radius_m),
                   final_radii_m=";".join(_num(float(r)) for r in radius_m),
                   final_errors_m=";".join(_num(float(e)) for e in error_m[n - 1]))
    series = {"t_s": t_s[:n], "vehicle_en_m": vehicle_en[:n], "error_m": error_m[:n],
              "trace_m2": trace_m2[:n]}
    return RunResult(spec, row, {name: v.astype(np.float32) for name, v in series.items()},
                     stages_s=dict(stage))


def _num(x: float | None) -> str:
    """Shortest exact text of a float ('' for None or NaN)."""
    if x is None or not math.isfinite(x):
        return ""
    return repr(float(x))


def _reading(tag_ids: tuple[str, ...], localised: dict[str, Localised],
             errors_radii: tuple[dict[str, float], dict[str, float]], done_t: float | None,
             prefix: str = "") -> dict[str, str]:
    """The localisation columns of one radius: success, time, count, mean and per-tag errors,
    times and claimed radii, and how many tags lay inside their claim (``prefix``ed names)."""
    errors, radii = errors_radii
    errs = [errors[t] for t in tag_ids if t in errors]
    inside = sum(errors[t] <= radii[t] for t in tag_ids if t in errors and t in radii)
    return {
        f"{prefix}radii_m": ";".join(_num(radii.get(t)) for t in tag_ids),
        f"{prefix}inside": str(inside),
        f"{prefix}success": "1" if done_t is not None else "0",
        f"{prefix}time_s": _num(done_t),
        f"{prefix}n_localised": str(len(localised)),
        f"{prefix}error_m": _num(float(np.mean(errs))) if errs else "",
        f"{prefix}errors_m": ";".join(_num(errors.get(t)) for t in tag_ids),
        f"{prefix}localised_t_s": ";".join(
            _num(localised[t].t) if t in localised else "" for t in tag_ids),
    }


def _row(spec: RunSpec, digest: str, core: MissionCore,
         localised_err: tuple[dict[str, float], dict[str, float]], done_t: float | None,
         error_m: FloatArray, trace_m2: FloatArray, *, sim_s: float, wall_s: float,
         cpu_s: float, plan_s: list[float], detections: int) -> dict[str, str]:
    sc = spec.scenario
    row = dict.fromkeys(COLUMNS, "")
    row.update(scenario=sc.kind, preset=sc.label, seed=str(spec.seed), model=sc.model,
               method=spec.method, start=str(spec.start), rep=str(spec.rep),
               truth_digest=digest, sim_s=_num(sim_s), wall_s=f"{wall_s:.3f}", cpu_s=f"{cpu_s:.3f}",
               plans=str(len(plan_s)), detections=str(detections),
               plan_ms_median=f"{1e3 * statistics.median(plan_s):.2f}" if plan_s else "")
    if sc.kind == "localise":
        row.update(_reading(core.tag_ids, core.localised, localised_err, done_t))
    else:
        e, tr = error_m[:, 0], trace_m2[:, 0]
        row.update(error_mean_m=_num(float(np.mean(e))), error_final_m=_num(float(e[-1])),
                   trace_mean_m2=_num(float(np.mean(tr))), trace_final_m2=_num(float(tr[-1])))
    return row
