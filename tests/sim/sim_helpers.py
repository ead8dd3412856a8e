"""Helpers for the simulator tests: free ports, mission files, the simulator subprocess.

Imported by the tests as ``tests.sim.sim_helpers`` (the test folders are packages).
Ports: a test may bind its own receiving sockets on port 0 and pass their ports in (no race);
for MAVSDK, which binds itself, ``free_udp_port()`` picks one.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from mexgen_gcs.mission.run import free_udp_port as run_free_udp_port

# pymavlink's mavutil picks MAVLink 1 or 2 from this variable when it is imported (or when
# mavutil.set_dialect is called); the simulator speaks MAVLink 2.
os.environ["MAVLINK20"] = "1"

REPO = Path(__file__).resolve().parents[2]
DEMO_MISSION = REPO / "missions" / "demo.yaml"
READY_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 15.0


def free_udp_port() -> int:
    """A UDP port that was free a moment ago (for clients that must bind it themselves),
    outside the kernel's ephemeral range (:func:`mexgen_gcs.mission.run.free_udp_port`)."""
    return run_free_udp_port()


def udp_socket(timeout_s: float = 0.5) -> socket.socket:
    """A receiving socket bound to a free port on 127.0.0.1."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(timeout_s)
    return s


@dataclass
class SimProcess:
    """A running simulator. ``listen_port`` is where it receives MAVLink."""

    proc: subprocess.Popen[str]
    mavlink_port: int
    radio_port: int
    truth_dir: Path
    sysid: int
    ready_line: str = ""
    listen_port: int = 0
    stderr_lines: list[str] = field(default_factory=list)

    @property
    def truth_path(self) -> Path:
        return self.truth_dir / "truth.jsonl"

    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait_exit(self, timeout_s: float) -> int:
        return self.proc.wait(timeout=timeout_s)

    def stop(self) -> int:
        """SIGTERM and wait; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise


class SimFactory(Protocol):
    def __call__(self, mission: Path = ..., *, mavlink_port: int | None = ...,
                 radio_port: int | None = ..., speedup: float = ..., sysid: int = ...,
                 extra: list[str] | None = ...) -> SimProcess: ...


def _pump(stream: Any, lines: queue.Queue[str], keep: list[str] | None) -> None:
    for line in stream:
        lines.put(line)
        if keep is not None:
            keep.append(line)


def start_sim(mission: Path, truth_dir: Path, *, mavlink_port: int, radio_port: int,
              speedup: float = 1.0, sysid: int = 1, extra: list[str] | None = None
              ) -> SimProcess:
    cmd = [sys.executable, "-m", "sim", str(mission), "--speedup", str(speedup),
           "--mavlink", f"127.0.0.1:{mavlink_port}", "--radio", f"127.0.0.1:{radio_port}",
           "--listen", "127.0.0.1:0", "--truth-dir", str(truth_dir), "--sysid", str(sysid),
           *(extra or [])]
    return _launch(cmd, lambda proc: SimProcess(proc, mavlink_port, radio_port, truth_dir, sysid))


def start_radios_only(mission: Path, truth_dir: Path, *, vehicle: str, radio_port: int,
                      extra: list[str] | None = None) -> SimProcess:
    """``python -m sim MISSION --radios-only --vehicle URL``; ``listen_port`` = its socket."""
    cmd = [sys.executable, "-m", "sim", str(mission), "--radios-only", "--vehicle", vehicle,
           "--radio", f"127.0.0.1:{radio_port}", "--truth-dir", str(truth_dir),
           *(extra or [])]
    return _launch(cmd, lambda proc: SimProcess(proc, 0, radio_port, truth_dir, 0))


def _launch(cmd: list[str], make: Callable[[subprocess.Popen[str]], SimProcess]) -> SimProcess:
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=os.environ | {"PYTHONUNBUFFERED": "1"})
    sim = make(proc)
    out: queue.Queue[str] = queue.Queue()
    err: queue.Queue[str] = queue.Queue()
    threading.Thread(target=_pump, args=(proc.stdout, out, None), daemon=True).start()
    threading.Thread(target=_pump, args=(proc.stderr, err, sim.stderr_lines),
                     daemon=True).start()
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            line = out.get(timeout=0.2)
        except queue.Empty:
            if proc.poll() is not None:
                break
            continue
        if line.startswith("sim ready"):
            sim.ready_line = line.strip()
            fields = dict(p.split("=", 1) for p in sim.ready_line.split() if "=" in p)
            sim.listen_port = int(fields["listen"].rsplit(":", 1)[1])
            return sim
    with contextlib.suppress(Exception):
        proc.kill()
    raise AssertionError(f"simulator did not become ready: {''.join(sim.stderr_lines)[-2000:]}")


def write_mission(path: Path, *, tags: list[dict[str, Any]], sim_tags: list[dict[str, Any]],
                  area: str = "{west_m: -1000, east_m: 1000, south_m: -500, north_m: 9000}",
                  radio: str = "", faults: str = "[]", endurance_s: float = 1800.0,
                  reality: str = "matched") -> Path:
    """A small mission file in the brief's schema."""
    tag_lines = "\n".join(f"  - {{id: {t['id']}, freq_hz: {t['freq_hz']}}}" for t in tags)
    sim_lines = "\n".join(
        "    - {" + ", ".join(f"{k}: {v}" for k, v in t.items()) + "}" for t in sim_tags)
    text = f"""version: 1
name: simtest
kind: localise
home: {{lat_deg: -34.9212, lon_deg: 138.6011, alt_m: 20.0}}
area:
  rectangle_m: {area}
tags:
{tag_lines}
{radio}
sim:
  seed: 11
  reality: {reality}
  battery_endurance_s: {endurance_s}
  tags:
{sim_lines}
  faults: {faults}
"""
    path.write_text(text)
    return path
