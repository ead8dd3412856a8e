"""The mission's long-lived background tasks, and the wrapper that contains their failures.

Owned by the controller's TaskGroup for the whole mission (every phase needs them): the
vehicle's telemetry streams, the telemetry log and headless progress line, the snapshot
publisher for the UI, the operator's commands and the mode watch (a commanded mode change
that never lands is a takeover too). ``contained`` turns an unexpected exception in any of
them into ``ctx.fault`` (the running phase takes its safe action) instead of cancelling the
mission; telemetry restarts so a return can still be watched. Views and progress output can
never stop a flight: their failures are logged and skipped. No frames here.
"""

from __future__ import annotations

import asyncio
import logging
import os
import sys
import time
from collections.abc import Awaitable, Callable

from mexgen_gcs.core.generators import METHODS
from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.vehicle import StatusText
from mexgen_gcs.mission import views
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.state import EndReason, ReturnAction, StopRequest

log = logging.getLogger("mexgen_gcs.mission")

SNAPSHOT_HZ = 4.0
TELEMETRY_LOG_HZ = 2.0
MODE_WATCH_HZ = 10.0
RESTART_DELAY_S = 1.0

OPERATOR_STOPS = {
    "rtl": (EndReason.OPERATOR_RTL, ReturnAction.RTL),
    "abort": (EndReason.OPERATOR_ABORT, ReturnAction.RTL),
    "land": (EndReason.OPERATOR_LAND, ReturnAction.LAND),
}
SIGNAL_STOPS = {
    "SIGHUP": EndReason.SIGNAL_SIGHUP,
    "SIGTERM": EndReason.SIGNAL_SIGTERM,
}


async def contained(ctx: MissionContext, name: str, task: Callable[[], Awaitable[None]],
                    *, restarts: int = 0) -> None:
    """Run `task`; an unexpected exception becomes a fault (and a restart, up to `restarts`)."""
    attempt = 0
    while True:
        try:
            await task()
            return
        except Exception as exc:
            ctx.fault(name, exc)
            if attempt >= restarts:
                return
            attempt += 1
            await asyncio.sleep(RESTART_DELAY_S)
            ctx.event("task_restarted", level=logging.WARNING, task=name, attempt=attempt)


async def telemetry(ctx: MissionContext) -> None:
    """The vehicle's telemetry streams, which run until cancelled: streams that end are a
    fault (the running phase takes its safe action; ``contained`` re-subscribes), not a quiet
    stop that would leave the mode watch blind."""
    await ctx.vehicle.run_telemetry()
    raise VehicleError("telemetry", "the streams ended")


def on_status_text(ctx: MissionContext) -> Callable[[StatusText], None]:
    """Hub listener: every STATUSTEXT becomes a `statustext` record and an event line."""
    def listener(st: StatusText) -> None:
        t = ctx.clock.now()
        ctx.log.write("statustext", t=t, severity=st.severity, text=st.text)
        ctx.events.append(f"{t - ctx.t_start:7.1f}s autopilot [{st.severity}] {st.text}")
    return listener


CLOCK_LOG_EVERY = 20
"""Telemetry records between two `clock` records (the vehicle clock's fit)."""


async def telemetry_log(ctx: MissionContext) -> None:
    last_print = time.monotonic()
    describe = getattr(ctx.clock, "describe", None)
    n = 0
    while True:
        log_rejects(ctx)
        if describe is not None and n % CLOCK_LOG_EVERY == 0:
            ctx.log.write("clock", t=ctx.clock.now(), **describe())
        n += 1
        tel = ctx.vehicle.hub.latest
        ctx.log.write("telemetry", t=ctx.clock.now(), lat=tel.lat_deg, lon=tel.lon_deg,
                      rel_alt_m=tel.rel_alt_m, v_north_m_s=tel.v_north_m_s,
                      v_east_m_s=tel.v_east_m_s, yaw_deg=tel.yaw_deg, mode=tel.flight_mode,
                      armed=tel.armed, in_air=tel.in_air, battery_percent=tel.battery_percent,
                      connected=tel.connected)
        if ctx.print_progress and time.monotonic() - last_print >= (
                ctx.opt.headless_progress_s):
            last_print = time.monotonic()
            print_progress(ctx)
        await ctx.clock.sleep(1.0 / TELEMETRY_LOG_HZ)  # mission time: same log at any speed


def print_progress(ctx: MissionContext) -> None:
    """The headless progress line; a dead terminal (SSH gone) switches it off for good."""
    try:
        line = views.progress_line(ctx)
        print(line, flush=True)
    except (OSError, ValueError) as exc:  # BrokenPipeError, EIO, a closed stdout
        ctx.print_progress = False
        ctx.count("progress_output_lost")
        ctx.event("progress_output_lost", level=logging.WARNING,
                  error=f"{type(exc).__name__}: {exc}")
        _silence_stdout()
    except Exception as exc:
        log.warning("progress line failed: %s: %s", type(exc).__name__, exc)


def _silence_stdout() -> None:
    """Point stdout at /dev/null so later prints (and the interpreter's final flush) cannot
    fail on the dead terminal."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def log_rejects(ctx: MissionContext) -> None:
    """Account for every rejected datagram: per-reason deltas since the last record."""
    now = dict(ctx.receiver.rejects)
    logged = ctx.logged_rejects
    delta = {k: v - logged.get(k, 0) for k, v in now.items() if v != logged.get(k, 0)}
    if delta:
        ctx.log.write("reject", t=ctx.clock.now(), counts=delta, total=now)
        ctx.logged_rejects = now


async def snapshots(ctx: MissionContext) -> None:
    while True:
        publish(ctx)
        await asyncio.sleep(1.0 / SNAPSHOT_HZ)


def publish(ctx: MissionContext) -> None:
    try:
        ctx.bus.publish(views.build_snapshot(ctx))
    except Exception as exc:
        if ctx.count("snapshot_failures") == 1:
            log.warning("snapshot failed: %s: %s", type(exc).__name__, exc)


async def mode_watch(ctx: MissionContext) -> None:
    """Re-check the mode a few times a second: a commanded change that never lands (the
    grace runs out with the old mode still set) is a takeover too."""
    while True:
        await asyncio.sleep(1.0 / MODE_WATCH_HZ)
        ctx.check_takeover()


async def operator(ctx: MissionContext) -> None:
    """Operator commands (UI keys, Ctrl-C) and signals, for every phase."""
    while True:
        cmd = await ctx.commands.get()
        if cmd.startswith("signal:"):
            name = cmd.split(":", 1)[1]
            ctx.event("signal", level=logging.WARNING, signal=name)
            ctx.request_stop(StopRequest(SIGNAL_STOPS.get(name, EndReason.SIGNAL_SIGTERM),
                                         ReturnAction.RTL, operator=False))
            continue
        ctx.event("operator_command", command=cmd)
        if cmd == "pause":
            ctx.operator_pause = True
        elif cmd == "resume":
            ctx.operator_pause = False
        elif cmd in OPERATOR_STOPS:
            reason, action = OPERATOR_STOPS[cmd]
            ctx.request_stop(StopRequest(reason, action, operator=True))
        elif cmd.startswith("method:") and cmd.split(":", 1)[1] in METHODS:
            ctx.method = cmd.split(":", 1)[1]
