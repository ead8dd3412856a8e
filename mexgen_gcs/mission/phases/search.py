"""Search: offboard velocity control while the filters, the planner and the safety rules run.
Safe action: return to launch (the return phase), unless the autopilot took over.

Tasks (one TaskGroup, all ended together): the filter cadence (every pulse period of vehicle
time), the planner loop (every replan interval of vehicle time; the planning itself runs in a
worker thread and a plan still running when the next is due is skipped, never queued), the
setpoint stream (20 Hz wall, with the area guard) and the safety rules (5 Hz wall, on vehicle
time). Frames: ENU metres about the mission home, heights above the vehicle's home; setpoints
leave as NED m/s.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import logging
import math
import time

import numpy as np

from mexgen_gcs.core.guidance import (
    LATENCY_S,
    PX4_MPC_ACC_HOR_M_S2,
    Setpoint,
    velocity_setpoint,
)
from mexgen_gcs.errors import PlannerError, VehicleError
from mexgen_gcs.io.plans import MissionPlanner
from mexgen_gcs.io.records import Plan
from mexgen_gcs.mission import safety
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.phases.common import SETPOINT_HZ, supervised
from mexgen_gcs.mission.state import EndReason, MissionState

SAFETY_HZ = 5.0
CLOUD_LOG_EVERY_S = 5.0
LINK_MIN_WALL_S = 0.5
"""A telemetry gap counts as a lost link only after this many wall seconds as well (at a high
time scale a few vehicle seconds are a blink of wall time)."""
SKIP_EVENT_EVERY = 10
"""Skipped plans: an event for the first and then every this many."""


async def run(ctx: MissionContext, planner: MissionPlanner,
              executor: concurrent.futures.ThreadPoolExecutor) -> None:
    ctx.phase = "search"
    ctx.telemetry_gap_seen = False
    if not await ctx.commander.start_offboard(ctx.vehicle.hub.latest.yaw_deg):
        return
    ctx.event("offboard_started")
    ctx.state = MissionState.SEARCHING
    await supervised(ctx, None, filter_cadence(ctx), planner_loop(ctx, planner, executor),
                     setpoints(ctx), safety_rules(ctx))


# -- filter cadence ------------------------------------------------------------------------------


async def filter_cadence(ctx: MissionContext) -> None:
    period = ctx.mission.receiver.pulse_period_s
    hb_timeout = ctx.mission.receiver.heartbeat_timeout_s
    last_cloud_t = -math.inf
    while True:
        await ctx.clock.sleep(period)
        t = ctx.clock.now()
        vs, _, _ = ctx.vehicle_state()
        if not np.all(np.isfinite(vs.xyz_m)):
            continue
        fresh = t - ctx.last_heartbeat_t <= hb_timeout
        listening = (ctx.heartbeat_listening if ctx.heartbeat_listening is not None
                     else ctx.core.tag_ids) if fresh else None
        report = ctx.core.pulse(t, vs.xyz_m, vs.yaw_rad, listening)
        for tid, est in report.estimates.items():
            ctx.log.write("estimate", t=t, tag=tid, existence=est.existence,
                          east_m=est.mean[0], north_m=est.mean[1], v_east_m_s=est.mean[2],
                          v_north_m_s=est.mean[3], cov_pos_m2=est.cov_pos,
                          radius_m=est.radius_m, localised=est.localised,
                          update=report.updated[tid], ess=est.ess)
        if t - last_cloud_t >= CLOUD_LOG_EVERY_S:
            last_cloud_t = t
            for tid in ctx.core.tag_ids:
                ctx.log.write("cloud", t=t, tag=tid, en_m=ctx.core.particle_cloud(tid, 100))
        for rec in report.newly_localised:
            lat, lon, _ = ctx.frame.to_geodetic(rec.estimate.mean[0], rec.estimate.mean[1])
            ctx.event("tag_localised", tag=rec.tag_id,
                      after_s=round(ctx.mission_elapsed_s(rec.t), 1),
                      lat=round(float(lat), 7), lon=round(float(lon), 7),
                      radius_m=round(rec.estimate.radius_m, 1))
        for rep in report.newly_reported:
            ctx.log.write("tag_reported", t=t, tag=rep.tag_id, reason=rep.reason,
                          after_s=round(ctx.mission_elapsed_s(rep.t), 1),
                          east_m=float(rep.estimate.mean[0]),
                          north_m=float(rep.estimate.mean[1]),
                          radius_m=rep.estimate.radius_m, worked_s=round(rep.worked_s, 1))
            if rep.reason != "reached":
                ctx.event("tag_reported", level=logging.WARNING, tag=rep.tag_id,
                          reason=rep.reason, radius_m=round(rep.estimate.radius_m, 1),
                          worked_s=round(rep.worked_s, 1))
        check_done(ctx, t)


def check_done(ctx: MissionContext, t: float) -> None:
    m = ctx.mission
    if m.kind == "follow":
        assert m.follow is not None  # the schema requires the section for kind follow
        if ctx.t_airborne is not None and t - ctx.t_airborne >= m.follow.duration_s:
            ctx.finish(EndReason.FOLLOW_COMPLETE)
    elif ctx.core.all_localised():
        ctx.finish(EndReason.ALL_LOCALISED)
    elif ctx.core.all_reported():
        ctx.finish(EndReason.ALL_REPORTED)


# -- planner -------------------------------------------------------------------------------------


async def planner_loop(ctx: MissionContext, planner: MissionPlanner,
                       executor: concurrent.futures.ThreadPoolExecutor) -> None:
    """Plan every replan interval of vehicle time. The worker thread is never queued: a plan
    still running when the next is due is left to finish (its result is dropped) and the due
    one is skipped; the vehicle holds while planning is late. Plans keep to a grid of the
    interval; woken more than half an interval late (the event loop stalled), the grid
    restarts from this plan, so the tick it slept through is not planned at once after it."""
    interval = ctx.mission.planner.replan_interval_s
    loop = asyncio.get_running_loop()
    running: asyncio.Future[Plan] | None = None
    due = ctx.clock.now()
    while True:
        t = ctx.clock.now()
        if t - due > 0.5 * interval:  # a stall: the schedule restarts from this plan
            due = t
        ctx.next_plan_t = due + interval
        if running is not None and not running.done():
            n = ctx.count("plans_skipped")
            hold(ctx, "planner_overrun")
            if n == 1 or n % SKIP_EVENT_EVERY == 0:
                ctx.event("plan_skipped", level=logging.WARNING, skipped=n,
                          reason="the previous plan is still running")
        else:
            vs, _, _ = ctx.vehicle_state()
            request = ctx.core.plan_request(t, vs) if np.all(np.isfinite(vs.xyz_m)) else None
            if request is not None:
                running = loop.run_in_executor(executor, planner.plan, request, ctx.method,
                                               ctx.rng.spawn(1)[0])
                budget = ctx.clock.wall_seconds(interval)
                done, _ = await asyncio.wait({running}, timeout=max(budget, 0.05))
                if done:
                    apply_plan(ctx, running)
                else:
                    running.add_done_callback(lambda f: _late(ctx, f))
                    hold(ctx, "planner_overrun")
                    ctx.event("planner_overrun", level=logging.ERROR,
                              budget_wall_s=round(budget, 2))
        due += interval
        now = ctx.clock.now()
        if due < now:  # planning took longer than the interval: the next one now
            due = now
        await ctx.clock.sleep(due - now)


def apply_plan(ctx: MissionContext, fut: asyncio.Future[Plan]) -> None:
    """Use a finished plan: a planner error holds; any other exception is a fault."""
    try:
        outcome = fut.result()
    except (PlannerError, ValueError, FloatingPointError) as exc:
        hold(ctx, "planner_error")
        ctx.event("planner_error", level=logging.ERROR, error=str(exc))
        return
    ctx.last_plan = outcome
    if ctx.hold_reason in ("planner_error", "planner_overrun"):
        ctx.hold_reason = None
    ctx.heading_deg = outcome.chosen_heading_deg
    if outcome.chosen_alt_m is not None:
        ctx.target_alt_m = outcome.chosen_alt_m
    ctx.log.write_record(outcome)


def _late(ctx: MissionContext, fut: asyncio.Future[Plan]) -> None:
    """A late plan finished: dropped (the vehicle has moved on), counted."""
    ctx.count("plans_late")
    if not fut.cancelled() and fut.exception() is not None:
        ctx.event("planner_error", level=logging.ERROR, error=str(fut.exception()), late=True)


def hold(ctx: MissionContext, reason: str) -> None:
    if ctx.hold_reason != reason:
        ctx.hold_reason = reason
        ctx.state = MissionState.HOLDING


# -- setpoints -----------------------------------------------------------------------------------


async def setpoints(ctx: MissionContext) -> None:
    """Stream velocity setpoints at 20 Hz wall while in control. The guard's timing follows
    what the loop really achieves: the latency is the position's age plus the link's, the
    period the slowest recent setpoint interval, both in vehicle seconds (at a high time
    scale on a busy machine a few wall milliseconds are metres)."""
    m = ctx.mission
    speed, alt = m.flight.speed_m_s, m.flight.alt_m
    brake = min(m.flight.max_accel_m_s2, PX4_MPC_ACC_HOR_M_S2)
    failures = 0
    intervals: collections.deque[float] = collections.deque(maxlen=40)
    last = time.monotonic()
    while ctx.commander.in_control:
        now = time.monotonic()
        intervals.append(now - last)
        last = now
        tel = ctx.vehicle.hub.latest
        _, en, rel_alt = ctx.vehicle_state()
        heading = None if (ctx.hold_reason or ctx.operator_pause) else ctx.heading_deg
        if not all(map(math.isfinite, en)):
            sp = Setpoint(0.0, 0.0, 0.0, tel.yaw_deg, "hold")
        else:
            rate = ctx.clock.rate
            age_wall = min(max(now - ctx.position_mono, 0.0), 2.0)
            target_alt = alt if ctx.target_alt_m is None else ctx.target_alt_m
            sp = velocity_setpoint(heading, speed, en, rel_alt, target_alt, ctx.area, tel.yaw_deg,
                                   (tel.v_east_m_s, tel.v_north_m_s), brake_m_s2=brake,
                                   latency_s=LATENCY_S + rate * age_wall,
                                   period_s=rate * max(max(intervals), 1.0 / SETPOINT_HZ))
            ctx.track.append(en)
        if ctx.state in (MissionState.SEARCHING, MissionState.HOLDING):
            ctx.state = MissionState.HOLDING if sp.reason == "hold" else MissionState.SEARCHING
        try:
            if await ctx.commander.set_velocity_ned(sp.v_north_m_s, sp.v_east_m_s,
                                                    sp.v_down_m_s, sp.yaw_deg):
                ctx.log.write("setpoint", t=ctx.clock.now(), v_north_m_s=sp.v_north_m_s,
                              v_east_m_s=sp.v_east_m_s, v_down_m_s=sp.v_down_m_s,
                              yaw_deg=sp.yaw_deg, reason=sp.reason)
        except VehicleError as exc:
            failures += 1
            if failures == 1 or failures % 100 == 0:
                ctx.event("setpoint_failed", level=logging.WARNING, error=str(exc),
                          failures=failures)
        await asyncio.sleep(1.0 / SETPOINT_HZ)


# -- safety rules --------------------------------------------------------------------------------


async def safety_rules(ctx: MissionContext) -> None:
    s = ctx.mission.safety
    limits = safety.SafetyLimits(
        max_mission_time_s=s.max_mission_time_s, battery_rtl_percent=s.battery_rtl_percent,
        link_loss_timeout_s=s.link_loss_timeout_s, on_link_regained=s.on_link_regained,
        radio_heartbeat_timeout_s=ctx.mission.receiver.heartbeat_timeout_s,
        radio_loss_timeout_s=s.radio_loss_timeout_s)
    last = "ok"
    while True:
        await asyncio.sleep(1.0 / SAFETY_HZ)
        if not ctx.commander.in_control:
            continue  # the autopilot has control: no rule commands anything
        tel = ctx.vehicle.hub.latest
        t = ctx.clock.now()
        age_wall = ctx.vehicle.hub.age_s()
        link_age = age_wall * ctx.clock.rate if age_wall > LINK_MIN_WALL_S else 0.0
        inp = safety.SafetyInputs(
            elapsed_s=ctx.mission_elapsed_s(t), battery_percent=tel.battery_percent,
            link_age_s=link_age, link_connected=tel.connected,
            radio_silent_s=t - ctx.last_radio_t, link_was_lost=ctx.link_was_lost)
        d = safety.decide(inp, limits)
        if d.reason != last:
            ctx.event("safety", action=d.action.value, reason=d.reason,
                      level=logging.WARNING if d.action is not safety.Action.NONE
                      else logging.INFO)
            last = d.reason
        if d.action is safety.Action.RTL:
            ctx.finish(EndReason(d.reason))
        elif d.action is safety.Action.HOLD:
            if d.reason == "link_lost":
                ctx.link_was_lost = True
            hold(ctx, d.reason)
        elif d.action is safety.Action.RESUME_OFFBOARD:
            await resume_after_link(ctx)
        elif ctx.hold_reason in ("radio_silent", "link_lost"):
            ctx.hold_reason = None


async def resume_after_link(ctx: MissionContext) -> None:
    """The link is back: re-enter offboard if PX4 left it for its offboard-loss hold."""
    tel = ctx.vehicle.hub.latest
    ctx.link_was_lost = False
    ctx.telemetry_gap_seen = False
    ctx.hold_reason = None
    if tel.flight_mode == "OFFBOARD":
        ctx.commander.expect({"OFFBOARD"})  # still ours: watch it again
        return
    if not tel.in_air:
        ctx.finish(EndReason.LANDED_DURING_LINK_LOSS)
    try:
        if await ctx.commander.start_offboard(tel.yaw_deg):
            ctx.event("offboard_resumed", previous_mode=tel.flight_mode)
    except VehicleError as exc:
        ctx.event("resume_failed", level=logging.ERROR, error=str(exc))
        ctx.finish(EndReason.RESUME_FAILED)
