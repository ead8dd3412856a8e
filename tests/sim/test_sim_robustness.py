"""Malformed or unexpected MAVLink input never crashes the simulator or breaks its answers.

Garbage bytes, corrupted packets, unknown message ids, other dialects, MAVLink 1, commands
with NaN/inf/out-of-range parameters, setpoints full of NaN, hostile parameter names, stray
mission items: the vehicle keeps answering, acks unsupported commands with UNSUPPORTED and
out-of-range ones with DENIED, and ends with zero internal errors in its truth log.
"""

from __future__ import annotations

import contextlib
import math
import random
import struct
import time
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v10 import common as mavlink1
from pymavlink.dialects.v20 import ardupilotmega

from mexgen_gcs.io.truthfile import read_truth_file
from tests.sim.mav_helpers import command, start, wait_for
from tests.sim.sim_helpers import SimFactory

M = mavutil.mavlink
WILD_FLOATS = [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e38, -1e38, 1.0, 21196.0, 129.0,
               4.0, 6.0, 0.5, 3.4e38]


def send_raw(conn: Any, port: int, data: bytes) -> None:
    conn.port.sendto(data, ("127.0.0.1", port))


def test_unsupported_and_out_of_range_commands(sim_factory: SimFactory, client: Any) -> None:
    start(sim_factory, client, extra=["--keep-running"])
    for unsupported in (M.MAV_CMD_DO_FLIGHTTERMINATION, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
                        M.MAV_CMD_DO_SET_SERVO, 31999, 65535):
        assert command(client, unsupported, 1) == M.MAV_RESULT_UNSUPPORTED
    denied = [
        (M.MAV_CMD_COMPONENT_ARM_DISARM, (2.0,)),
        (M.MAV_CMD_COMPONENT_ARM_DISARM, (math.nan,)),
        (M.MAV_CMD_DO_SET_MODE, (129.0, 99.0, 0.0)),
        (M.MAV_CMD_DO_SET_MODE, (129.0, 4.0, 77.0)),
        (M.MAV_CMD_DO_SET_MODE, (0.0, 4.0, 3.0)),
        (M.MAV_CMD_DO_SET_MODE, (129.0, math.inf, 0.0)),
        (M.MAV_CMD_DO_SET_MODE, (129.0, 4.0, 4.0)),  # MISSION: nothing uploaded
        (M.MAV_CMD_DO_SET_MODE, (129.0, 1.0, 0.0)),  # MANUAL: no RC
        (M.MAV_CMD_REQUEST_MESSAGE, (99999.0,)),
        (M.MAV_CMD_REQUEST_MESSAGE, (-5.0,)),
        (M.MAV_CMD_SET_MESSAGE_INTERVAL, (math.nan, 1e5)),
        (M.MAV_CMD_SET_MESSAGE_INTERVAL, (float(M.MAVLINK_MSG_ID_HEARTBEAT), -1.0)),
        (M.MAV_CMD_DO_CHANGE_SPEED, (1.0, 1e9)),
        (M.MAV_CMD_DO_REPOSITION, (-1.0, 0.0, 0.0, math.nan, 95.0, 10.0, 50.0)),
        (M.MAV_CMD_NAV_TAKEOFF, (0.0,) * 6 + (1e9,)),
        (M.MAV_CMD_NAV_TAKEOFF, (math.nan,) * 7),  # disarmed
        (M.MAV_CMD_NAV_RETURN_TO_LAUNCH, ()),  # disarmed
    ]
    for cmd, params in denied:
        assert command(client, cmd, *params) == M.MAV_RESULT_DENIED, (cmd, params)
    # Offboard without setpoints is refused for now (retrying with setpoints works).
    assert command(client, M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == \
        M.MAV_RESULT_TEMPORARILY_REJECTED
    # Commands for another system or component are not answered.
    client.mav.command_long_send(42, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    client.mav.command_long_send(1, 100, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert client.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0) is None


def test_garbage_and_hostile_messages(sim_factory: SimFactory, client: Any) -> None:
    sim = start(sim_factory, client, speedup=5.0, extra=["--keep-running"])
    port = sim.listen_port
    rng = random.Random(1234)
    mav = client.mav
    # 1. Raw garbage, including bytes that look like MAVLink start markers.
    for _ in range(300):
        n = rng.choice([0, 1, 2, 5, 12, 40, 280, 1500, 8000])
        blob = bytes(rng.getrandbits(8) for _ in range(n))
        if n and rng.random() < 0.5:
            blob = bytes([rng.choice([0xFD, 0xFE])]) + blob
        send_raw(client, port, blob)
    time.sleep(0.3)  # let the simulator drain its socket between floods
    # 2. Valid packets, corrupted: bit flips, truncation, doubled, length lies.
    good = mav.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
                                   ).pack(mav)
    for _ in range(300):
        b = bytearray(good)
        how = rng.randrange(4)
        if how == 0:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        elif how == 1:
            b = b[:rng.randrange(len(b))]
        elif how == 2:
            b = b + b
        else:
            b[1] = rng.randrange(256)
        send_raw(client, port, bytes(b))
    time.sleep(0.3)
    # 3. Unknown message ids, another dialect, MAVLink 1.
    apm = ardupilotmega.MAVLink(None, srcSystem=255, srcComponent=190)
    send_raw(client, port, apm.meminfo_encode(100, 200).pack(apm))
    send_raw(client, port, apm.ahrs_encode(1, 2, 3, 4, 5, 6, 7).pack(apm))
    header = struct.pack("<BBBBBBBHB", 0xFD, 4, 0, 0, 1, 255, 190, 0xFFFF, 0xFF)
    send_raw(client, port, header + b"\x01\x02\x03\x04" + b"\x00\x00")
    v1 = mavlink1.MAVLink(None, srcSystem=255, srcComponent=190)
    send_raw(client, port, v1.command_long_encode(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0).pack(v1))
    time.sleep(0.3)
    # 4. Well-formed messages with wild field values, aimed at every handler.
    for _ in range(400):
        f = [rng.choice(WILD_FLOATS) for _ in range(7)]
        kind = rng.randrange(8)
        if kind == 0:
            mav.command_long_send(1, 1, rng.randrange(65536), rng.randrange(256), *f)
        elif kind == 1:
            mav.command_int_send(1, 1, rng.randrange(20), rng.randrange(65536), 0, 0, *f[:4],
                                 rng.randrange(-2**31, 2**31), rng.randrange(-2**31, 2**31),
                                 f[6])
        elif kind == 2:
            mav.set_position_target_local_ned_send(
                0, 1, 1, rng.randrange(30), rng.randrange(65536), *f[:6], *f[:3], f[3], f[4])
        elif kind == 3:
            mav.set_position_target_global_int_send(
                0, 1, 1, rng.randrange(30), rng.randrange(65536), rng.randrange(-2**31, 2**31),
                rng.randrange(-2**31, 2**31), *f[:7], f[0], f[1])
        elif kind == 4:
            name = bytes(rng.getrandbits(8) for _ in range(rng.randrange(17)))
            mav.param_set_send(1, 1, name, f[0], rng.randrange(12))
        elif kind == 5:
            mav.param_request_read_send(1, 1, b"MIS_TAKEOFF_ALT", rng.randrange(-1, 32767))
        elif kind == 6:
            mav.mission_count_send(1, 1, rng.randrange(65536), rng.choice([0, 1, 2, 255, 7]))
        else:
            mav.mission_item_int_send(
                1, 1, rng.randrange(65536), rng.randrange(20), rng.randrange(65536), 0, 1,
                *f[:4], rng.randrange(-2**31, 2**31), rng.randrange(-2**31, 2**31), f[4],
                rng.choice([0, 1, 2]))
    # Still alive and answering: heartbeats flow and a plain command is acked. (Drain the
    # replies to the flood first: a full receive buffer would drop the answer.)
    time.sleep(1.0)
    with contextlib.suppress(BlockingIOError):
        while True:
            client.port.recvfrom(65536)  # mavutil's socket is non-blocking
    wait_for(client, "HEARTBEAT", timeout_s=5.0)
    assert command(client, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) == \
        M.MAV_RESULT_ACCEPTED
    assert sim.alive()
    assert sim.stop() == 0
    end = read_truth_file(sim.truth_path).records[-1]
    assert end["type"] == "end"
    stats = end["mavlink"]
    assert stats["errors"] == 0, sim.stderr_lines
    assert stats["rx_bad"] > 100 and stats["rx_unknown"] >= 2
    assert not any("Traceback" in line for line in sim.stderr_lines)


@pytest.mark.e2e  # simulator processes (that exit at once)
@pytest.mark.parametrize("bad_args", [
    ["--speedup", "0"], ["--sysid", "300"], ["--mavlink", "nonsense"],
    ["--fault", "meteor,at_s=3"], ["--fault", "link_drop,duration_s=3"],
])
def test_bad_flags_exit_2(bad_args: list[str]) -> None:
    import subprocess
    import sys

    from tests.sim.sim_helpers import DEMO_MISSION, REPO

    done = subprocess.run([sys.executable, "-m", "sim", str(DEMO_MISSION), *bad_args],
                          cwd=REPO, capture_output=True, text=True, timeout=30)
    assert done.returncode == 2
    assert "error" in done.stderr


@pytest.mark.e2e
def test_bad_mission_exits_2(tmp_path: Any) -> None:
    import subprocess
    import sys

    from tests.sim.sim_helpers import REPO

    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\nname: x\n")
    done = subprocess.run([sys.executable, "-m", "sim", str(bad)], cwd=REPO,
                          capture_output=True, text=True, timeout=30)
    assert done.returncode == 2 and "sim:" in done.stderr
