"""pymavlink (mavutil) client helpers for the simulator tests."""

from __future__ import annotations

import time
from typing import Any

from pymavlink import mavutil

from tests.sim.sim_helpers import SimFactory, SimProcess

mavutil.set_dialect("common")  # MAVLink 2: sim_helpers sets MAVLINK20=1, read here
M = mavutil.mavlink


def open_client() -> Any:
    """A mavutil UDP client listening on a free port of 127.0.0.1 (port 0 = any)."""
    return mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255,
                                      source_component=190)


def client_port(conn: Any) -> int:
    return int(conn.port.getsockname()[1])


def wait_for(conn: Any, kind: str, predicate: Any = None, timeout_s: float = 10.0) -> Any:
    """The next message of this type satisfying predicate, or fail after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type=kind, blocking=True, timeout=0.5)
        if msg is not None and (predicate is None or predicate(msg)):
            return msg
    raise AssertionError(f"no {kind} within {timeout_s} s")


def drain(conn: Any) -> None:
    """Read and drop what is waiting: a socket left unread fills up and drops new datagrams."""
    while conn.recv_match(blocking=False) is not None:
        pass


def command(conn: Any, cmd: int, *params: float, sysid: int = 1) -> int:
    """Send a COMMAND_LONG and return its COMMAND_ACK result (after draining the backlog,
    which cannot hold the answer yet and would make the kernel drop it)."""
    drain(conn)
    p = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(sysid, 1, cmd, 0, *p)
    return int(wait_for(conn, "COMMAND_ACK", lambda m: m.command == cmd).result)


def start(sim_factory: SimFactory, conn: Any, **kw: Any) -> SimProcess:
    """Start a simulator sending to this client and wait for its first heartbeat."""
    sim = sim_factory(mavlink_port=client_port(conn), **kw)
    conn.wait_heartbeat(timeout=10)
    return sim
