"""The mission controller: flies one tag-localisation mission through four phases.

Frames: the decision logic works in local ENU metres about the mission home horizontally and
in heights above the vehicle's own home; telemetry and setpoints are MAVLink NED / WGS84 and
are converted at the edge (``MissionContext.vehicle_state``, ``guidance``). Times are the
vehicle's clock (``io.clock.VehicleClock``): re-planning, the filter cadence, limits, safety
timeouts and every logged ``t``.

Who owns what. The controller's TaskGroup owns, for the whole mission, the vehicle's
telemetry streams, radio ingest, the telemetry log, the snapshot publisher, the operator's
commands and the mode watch (``mission.background``), each inside ``contained``: an
unexpected exception there becomes a fault for the running phase instead of cancelling the
mission. The flight sequence runs the phases one after the other; each phase owns the tasks
it starts (``mission.phases``).

Safe action of each phase (what any unexpected exception, fault, signal or failed rule leads
to; every ending writes a ``result`` record with the end reason and the error, if any):

============  ================================================================================
preflight     nothing is armed; the mission ends on the ground (exit 1)
takeoff       return to launch, then wait for landed and disarmed
search        return to launch (an operator's ``land``: land here), then wait
return        re-command the return (or the land) once, then keep waiting (bounded)
takeover      (any phase, the autopilot or a pilot set a mode the GCS did not command, or
              disarmed in flight) stop every command and setpoint at once, log the mode and
              the autopilot's STATUSTEXT reasons, end with ``autopilot_takeover`` (exit 1),
              keep logging and wait for landed and disarmed; command again only if the
              operator asks (UI key, Ctrl-C = return to launch)
============  ================================================================================

Cancelled (the task running ``run`` is cancelled, e.g. by the UI's task group): return to
launch is commanded once (bounded), the ``result`` record (``cancelled``) is written and the
CancelledError propagates; the landing is the autopilot's.

SIGINT (Ctrl-C) is the operator's abort; SIGHUP and SIGTERM return the vehicle and land, then
exit (after a takeover they only end the wait). Log I/O errors (disk full) degrade to a
warning and a count of lost records; a late planner is skipped, never queued; progress output
to a dead terminal and any UI failure never stop a flight.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from mexgen_gcs.config.mission import Mission
from mexgen_gcs.core.mission_core import MissionCore
from mexgen_gcs.errors import MexgenError
from mexgen_gcs.io.clock import Clock
from mexgen_gcs.io.plans import MissionPlanner
from mexgen_gcs.io.snapshot import SnapshotBus
from mexgen_gcs.io.vehicle import Vehicle
from mexgen_gcs.mission import background as bg
from mexgen_gcs.mission import views
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.ingest import radio_ingest
from mexgen_gcs.mission.logsink import MissionLog
from mexgen_gcs.mission.phases import preflight, returning, search, takeoff
from mexgen_gcs.mission.state import (
    ControllerOptions,
    EndReason,
    Fault,
    MissionEnd,
    MissionResult,
    MissionState,
    ReturnAction,
    Takeover,
)

__all__ = ["ControllerOptions", "MissionController", "MissionResult"]

log = logging.getLogger(__name__)


CANCEL_COMMAND_S = 5.0
"""Wall seconds a cancelled mission waits for its return (or land) command to go out."""


class _Over(Exception):
    pass


class MissionController:
    """Flies one mission. Construct with the mission, its ports and a MissionCore."""

    def __init__(
        self,
        mission: Mission,
        vehicle: Vehicle,
        receiver: Any,
        clock: Clock,
        core: MissionCore,
        flight_log: Any,
        *,
        method: str,
        rng: np.random.Generator,
        connect_url: str,
        options: ControllerOptions | None = None,
        truth: Callable[[], dict[str, tuple[float, float]]] | None = None,
    ) -> None:
        sink = flight_log if isinstance(flight_log, MissionLog) else MissionLog(
            flight_log, fsync_every_s=mission.log.fsync_every_s)
        self.ctx = MissionContext(mission, vehicle, receiver, clock, core, sink, method=method,
                                  rng=rng, connect_url=connect_url,
                                  options=options or ControllerOptions(), truth=truth)
        sink.on_loss = lambda text: self.ctx.events.append(f"flight log: {text}")
        self.planner = MissionPlanner(mission)
        self._executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="planner")
        self.result: MissionResult | None = None
        """The result, once ``run`` has ended (also when it was cancelled)."""

    # -- public ------------------------------------------------------------------------------

    @property
    def bus(self) -> SnapshotBus:
        return self.ctx.bus

    @property
    def state(self) -> MissionState:
        return self.ctx.state

    def request(self, command: str) -> None:
        """Operator command: pause | resume | rtl | land | abort | method:<name>; signals
        arrive as signal:SIGHUP / signal:SIGTERM."""
        try:
            self.ctx.commands.put_nowait(command)
        except asyncio.QueueFull:
            self.ctx.event("command_dropped", level=logging.WARNING, command=command)

    def escalate(self, why: str) -> None:
        """A stop request that cannot be obeyed (a second stop signal while the vehicle does
        not answer): logged, nothing more is commanded, and the end reason says so. The
        caller then cancels ``run``, which writes the result record."""
        ctx = self.ctx
        ctx.escalated = True
        ctx.event("signal_repeated", level=logging.ERROR, why=why, phase=ctx.phase,
                  note="exiting now without waiting for the vehicle")
        ctx.end_reason = EndReason.SIGNAL_REPEATED

    async def run(self) -> MissionResult:
        """Fly the mission to its result. Cancelled (the caller's task group, an app closing):
        the sequence commands its safe action (``_cancelled``), the ``result`` record is
        written, and the CancelledError propagates."""
        ctx = self.ctx
        cancelled: asyncio.CancelledError | None = None
        try:
            try:
                async with asyncio.TaskGroup() as tg:
                    tg.create_task(bg.contained(ctx, "radio", lambda: radio_ingest(ctx)),
                                   name="radio")
                    tg.create_task(bg.contained(ctx, "operator", lambda: bg.operator(ctx),
                                                restarts=5), name="operator")
                    tg.create_task(bg.snapshots(ctx), name="snapshots")
                    tg.create_task(self._sequence(tg), name="sequence")
            except* _Over:
                pass
        except asyncio.CancelledError as exc:
            cancelled = exc
            ctx.set_end(EndReason.CANCELLED)
        finally:
            self._executor.shutdown(wait=False, cancel_futures=True)
        ctx.state = MissionState.DONE
        result = views.build_result(ctx)
        self._final_records(result)
        ctx.log.close()  # drains the writer thread (bounded): the result record is on disk
        self.result = result
        if cancelled is not None:
            raise cancelled
        return result

    # -- the flight sequence -----------------------------------------------------------------

    async def _sequence(self, tg: asyncio.TaskGroup) -> None:
        try:
            await self._phases(tg)
        except asyncio.CancelledError:
            await self._cancelled()
            raise
        raise _Over

    async def _cancelled(self) -> None:
        """The safe action of a cancelled mission: return to launch (the operator's land, if
        asked), commanded once and bounded by ``CANCEL_COMMAND_S``; the autopilot flies it
        home and lands on its own. The landing is not watched: the telemetry task is being
        cancelled with this one."""
        ctx = self.ctx
        ctx.set_end(EndReason.CANCELLED)
        ctx.event("cancelled", level=logging.WARNING, phase=ctx.phase)
        if not (ctx.armed_by_us and ctx.commander.in_control and not ctx.landed_ok
                and ctx.commander.may_be_armed()) or ctx.escalated:
            return
        land = (ctx.stop is not None and ctx.stop.operator
                and ctx.stop.action is ReturnAction.LAND)
        try:
            async with asyncio.timeout(CANCEL_COMMAND_S):
                if land:
                    await ctx.commander.land()
                else:
                    await ctx.commander.return_to_launch()
            ctx.event("land_commanded" if land else "rtl_commanded", reason=ctx.end_reason,
                      operator=False, note="cancelled: the landing is not watched")
        except Exception as exc:  # TimeoutError, VehicleError, ...: logged, the exit goes on
            ctx.fault("return", exc)

    async def _phases(self, tg: asyncio.TaskGroup) -> None:
        ctx = self.ctx
        action = ReturnAction.NONE
        try:
            await preflight.run(ctx, lambda: self._start_vehicle_tasks(tg))
            await takeoff.run(ctx)
            await search.run(ctx, self.planner, self._executor)
        except MissionEnd as end:
            ctx.set_end(end.reason)
            action = end.action
        except Takeover:
            action = ReturnAction.NONE
        except Fault:
            ctx.set_end(EndReason.ERROR)
            action = ReturnAction.RTL
        except MexgenError as exc:  # a vehicle command failed, a timeout, ...
            ctx.error = ctx.error or f"{type(exc).__name__}: {exc}"
            ctx.event("flight_error", level=logging.ERROR, phase=ctx.phase, error=str(exc))
            ctx.set_end(EndReason.VEHICLE_ERROR)
            action = ReturnAction.RTL
        except Exception as exc:
            ctx.fault(ctx.phase, exc)
            ctx.set_end(EndReason.ERROR)
            action = ReturnAction.RTL
        if ctx.stop is not None and ctx.stop.operator and ctx.stop.action is ReturnAction.LAND:
            action = ReturnAction.LAND  # the operator's land is never overridden
        if ctx.armed_by_us:
            try:
                await returning.run(ctx, action)
            except Exception as exc:
                ctx.fault("return", exc)
        elif ctx.end_reason is None:
            ctx.set_end(EndReason.ERROR)

    def _start_vehicle_tasks(self, tg: asyncio.TaskGroup) -> None:
        """Once connected: listeners on the telemetry hub, then the vehicle's long-lived tasks."""
        ctx = self.ctx
        hub = ctx.vehicle.hub
        hub.on_update.append(ctx.on_update)
        hub.on_status_text.append(bg.on_status_text(ctx))
        observe = getattr(ctx.clock, "observe", None)
        if observe is not None:
            hub.on_time.append(observe)
        tg.create_task(bg.contained(ctx, "telemetry", lambda: bg.telemetry(ctx), restarts=3),
                       name="telemetry")
        tg.create_task(bg.contained(ctx, "telemetry-log", lambda: bg.telemetry_log(ctx),
                                    restarts=3), name="telemetry-log")
        tg.create_task(bg.contained(ctx, "mode-watch", lambda: bg.mode_watch(ctx),
                                    restarts=3), name="mode-watch")

    def _final_records(self, result: MissionResult) -> None:
        ctx = self.ctx
        try:
            bg.log_rejects(ctx)
            ctx.log.write("result", t=ctx.clock.now(), end_reason=result.end_reason,
                          exit_code=result.exit_code, localised=result.localised,
                          unresolved=result.unresolved,
                          reports=result.reports or None,
                          rejects=result.rejects, duration_s=result.duration_s,
                          error=result.error, takeover=result.takeover,
                          counters=result.counters)
        except Exception:
            log.exception("could not write the result record")
        bg.publish(ctx)

    # -- views (for the UI and tests) --------------------------------------------------------

    def progress_line(self) -> str:
        return views.progress_line(self.ctx)

    def snapshot(self) -> Any:
        return views.build_snapshot(self.ctx)
