"""Flying a mission with real ports (`fly_mission`) and the scripted-SITL API `run_sitl`; the
command-line handlers of `mexgen-gcs sitl` and `fly` (which add the terminal UI) are in
`ui.commands`.

``run_sitl(mission, seed=..., speedup=..., overrides=...)`` starts ``python -m sim`` as a child
process on matching loopback ports, flies the mission through the real MAVSDK and UDP radio
path, stops the simulator and returns a ``MissionResult`` with per-tag errors against the
simulator's ground truth. ``fly`` is the same without the child process.
"""

from __future__ import annotations

import asyncio
import contextlib
import copy
import logging
import math
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mexgen_gcs.config import dump_resolved, load_mission, parse_mission
from mexgen_gcs.config.mission import Mission
from mexgen_gcs.errors import ConfigError, LogFormatError, MexgenError
from mexgen_gcs.io.clock import Clock, VehicleClock
from mexgen_gcs.io.flightlog import FlightLogWriter
from mexgen_gcs.io.mavlink_tap import TLOG_FILE
from mexgen_gcs.io.radio_udp import RadioPolicy, RadioReceiver
from mexgen_gcs.io.truthfile import TRUTH_FILE, TagPositions, read_truth_file
from mexgen_gcs.io.tunnel import TunnelReceiver
from mexgen_gcs.io.vehicle import MavsdkVehicle
from mexgen_gcs.mission.controller import ControllerOptions, MissionController, MissionResult
from mexgen_gcs.mission.iq_receiver import IqReceiverSpec, IqReceiverThread
from mexgen_gcs.mission.state import EndReason
from mexgen_gcs.receiver.run import ReceiveOptions
from mexgen_gcs.receiver.synth import SIM_CAL_OFFSET_DB

log = logging.getLogger(__name__)

MissionRunner = Callable[[MissionController], Awaitable[MissionResult]]
"""Flies a controller to its result with something attached (``ui.app.run_with_ui``)."""

DEFAULT_MAVLINK_PORT = 14540
DEFAULT_RADIO_PORT = 14600


@dataclass(frozen=True, slots=True)
class SitlPorts:
    mavlink: int = DEFAULT_MAVLINK_PORT
    radio: int = DEFAULT_RADIO_PORT

    @classmethod
    def free(cls) -> SitlPorts:
        """Two free UDP ports on loopback (for tests and parallel batches)."""
        return cls(free_udp_port(), free_udp_port())


_FREE_PORTS = (20000, 32000)
"""Free ports are picked here, below Linux's ephemeral range (32768-60999): a port the kernel
chose (bind to 0) is handed again to any process's unbound socket once released, and a CI run
with two workers flying side by side lost its radio port that way between pick and bind."""
_PORT_RNG = np.random.default_rng()


def free_port(kind: socket.SocketKind = socket.SOCK_DGRAM) -> int:
    """A loopback port (UDP, or TCP with SOCK_STREAM) that was free a moment ago, outside the
    ephemeral range."""
    for _ in range(500):
        port = int(_PORT_RNG.integers(*_FREE_PORTS))
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    name = "TCP" if kind == socket.SOCK_STREAM else "UDP"
    raise OSError(f"no free {name} port on loopback in {_FREE_PORTS[0]}-{_FREE_PORTS[1]}")


def free_udp_port() -> int:
    """A UDP port on loopback that was free a moment ago, outside the ephemeral range."""
    return free_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    """A TCP port on loopback that was free a moment ago, outside the ephemeral range."""
    return free_port(socket.SOCK_STREAM)


def apply_overrides(mission: Mission, overrides: Mapping[str, Any] | None) -> Mission:
    """A new mission with dotted-key overrides applied (``{"planner.method": "pim"}``) and
    validated by the one schema; errors name the key."""
    if not overrides:
        return mission
    data = copy.deepcopy(dump_resolved(mission))
    for dotted, value in overrides.items():
        cursor = data
        parts = dotted.split(".")
        for key in parts[:-1]:
            if not isinstance(cursor, dict) or key not in cursor or cursor[key] is None:
                if isinstance(cursor, dict):
                    cursor[key] = {}
                else:
                    raise ConfigError(f"override {dotted!r}: {key!r} is not a section")
            cursor = cursor[key]
        cursor[parts[-1]] = value
    text = yaml.safe_dump(data, sort_keys=False)
    return parse_mission(text, source=f"{mission.source_path or '<mission>'} + overrides")


def make_log_dir(base: str | os.PathLike[str], mission: Mission, method: str, seed: int) -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
    d = Path(base) / f"{stamp}-{mission.name}-{method}-s{seed}"
    n = 1
    while d.exists():
        d = Path(base) / f"{stamp}-{mission.name}-{method}-s{seed}-{n}"
        n += 1
    d.mkdir(parents=True)
    return d


async def fly_mission(
    mission: Mission,
    *,
    connect_url: str,
    radio_url: str,
    clock: Clock,
    log_dir: Path,
    method: str,
    seed: int,
    options: ControllerOptions | None = None,
    truth_path: Path | None = None,
    runner: MissionRunner | None = None,
    iq: IqReceiverSpec | None = None,
    iq_send_url: str | None = None,
) -> MissionResult:
    """Fly one mission with real ports. The caller owns any simulator process. ``runner``
    flies the controller with something attached (the terminal UI); default: headless.
    ``iq``: run the IQ receiver in this process on that source, sending to ``iq_send_url``
    (default ``radio_url``)."""
    rng = np.random.default_rng(seed)
    core = mission.mission_core(rng.spawn(1)[0])
    policy = RadioPolicy.from_mission(mission, clock=clock.now,
                                      clock_synced=lambda: bool(getattr(clock, "synced", True)))
    with FlightLogWriter(log_dir, mission=mission, seed=seed, method=method,
                         clock=clock.now) as flight_log:
        async with make_receiver(mission, radio_url, policy) as receiver:
            vehicle = MavsdkVehicle(tlog_path=log_dir / TLOG_FILE)
            truth = TagPositions(truth_path) if truth_path is not None else None
            controller = MissionController(
                mission, vehicle, receiver, clock, core, flight_log, method=method,
                rng=rng.spawn(1)[0], connect_url=connect_url, options=options,
                truth=truth.positions if truth is not None else None)
            stops = StopSignals(controller, asyncio.current_task())
            signals = stops.install()
            iq_thread = (IqReceiverThread(mission, iq, iq_send_url or radio_url, clock,
                                          covered=_pose_covers(controller))
                         if iq else None)
            if iq_thread is not None:
                iq_thread.start()
            try:
                if runner is not None:
                    result = await runner(controller)
                else:
                    result = await controller.run()
            except asyncio.CancelledError:
                if not stops.escalated or controller.result is None:
                    raise
                task = asyncio.current_task()
                if task is not None:
                    task.uncancel()
                result = controller.result
            finally:
                for sig in signals:
                    asyncio.get_running_loop().remove_signal_handler(sig)
                if iq_thread is not None:
                    await asyncio.to_thread(iq_thread.close)
                await vehicle.close()
            result.log_dir = str(log_dir)
    return result


def _pose_covers(controller: MissionController) -> Callable[[float], bool]:
    """Whether the GCS's pose history reaches time t (read from the receiver's thread)."""
    def covers(t: float) -> bool:
        span = controller.ctx.poses.span
        return span is not None and span[1] >= t
    return covers


def make_receiver(mission: Mission, radio_url: str, policy: RadioPolicy) -> RadioReceiver:
    """The receiver of ``receiver.format``: wire-format JSON datagrams, or MAVLink TUNNEL
    pulse reports (TagTracker / UAV-RT), on ``radio_url``."""
    if mission.receiver.format == "mavlink-tunnel":
        return TunnelReceiver(radio_url, policy,
                              calibration_db=mission.receiver.tunnel_calibration_db)
    return RadioReceiver(radio_url, policy)


ESCALATION_EXIT_S = 4.0
"""Wall seconds after a repeated stop signal at which the process exits whatever it is doing
(the cooperative exit, the result record included, normally takes well under a second)."""


class StopSignals:
    """SIGINT is the operator's abort; SIGHUP (the terminal is gone) and SIGTERM ask the
    mission to end too: the vehicle returns and lands, then the program exits. A second stop
    signal while the first is still being obeyed (the vehicle gone, a landing that cannot
    come) escalates: ``MissionController.escalate`` logs it and ends the mission without
    commanding more, the flight task is cancelled (the result record is written), and
    ``ESCALATION_EXIT_S`` later the process exits regardless. Handlers only in the main
    thread on POSIX; elsewhere (flights in worker threads) none are set."""

    SIGNALS = (("SIGINT", "abort"), ("SIGTERM", "signal:SIGTERM"), ("SIGHUP", "signal:SIGHUP"))

    def __init__(self, controller: MissionController, task: asyncio.Task[Any] | None, *,
                 force_exit: Callable[[str], None] | None = None) -> None:
        self.controller = controller
        self.task = task
        self.force_exit = force_exit if force_exit is not None else _force_exit
        self.received: list[str] = []
        self.escalated = False

    def install(self) -> list[signal.Signals]:
        if sys.platform == "win32" or threading.current_thread() is not threading.main_thread():
            return []
        loop = asyncio.get_running_loop()
        installed = []
        for name, command in self.SIGNALS:
            sig = getattr(signal, name)
            loop.add_signal_handler(sig, self.on_signal, name, command)
            installed.append(sig)
        return installed

    def on_signal(self, name: str, command: str) -> None:
        self.received.append(name)
        if len(self.received) == 1:
            self.controller.request(command)
            return
        if self.escalated:
            return
        self.escalated = True
        why = f"{name} after {self.received[0]}: the first stop could not be obeyed"
        print(f"mexgen-gcs: {why}; exiting now", file=sys.stderr, flush=True)
        self.controller.escalate(why)
        if self.task is not None:
            self.task.cancel()
        timer = threading.Timer(ESCALATION_EXIT_S, self.force_exit, args=(why,))
        timer.daemon = True
        timer.start()


def _force_exit(why: str) -> None:
    """The backstop of an escalated stop: the cooperative exit has hung (a native call)."""
    with contextlib.suppress(Exception):
        print(f"mexgen-gcs: forced exit ({why})", file=sys.stderr, flush=True)
    os._exit(1)


def start_simulator(mission_path: Path, *, seed: int, speedup: float, ports: SitlPorts,
                    truth_dir: Path, extra_args: list[str] | None = None,
                    ready_timeout_s: float = 30.0) -> subprocess.Popen[str]:
    """Start `python -m sim` and wait for its ready line."""
    cmd = [sys.executable, "-m", "sim", str(mission_path), "--seed", str(seed),
           "--speedup", str(speedup), "--mavlink", f"127.0.0.1:{ports.mavlink}",
           "--radio", f"127.0.0.1:{ports.radio}", "--truth-dir", str(truth_dir),
           *(extra_args or [])]
    log_file = open(truth_dir / "sim.log", "w", encoding="utf-8")  # noqa: SIM115 - owned by proc
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log_file, text=True,
                            env={**os.environ, "MAVLINK20": "1"})
    try:
        ready = _wait_for_ready_line(proc, time.monotonic() + ready_timeout_s)
    except BaseException:  # Ctrl-C while waiting: the simulator goes too
        stop_simulator(proc, wait_s=0.0)
        raise
    if ready:
        return proc
    stop_simulator(proc, wait_s=0.0)
    raise MexgenError(f"the simulator did not start within {ready_timeout_s:.0f} s; "
                      f"see {truth_dir / 'sim.log'}")


def _wait_for_ready_line(proc: subprocess.Popen[str], deadline: float) -> bool:
    """Whether the simulator printed its ready line before the monotonic ``deadline``: the
    deadline bounds each read (a simulator that hangs before its first line, or mid-line,
    cannot hold the wait), not only the gaps between lines."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()  # read raw: the text wrapper's buffer would hide lines from select
    pending = b""
    while (remaining := deadline - time.monotonic()) > 0:
        readable, _, _ = select.select([fd], [], [], remaining)
        if not readable:
            return False
        chunk = os.read(fd, 4096)
        if not chunk:  # the simulator exited
            return False
        pending += chunk
        lines = pending.split(b"\n")
        pending = lines.pop()
        if any(line.startswith(b"sim ready") for line in lines):
            return True
    return False


def stop_simulator(proc: subprocess.Popen[str], wait_s: float = 20.0,
                   term_wait_s: float = 10.0) -> int | None:
    """Let the simulator finish on its own (it exits once landed), else SIGTERM, else kill."""
    try:
        return proc.wait(timeout=wait_s)
    except subprocess.TimeoutExpired:
        proc.terminate()
    try:
        return proc.wait(timeout=term_wait_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def run_sitl(
    mission: str | os.PathLike[str] | Any,
    *,
    seed: int = 1,
    speedup: float = 1.0,
    method: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    log_dir: str | os.PathLike[str] = "flights",
    ports: SitlPorts | None = None,
    sim_args: list[str] | None = None,
    options: ControllerOptions | None = None,
    runner: MissionRunner | None = None,
    time_scale: float | None = None,
    receiver: str = "sim",
) -> MissionResult:
    """Fly a mission against the built-in simulator; the scripted-SITL API.

    ``mission``: a path or a loaded Mission. ``overrides``: dotted keys, e.g.
    ``{"planner.method": "pim", "sim.seed": 3}``. ``ports``: defaults to the contract ports;
    ``SitlPorts.free()`` for parallel runs. The mission runs on the simulator's clock, measured
    from its SYSTEM_TIME (``time_scale``: a known rate instead). ``receiver``: ``sim`` (the
    simulator sends detections) or ``iq`` (the simulator serves IQ over rtl_tcp and the IQ
    receiver runs in this process). Raises ConfigError on a bad mission (nothing is started).
    """
    m = load_mission(mission) if isinstance(mission, str | os.PathLike) else mission
    if method is not None:
        overrides = {**(overrides or {}), "planner.method": method}
    m = apply_overrides(m, overrides)
    chosen = m.planner.method
    out = make_log_dir(log_dir, m, chosen, seed)
    resolved = out / "mission.yaml"
    resolved.write_text(yaml.safe_dump(dump_resolved(m), sort_keys=False), encoding="utf-8")
    ports = ports or SitlPorts()
    iq = None
    if receiver == "iq":
        iq_port = free_tcp_port()
        sim_args = [*(sim_args or []), "--iq-server", f"127.0.0.1:{iq_port}"]
        # The stream's samples are the simulator's time exactly; the mission clock is an
        # estimate of it that wanders by seconds on a loaded machine (its residual is logged),
        # so a gap is only declared when the counter lags that clock by 30 s: the simulator
        # drops samples only when 8 s of them wait in the socket.
        iq = IqReceiverSpec(f"rtltcp://127.0.0.1:{iq_port}", ReceiveOptions(
            cal_offset_db=SIM_CAL_OFFSET_DB, gap_tolerance_s=30.0),
            hold_s=25.0)
    elif receiver != "sim":
        raise ConfigError(f"receiver {receiver!r}: expected sim or iq")
    clock: Clock = VehicleClock(fixed_rate=time_scale)
    proc: subprocess.Popen[str] | None = None
    result: MissionResult | None = None
    try:  # start_simulator stops its process itself if interrupted while it waits
        proc = start_simulator(resolved, seed=seed, speedup=speedup, ports=ports, truth_dir=out,
                               extra_args=sim_args)
        result = asyncio.run(fly_mission(
            m, connect_url=f"udpin://127.0.0.1:{ports.mavlink}",
            radio_url=f"udp://127.0.0.1:{ports.radio}", clock=clock, log_dir=out,
            method=chosen, seed=seed, options=options, truth_path=out / TRUTH_FILE, runner=runner,
            iq=iq))
    finally:
        if proc is not None:
            if result is not None and result.end_reason == EndReason.SIGNAL_REPEATED:
                code = stop_simulator(proc, wait_s=0.0, term_wait_s=1.0)  # no time to wait
            else:
                code = stop_simulator(proc)
            log.info("simulator exited with %s", code)
    attach_truth_errors(result, out / TRUTH_FILE, m)
    return result


def attach_truth_errors(result: MissionResult, truth_path: Path, mission: Mission) -> None:
    """Add `error_m` per localised tag from the simulator's truth at localisation time, and per
    unresolved tag from the last truth."""
    if not truth_path.exists():
        return
    try:
        truth = read_truth_file(truth_path)
    except (LogFormatError, OSError) as exc:
        print(f"truth file not scored: {exc}", file=sys.stderr)
        return
    history: dict[str, list[tuple[float, float, float]]] = {}
    for rec in truth.tags():
        history.setdefault(rec.tag, []).append((rec.t, rec.x_m, rec.y_m))
    for tid, info in result.localised.items():
        rows = history.get(tid)
        if not rows:
            continue
        # the truth at the moment the tag was localised
        t_loc = info["t"]
        _, e, n = min(rows, key=lambda r: abs(r[0] - t_loc))
        info["error_m"] = math.hypot(info["east_m"] - e, info["north_m"] - n)
    for tid, info in result.unresolved.items():
        if rows := history.get(tid):  # the truth at the end
            _, e, n = max(rows)
            info["error_m"] = math.hypot(info["east_m"] - e, info["north_m"] - n)


def summary_text(result: MissionResult) -> str:
    lines = [f"mission end: {result.end_reason} (exit {result.exit_code}), "
             f"{result.duration_s:.0f} s mission time"]
    if result.error:
        lines.append(f"  error: {result.error}")
    if result.takeover:
        tk = result.takeover
        lines.append(f"  the autopilot took control: mode {tk['mode']} ({tk['reason']})")
    for tid, info in sorted(result.localised.items()):
        err = f", error {info['error_m']:.1f} m" if "error_m" in info else ""
        lines.append(f"  {tid}: localised after {info['after_s']:.0f} s at "
                     f"({info['lat']:.6f}, {info['lon']:.6f}) +-{info['radius_m']:.0f} m{err}")
    for tid, info in sorted(result.unresolved.items()):
        err = f", error {info['error_m']:.1f} m" if "error_m" in info else ""
        rep = result.reports.get(tid)
        why = (f"; reported {rep['reason']} after {rep['after_s']:.0f} s at "
               f"+-{rep['radius_m']:.0f} m") if rep else ""
        lines.append(f"  {tid}: not localised; last estimate ({info['lat']:.6f}, "
                     f"{info['lon']:.6f}) +-{info['radius_m']:.0f} m (95 %){err}{why}")
    if result.rejects:
        lines.append("  radio rejects: " + ", ".join(f"{k}={v}" for k, v in result.rejects.items()))
    lines.append(f"  log: {result.log_dir}")
    return "\n".join(lines)
