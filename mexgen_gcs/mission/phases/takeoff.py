"""Takeoff: arm, take off to flight.alt_m and wait for the climb. Safe action: return to
launch (the return phase; a vehicle still on the ground is left alone).

Heights are above the vehicle's own home (MAVSDK relative altitude).
"""

from __future__ import annotations

import asyncio

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.phases.common import supervised
from mexgen_gcs.mission.state import MissionEnd, MissionState, ReturnAction


async def run(ctx: MissionContext) -> None:
    if ctx.stop is not None:  # asked before arming: end on the ground
        ctx.set_end(ctx.stop.reason)
        ctx.event("mission_end_on_ground", reason=ctx.stop.reason, armed=False)
        raise MissionEnd(ctx.stop.reason, ReturnAction.NONE)
    ctx.phase = "takeoff"
    ctx.state = MissionState.TAKEOFF
    await supervised(ctx, _climb(ctx))


async def _climb(ctx: MissionContext) -> None:
    alt = ctx.mission.flight.alt_m
    ctx.armed_by_us = True  # from the arm command on, the safe action is a return
    if not await ctx.commander.arm():
        return
    ctx.event("armed")
    if not await ctx.commander.takeoff(alt):
        return
    ctx.event("takeoff", alt_m=alt)
    hub = ctx.vehicle.hub
    wall_s = ctx.opt.takeoff_timeout_s / ctx.clock.rate
    try:
        async with asyncio.timeout(wall_s):
            while not hub.latest.rel_alt_m >= 0.95 * alt:
                await asyncio.sleep(0.05)
    except TimeoutError:
        raise VehicleError("climb to mission altitude",
                           f"timeout after {ctx.opt.takeoff_timeout_s:.0f} s") from None
    ctx.t_airborne = ctx.clock.now()
    ctx.core.reset_clock(ctx.t_airborne)
