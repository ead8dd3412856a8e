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

Reporting (the mission's ``localisation`` stall and budget rules, on with the scenario's
``finish``): a tag is reported when it reaches the radius, stalls or spends its budget, and the
run ends when every tag is reported, as the flight does (the tight reading then only counts what
happened before). ``reasons``, ``reported_t_s`` and ``reported_radii_m`` say which, when and
with what radius; the series carry every tag's radius at every pulse.

The oracles (methods ``oracle<R>``, e.g. ``oracle60``, and ``oraclestar<R>``): the same world,
filter, claims and report rule, but the heading is not planned: the vehicle flies to the *true*
position of the core's target tag and orbits it at R metres horizontal (at the scenario's
speed, or slower where the acceleration limit forbids it), or flies straight passes over it out
to R metres, each from another side (:class:`StarPasses`); re-aimed every control period.
The better of them is the floor our planner is measured against (they know what the planner
has to find out).

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
from mexgen_gcs.experiments.scenario import (
    Scenario,
    method_config,
    mission_for,
    oracle_orbit_m,
    oracle_pattern,
)
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
    "reasons", "reported_t_s", "reported_radii_m", "all_reported_s",
    "all_under_50_s", "all_under_75_s", "all_under_100_s",
)
"""runs.csv columns (format 5; format 4 had the first 38, format 3 the first 36, format 2 the
first 32, format 1 the first 24). ``radii_m``: the 95 % radius each tag claimed when it was
localised; ``inside``: how many localised tags lay inside it (the coverage of the claim).
``final_radii_m``, ``final_errors_m``: every tag's 95 % radius and error at the end of the
run, localised or not (the estimate an operator is left with). Localise fills success..
localised_t_s and radius_m..tight_localised_t_s (the same at the tight radius), follow
error_mean_m..trace_final_m2; the rest is common. ``*errors_m`` and ``*localised_t_s`` hold one
value per tag, ';'-separated (empty where a tag was not localised). ``reasons``,
``reported_t_s``, ``reported_radii_m``: per tag why it was reported (reached, stalled, budget;
empty if never), when and its radius then; ``all_reported_s``: when the last one was (empty if
not every tag was). ``all_under_<R>_s``: the first pulse at which every tag's 95 % radius
was at most R m at once (empty if never before the run ended): the time-to-radius curve."""
UNDER_RADII_M = (50, 75, 100)
"""The radii of the ``all_under_<R>_s`` columns."""
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
    """t_s (T,), vehicle_en_m (T, 2), vehicle_alt_m (T,) above home, error_m (T, n_tags),
    trace_m2 (T, n_tags), radius_m (T, n_tags): every tag's 95 % radius at every pulse."""
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
    orbit_m = oracle_orbit_m(spec.method)
    star = StarPasses(orbit_m) if oracle_pattern(spec.method) == "star" and orbit_m else None
    config = replace(mission.planner_config(planner_method), reach=sc.planner_reach,
                     outcome=sc.planner_outcome,  # type: ignore[arg-type]
                     toward_target=sc.planner_toward_target)
    planner = Planner(config, radio_model, area)
    plan_rng = gcs.spawn(1)[0]
    radio = RadioWorld(radio_model, sc.n_tags, np.random.default_rng(seeds.radio),
                       reality_for(sc, radio_model, spec.seed, spec.start))
    vehicle = PointMass(0.0, 0.0, sc.alt_m, sc.speed_m_s, sc.max_accel_m_s2)
    tag_ids = core.tag_ids
    listening = list(tag_ids)

    heading_deg: float | None = None
    target_alt_m = sc.alt_m
    plan_s: list[float] = []
    cpu = time.process_time
    stage = {"filter": 0.0, "planner": 0.0}

    def replan(t: float) -> float | None:
        nonlocal target_alt_m
        c0 = cpu()
        vs = VehicleState(vehicle.xyz_m, vehicle.v_xy_m_s, vehicle.yaw_rad)
        request = core.plan_request(t, vs)
        if request is None:
            stage["planner"] += cpu() - c0
            return heading_deg
        result = planner.plan(request.beliefs, request.vehicle, plan_rng.spawn(1)[0])
        plan_s.append(result.total_s)
        stage["planner"] += cpu() - c0
        if result.alt_m is not None:
            target_alt_m = result.alt_m
        return result.heading_deg

    def oracle_heading(t: float) -> tuple[float | None, float]:
        """Heading and speed towards / around the true position of the core's target."""
        assert orbit_m is not None
        targets = core.targets(vehicle.xyz_m[:2])
        if not targets:
            return None, sc.speed_m_s
        j = tag_ids.index(targets[0])
        k_now = min(round(t / sc.pulse_period_s), truth.states.shape[0] - 1)
        if star is not None:
            return star.heading(targets[0], vehicle.xyz_m[:2], truth.states[k_now, j, :2]), \
                sc.speed_m_s
        return orbit_heading(vehicle.xyz_m[:2], truth.states[k_now, j, :2], orbit_m,
                             sc.speed_m_s, sc.max_accel_m_s2)

    speed_m_s = sc.speed_m_s
    if orbit_m is None:
        heading_deg = replan(0.0)
    else:
        heading_deg, speed_m_s = oracle_heading(0.0)
    next_plan_t = sc.replan_interval_s
    n_sub = max(1, round(sc.pulse_period_s / sc.control_period_s))
    dt_sub = sc.pulse_period_s / n_sub
    steps = sc.steps
    t_s = np.zeros(steps)
    vehicle_en = np.zeros((steps, 2))
    vehicle_alt = np.zeros(steps)
    error_m = np.full((steps, sc.n_tags), np.nan)
    trace_m2 = np.full((steps, sc.n_tags), np.nan)
    radius_m = np.full(sc.n_tags, np.nan)  # every tag's 95 % radius at the latest pulse
    radius_series = np.full((steps, sc.n_tags), np.nan)
    all_reported_t: float | None = None
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
            if orbit_m is not None:
                heading_deg, speed_m_s = oracle_heading(t - sc.pulse_period_s)
            # the guard predicts the point mass exactly: its velocity, its acceleration limit
            # for speeding up and braking, no latency, the next command after dt_sub
            sp = velocity_setpoint(heading_deg, speed_m_s, (vehicle.east_m, vehicle.north_m),
                                   vehicle.alt_m, target_alt_m, area, vehicle.yaw_deg,
                                   (vehicle.v_east_m_s, vehicle.v_north_m_s),
                                   brake_m_s2=sc.max_accel_m_s2, latency_s=0.0, period_s=dt_sub)
            vehicle.step(sp.v_east_m_s, sp.v_north_m_s, sp.yaw_deg, dt_sub, sp.v_down_m_s)
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
        vehicle_alt[i] = rx_xyz[2]
        for j, tid in enumerate(tag_ids):
            est = report.estimates[tid]
            error_m[i, j] = math.dist(est.mean[:2], tag_xy[j])
            trace_m2[i, j] = est.trace_pos_m2
            radius_m[j] = est.radius_m
            radius_series[i, j] = est.radius_m
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
        if sc.kind == "localise" and all_reported_t is None and core.all_reported():
            all_reported_t = t
        if done_t is not None and (tight_t is not None or core.tight_radius_m is None):
            break
        if core.report_rule.active and all_reported_t is not None:
            break  # the flight ends here (RTL)
        if orbit_m is None and t >= next_plan_t - 1e-9:
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
                   final_errors_m=";".join(_num(float(e)) for e in error_m[n - 1]),
                   reasons=";".join(core.reported[t].reason if t in core.reported else ""
                                    for t in tag_ids),
                   reported_t_s=";".join(_num(core.reported[t].t if t in core.reported else None)
                                         for t in tag_ids),
                   reported_radii_m=";".join(
                       _num(core.reported[t].estimate.radius_m if t in core.reported else None)
                       for t in tag_ids),
                   all_reported_s=_num(all_reported_t),
                   **{f"all_under_{r}_s": _num(first_all_under(t_s[:n], radius_series[:n], r))
                      for r in UNDER_RADII_M})
    series = {"t_s": t_s[:n], "vehicle_en_m": vehicle_en[:n], "vehicle_alt_m": vehicle_alt[:n],
              "error_m": error_m[:n],
              "trace_m2": trace_m2[:n], "radius_m": radius_series[:n]}
    return RunResult(spec, row, {name: v.astype(np.float32) for name, v in series.items()},
                     stages_s=dict(stage))


def first_all_under(t_s: FloatArray, radius_m: FloatArray, limit_m: float) -> float | None:
    """The first time (t_s (T,)) at which every column of radius_m (T, n_tags) is <= limit_m;
    None if never."""
    ok = np.all(radius_m <= limit_m, axis=1)
    return float(t_s[int(np.argmax(ok))]) if ok.any() else None


class StarPasses:
    """The star oracle's path about one tag at a time: straight passes over the (true) tag out
    to ``reach_m`` on the far side, each next end point 157.5 deg further round, so successive
    passes cross near the tag (within 0.2 reach) from directions 22.5 deg apart: the range to
    the tag sweeps from overhead to ``reach_m`` on every pass, from every side. The first pass
    heads over the tag from where the vehicle is. ENU metres, compass degrees out."""

    STEP_DEG = 157.5
    ARRIVED_M = 15.0

    def __init__(self, reach_m: float) -> None:
        self.reach_m = reach_m
        self._tag: str | None = None
        self._angle_rad = 0.0

    def heading(self, tag_id: str, vehicle_xy: FloatArray, tag_xy: FloatArray) -> float:
        v = np.asarray(vehicle_xy, dtype=np.float64)[:2]
        c = np.asarray(tag_xy, dtype=np.float64)[:2]
        if tag_id != self._tag:  # a new tag: the first end point beyond it, seen from here
            self._tag = tag_id
            d = c - v
            self._angle_rad = math.atan2(float(d[1]), float(d[0]))
        end = c + self.reach_m * np.array([math.cos(self._angle_rad), math.sin(self._angle_rad)])
        if float(np.hypot(*(end - v))) < self.ARRIVED_M:
            self._angle_rad += math.radians(self.STEP_DEG)
            end = c + self.reach_m * np.array([math.cos(self._angle_rad),
                                               math.sin(self._angle_rad)])
        d = end - v
        return math.degrees(math.atan2(float(d[0]), float(d[1]))) % 360.0


def orbit_heading(vehicle_xy: FloatArray, centre_xy: FloatArray, orbit_m: float,
                  speed_m_s: float, max_accel_m_s2: float) -> tuple[float, float]:
    """(compass heading deg, speed m/s) that brings a vehicle onto, and keeps it on, a
    counter-clockwise circle of ``orbit_m`` about ``centre_xy``: a vector field whose tangential
    part is 1 and whose radial part pulls in (or out) in proportion to the distance off the
    circle (saturating at 1) within twice the orbit, straight in from further; at the
    scenario's speed, slowed near the circle so that the centripetal acceleration v^2 / r
    stays within ``max_accel_m_s2``. ENU metres in."""
    d = np.asarray(vehicle_xy, dtype=np.float64)[:2] - np.asarray(centre_xy, dtype=np.float64)
    dist = float(np.hypot(d[0], d[1]))
    if dist < 1e-6:
        return 0.0, speed_m_s
    radial = d / dist  # outward unit
    if dist > 2.0 * orbit_m:  # far: straight in, at full speed
        v = -radial
        speed = speed_m_s
    else:
        tangent = np.array([-radial[1], radial[0]])  # counter-clockwise
        pull = max(-1.0, min(1.0, -2.0 * (dist - orbit_m) / orbit_m))
        v = tangent + radial * pull
        speed = min(speed_m_s, math.sqrt(max_accel_m_s2 * orbit_m))
    return math.degrees(math.atan2(float(v[0]), float(v[1]))) % 360.0, speed


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
