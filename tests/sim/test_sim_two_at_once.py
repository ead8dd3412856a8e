"""Two simulators at once, on different ports and system ids, do not interfere."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from mexgen_gcs.io.wire import Heartbeat, decode
from tests.sim.mav_helpers import M, client_port, command, open_client, wait_for
from tests.sim.sim_helpers import SimFactory, udp_socket, write_mission


def radio_listening(sock: Any, seconds: float) -> set[tuple[str, ...]]:
    seen: set[tuple[str, ...]] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            event = decode(sock.recvfrom(2048)[0])
        except TimeoutError:
            continue
        if isinstance(event, Heartbeat):
            assert event.listening is not None
            seen.add(event.listening)
    return seen


def test_two_simulators_do_not_interfere(sim_factory: SimFactory, tmp_path: Path) -> None:
    other = write_mission(tmp_path / "other.yaml", tags=[{"id": "X9", "freq_hz": 151_000_000}],
                          sim_tags=[{"id": "X9", "position_m": "[10.0, 20.0]"}])
    a, b = open_client(), open_client()
    ra, rb = udp_socket(0.2), udp_socket(0.2)
    try:
        sim_a = sim_factory(mavlink_port=client_port(a), radio_port=ra.getsockname()[1],
                            sysid=1, speedup=2.0)
        sim_b = sim_factory(other, mavlink_port=client_port(b), radio_port=rb.getsockname()[1],
                            sysid=2, speedup=2.0)
        assert sim_a.listen_port != sim_b.listen_port
        for conn, sysid in ((a, 1), (b, 2)):
            conn.wait_heartbeat(timeout=10)
            assert conn.target_system == sysid
        # Arming one leaves the other alone; each hears only its own vehicle.
        assert command(a, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, sysid=1) == M.MAV_RESULT_ACCEPTED
        # A command for system 1 sent to vehicle 2 is not its business: no answer.
        b.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert b.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0) is None
        wait_for(a, "HEARTBEAT", lambda m: m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 3.0)
        for _ in range(3):
            hb = wait_for(b, "HEARTBEAT")
            assert hb.get_srcSystem() == 2
            assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            msg = wait_for(a, "GLOBAL_POSITION_INT")
            assert msg.get_srcSystem() == 1
        assert radio_listening(ra, 1.0) == {("T1", "T2", "T3", "T4")}
        assert radio_listening(rb, 1.0) == {("X9",)}
    finally:
        for sock in (a, b, ra, rb):
            sock.close()
