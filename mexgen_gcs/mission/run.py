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
import copy
import logging
import math
import os
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
from mexgen_gcs.core.mission_core import MissionCore
from mexgen_gcs.errors import ConfigError, LogFormatError, MexgenError
from mexgen_gcs.io.clock import Clock, VehicleClock
from mexgen_gcs.io.flightlog import FlightLogWriter
from mexgen_gcs.io.radio_udp import RadioPolicy, RadioReceiver
from mexgen_gcs.io.truthfile import TRUTH_FILE, TagPositions, read_truth_file
from mexgen_gcs.io.vehicle import MavsdkVehicle
from mexgen_gcs.mission.controller import ControllerOptions, MissionController, MissionResult

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


def free_udp_port() -> int:
    """A UDP port on loopback that was free a moment ago, outside the ephemeral range."""
    for _ in range(500):
        port = int(_PORT_RNG.integers(*_FREE_PORTS))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise OSError(f"no free UDP port on loopback in {_FREE_PORTS[0]}-{_FREE_PORTS[1]}")


def apply_overrides(mission: Any, overrides: Mapping[str, Any] | None) -> Any:
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


def make_log_dir(base: str | os.PathLike[str], mission: Any, method: str, seed: int) -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
    d = Path(base) / f"{stamp}-{mission.name}-{method}-s{seed}"
    n = 1
    while d.exists():
        d = Path(base) / f"{stamp}-{mission.name}-{method}-s{seed}-{n}"
        n += 1
    d.mkdir(parents=True)
    return d


def build_core(mission: Any, rng: np.random.Generator) -> MissionCore:
    return MissionCore(
        mission.tag_ids, mission.filter_motion_model(), mission.radio_model(),
        mission.search_area(), mission.filter_config(), rng, kind=mission.kind,
        target_rule=mission.planner.target,
        follow_tag=mission.follow.tag if mission.follow is not None else None,
        planning_particles=mission.planner.n_particles, tag_priors=mission.tag_radio_priors(),
        report_rule=mission.report_rule())


async def fly_mission(
    mission: Any,
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
) -> MissionResult:
    """Fly one mission with real ports. The caller owns any simulator process. ``runner``
    flies the controller with something attached (the terminal UI); default: headless."""
    rng = np.random.default_rng(seed)
    core = build_core(mission, rng.spawn(1)[0])
    policy = RadioPolicy.from_mission(mission, clock=clock.now)
    with FlightLogWriter(log_dir, mission=mission, seed=seed, method=method,
                         clock=clock.now) as flight_log:
        async with RadioReceiver(radio_url, policy) as receiver:
            vehicle = MavsdkVehicle()
            truth = TagPositions(truth_path) if truth_path is not None else None
            controller = MissionController(
                mission, vehicle, receiver, clock, core, flight_log, method=method,
                rng=rng.spawn(1)[0], connect_url=connect_url, options=options,
                truth=truth.positions if truth is not None else None)
            signals = _abort_on_signals(controller)
            try:
                if runner is not None:
                    result = await runner(controller)
                else:
                    result = await controller.run()
            finally:
                for sig in signals:
                    asyncio.get_running_loop().remove_signal_handler(sig)
                await vehicle.close()
            result.log_dir = str(log_dir)
    return result


def _abort_on_signals(controller: MissionController) -> list[signal.Signals]:
    """SIGINT is the operator's abort; SIGHUP (the terminal is gone) and SIGTERM ask the
    mission to end too: the vehicle returns and lands, then the program exits. Only possible
    in the main thread on POSIX; elsewhere (flights in worker threads) none are set."""
    if sys.platform == "win32" or threading.current_thread() is not threading.main_thread():
        return []
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGINT, controller.request, "abort")
    loop.add_signal_handler(signal.SIGTERM, controller.request, "signal:SIGTERM")
    loop.add_signal_handler(signal.SIGHUP, controller.request, "signal:SIGHUP")
    return [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


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
    deadline = time.monotonic() + ready_timeout_s
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if line.startswith("sim ready"):
            return proc
    stop_simulator(proc)
    raise MexgenError(f"the simulator did not start within {ready_timeout_s:.0f} s; "
                      f"see {truth_dir / 'sim.log'}")


def stop_simulator(proc: subprocess.Popen[str], wait_s: float = 20.0) -> int | None:
    """Let the simulator finish on its own (it exits once landed), else SIGTERM, else kill."""
    try:
        return proc.wait(timeout=wait_s)
    except subprocess.TimeoutExpired:
        proc.terminate()
    try:
        return proc.wait(timeout=10.0)
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
) -> MissionResult:
    """Fly a mission against the built-in simulator; the scripted-SITL API.

    ``mission``: a path or a loaded Mission. ``overrides``: dotted keys, e.g.
    ``{"planner.method": "pim", "sim.seed": 3}``. ``ports``: defaults to the contract ports;
    ``SitlPorts.free()`` for parallel runs. The mission runs on the simulator's clock, measured
    from its SYSTEM_TIME (``time_scale``: a known rate instead). Raises ConfigError on a bad
    mission (nothing is started).
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
    proc = start_simulator(resolved, seed=seed, speedup=speedup, ports=ports, truth_dir=out,
                           extra_args=sim_args)
    clock: Clock = VehicleClock(fixed_rate=time_scale)
    try:
        result = asyncio.run(fly_mission(
            m, connect_url=f"udpin://127.0.0.1:{ports.mavlink}",
            radio_url=f"udp://127.0.0.1:{ports.radio}", clock=clock, log_dir=out,
            method=chosen, seed=seed, options=options, truth_path=out / TRUTH_FILE, runner=runner))
    finally:
        code = stop_simulator(proc)
        log.info("simulator exited with %s", code)
    attach_truth_errors(result, out / TRUTH_FILE, m)
    return result


def attach_truth_errors(result: MissionResult, truth_path: Path, mission: Any) -> None:
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
