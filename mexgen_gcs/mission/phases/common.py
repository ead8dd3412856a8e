"""What every phase shares: running its tasks under the mission's interrupt, and holding the
vehicle still in offboard while a command to leave offboard is on its way.

Frames: setpoints are NED m/s with a compass yaw in degrees.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Coroutine
from typing import Any

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.mission.commander import OFFBOARD
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.state import (
    Fault,
    MissionEnd,
    MissionSignal,
    PhaseDone,
    Takeover,
)

SETPOINT_HZ = 20.0


def pending_signal(ctx: MissionContext) -> MissionSignal | None:
    """What the mission's interrupt means now, most important first; None if nothing new."""
    if ctx.takeover is not None and not ctx.commander.in_control:
        return Takeover()
    if ctx.faults > ctx.faults_handled:
        ctx.faults_handled = ctx.faults
        return Fault()
    if ctx.stop is not None:
        return MissionEnd(ctx.stop.reason, ctx.stop.action)
    return None


async def _watch(ctx: MissionContext) -> None:
    while True:
        signal = pending_signal(ctx)
        if signal is not None:
            raise signal
        ctx.interrupt.clear()
        await ctx.interrupt.wait()


_RANK = (Takeover, Fault, Exception, MissionEnd, PhaseDone)


def _most_important(eg: BaseExceptionGroup[Any]) -> BaseException:
    flat: list[BaseException] = []

    def walk(e: BaseException) -> None:
        if isinstance(e, BaseExceptionGroup):
            for sub in e.exceptions:
                walk(sub)
        else:
            flat.append(e)

    walk(eg)
    for kind in _RANK:
        for e in flat:
            if isinstance(e, kind) and (kind is not Exception or not isinstance(
                    e, MissionSignal)):
                return e
    return flat[0]


async def supervised(ctx: MissionContext, main: Coroutine[Any, Any, None] | None,
                     *tasks: Coroutine[Any, Any, None]) -> None:
    """Run a phase: `main` (returns when the phase is done) and `tasks` (run until something
    ends the phase) in one TaskGroup with a watcher on the mission's interrupt. Returns when
    `main` returns; raises the most important signal or error otherwise (a takeover before a
    fault before an error before a planned end)."""

    async def run_main() -> None:
        assert main is not None
        await main
        raise PhaseDone

    try:
        async with asyncio.TaskGroup() as g:
            if main is not None:
                g.create_task(run_main(), name="phase-main")
            for i, coro in enumerate(tasks):
                g.create_task(coro, name=f"phase-task-{i}")
            g.create_task(_watch(ctx), name="phase-watch")
    except BaseExceptionGroup as eg:
        exc = _most_important(eg)
        if isinstance(exc, PhaseDone):
            return
        raise exc from None


async def hold_while_offboard(ctx: MissionContext, wall_s: float) -> None:
    """Stream zero-velocity setpoints while the vehicle is still in offboard (at most
    `wall_s`), so it is never left in offboard without setpoints while a return, a land or
    a retry of either is on its way. Stops at once if the GCS is not in control."""
    hub = ctx.vehicle.hub
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wall_s
    while loop.time() < deadline and hub.latest.flight_mode == OFFBOARD:
        if not ctx.commander.in_control:
            return
        try:
            await ctx.commander.set_velocity_ned(0.0, 0.0, 0.0, hub.latest.yaw_deg)
        except VehicleError as exc:
            if ctx.count("hold_setpoint_failed") == 1:
                ctx.event("setpoint_failed", level=logging.WARNING, error=str(exc))
        await asyncio.sleep(1.0 / SETPOINT_HZ)
