"""Return: command return to launch (or land, if that is what the operator asked), then watch
until the vehicle has landed and disarmed, bounded by ``landing_timeout_s`` of vehicle time.

Safe action of this phase: on a fault, re-command the return (or the land) once, then wait.
After a takeover nothing is commanded: the GCS keeps logging and waits for the landing, and
only the operator may command again (a UI key or Ctrl-C: return to launch; ``land``: land).
SIGHUP/SIGTERM after a takeover stop the wait (the GCS does not fly a vehicle it does not
control). An operator's land is never overridden by a return. While the vehicle is still in
offboard, zero-velocity setpoints keep streaming so it is never left in offboard without them.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Coroutine
from typing import Any

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.mission.commander import OFFBOARD
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.phases.common import SETPOINT_HZ, hold_while_offboard
from mexgen_gcs.mission.state import MissionState, ReturnAction, StopRequest

COMMAND_ATTEMPTS = 3
FRESH_AFTER_COMMAND_S = 1.2
"""Telemetry this much newer than the last command shows its effect (PX4's heartbeat, which
carries the armed flag, comes once a second)."""
RETRY_EVERY_S = 2.0
"""Wall seconds between retries of a return (or land) that has not gone through."""


async def run(ctx: MissionContext, action: ReturnAction) -> None:
    ctx.phase = "return"
    commanded = False
    if not ctx.commander.in_control:
        action = ReturnAction.NONE
        ctx.state = MissionState.TAKEOVER
    elif not ctx.commander.may_be_armed():
        ctx.event("on_the_ground", action="none")
        action = ReturnAction.NONE
    if action is not ReturnAction.NONE:
        ctx.state = MissionState.RETURNING
        commanded = bool(await _safely(ctx, command(ctx, action)))
    await watch_landing(ctx, action, commanded)


async def command(ctx: MissionContext, action: ReturnAction, *, operator: bool = False,
                  attempts: int = COMMAND_ATTEMPTS) -> bool:
    """Command the return or the land (retrying), holding in offboard meanwhile."""
    for attempt in range(attempts):
        try:
            if action is ReturnAction.LAND:
                ok = await ctx.commander.land(operator=operator)
            else:
                ok = await ctx.commander.return_to_launch(operator=operator)
            if not ok:
                return False
            ctx.event("land_commanded" if action is ReturnAction.LAND else "rtl_commanded",
                      reason=ctx.end_reason, operator=operator)
            await hold_while_offboard(ctx, 3.0)
            return True
        except VehicleError as exc:
            ctx.event("land_failed" if action is ReturnAction.LAND else "rtl_failed",
                      level=logging.ERROR, error=str(exc), attempt=attempt)
            await hold_while_offboard(ctx, 1.0)
    return False


async def watch_landing(ctx: MissionContext, action: ReturnAction, commanded: bool) -> None:
    """Wait for landed and disarmed (bounded). Meanwhile: hold setpoints while the vehicle is
    still in offboard (and retry a command that has not gone through), follow the operator,
    re-command once after a fault, and stand back after a takeover."""
    hub = ctx.vehicle.hub
    loop = asyncio.get_running_loop()
    seen_stop: StopRequest | None = ctx.stop
    faults_seen = ctx.faults
    recommanded = False
    waited_vehicle_s = 0.0
    last = last_try = loop.time()
    while True:
        tel = hub.latest
        fresh = tel.updated_wall - ctx.commander.last_command_mono > FRESH_AFTER_COMMAND_S
        if not tel.armed and not tel.in_air and fresh:
            ctx.state = MissionState.LANDED
            ctx.landed_ok = True
            ctx.event("landed_and_disarmed")
            return
        if not ctx.commander.in_control and ctx.state is not MissionState.TAKEOVER:
            ctx.state = MissionState.TAKEOVER  # a pilot took over during the return
        if ctx.stop is not seen_stop and ctx.stop is not None:
            seen_stop = ctx.stop
            if seen_stop.operator and seen_stop.action is not ReturnAction.NONE:
                if seen_stop.action is ReturnAction.LAND or action is not ReturnAction.LAND:
                    action = seen_stop.action  # never a return over the operator's land
                    ctx.state = MissionState.RETURNING
                    commanded = bool(await _safely(ctx, command(ctx, action, operator=True)))
            elif not ctx.commander.in_control:
                ctx.event("stopped_waiting", level=logging.WARNING, reason=seen_stop.reason,
                          note="the autopilot has control; the GCS exits without commanding")
                return
        if ctx.faults > faults_seen:
            faults_seen = ctx.faults
            if not recommanded and ctx.commander.in_control and action is not ReturnAction.NONE:
                recommanded = True
                ctx.event("return_recommanded", level=logging.WARNING, action=action)
                commanded = bool(await _safely(ctx, command(ctx, action, attempts=1)))
        if ctx.commander.in_control and action is not ReturnAction.NONE and (
                tel.flight_mode == OFFBOARD):
            await _safely(ctx, hold_while_offboard(ctx, 1.0 / SETPOINT_HZ))
            if not commanded and loop.time() - last_try >= RETRY_EVERY_S:
                last_try = loop.time()
                commanded = bool(await _safely(ctx, command(ctx, action, attempts=1)))
        await asyncio.sleep(1.0 / SETPOINT_HZ)
        now = loop.time()
        waited_vehicle_s += (now - last) * ctx.clock.rate
        last = now
        if waited_vehicle_s > ctx.opt.landing_timeout_s:
            ctx.event("landing_not_confirmed", level=logging.ERROR,
                      waited_s=round(waited_vehicle_s, 1), armed=tel.armed, in_air=tel.in_air)
            return


async def _safely(ctx: MissionContext, coro: Coroutine[Any, Any, Any]) -> Any:
    """Run a command coroutine; an unexpected exception is a fault, not the end of the wait."""
    try:
        return await coro
    except Exception as exc:
        ctx.fault("return", exc)
        return None
