"""The vehicle link as a `.tlog` beside flight.jsonl: a short sitl flight's tlog opens with
pymavlink's log reader and holds the vehicle's HEARTBEAT and GLOBAL_POSITION_INT and our
SET_POSITION_TARGET_LOCAL_NED setpoints, in timestamp order; the frame splitter and the tap's
relay in both URL directions, on real UDP sockets."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.io.mavlink_tap import TLOG_FILE, MavlinkTap, split_frames
from mexgen_gcs.mission.run import SitlPorts, run_sitl

MISSIONS = Path(__file__).parents[2] / "missions"


def _messages(path: Path) -> list[object]:
    reader = mavutil.mavlink_connection(str(path))
    out = []
    while (msg := reader.recv_match()) is not None:
        out.append(msg)
    reader.close()
    return out


def _encoded(n: int) -> list[bytes]:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return [mav.heartbeat_encode(2, 12, 0, i, 4).pack(mav) for i in range(n)]


def test_split_frames_keeps_whole_messages_and_counts_junk() -> None:
    frames = _encoded(3)
    found, junk = split_frames(b"\x00\x01" + b"".join(frames) + frames[0][:5])
    assert found == frames and junk == 2 + 5


@pytest.mark.parametrize("direction", ["udpin", "udpout"])
def test_the_tap_relays_both_ways_and_logs(tmp_path: Path, direction: str) -> None:
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.settimeout(2.0)
    frames = _encoded(4)
    if direction == "udpin":  # the vehicle sends to the tap's listening port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        tap = MavlinkTap(f"udpin://127.0.0.1:{port}", tmp_path / TLOG_FILE)
        gcs.bind(("127.0.0.1", int(tap.gcs_url.rsplit(":", 1)[1])))
        vehicle.sendto(frames[0], ("127.0.0.1", port))
        assert gcs.recvfrom(2048)[0] == frames[0]
        gcs.sendto(frames[1], tap._gcs_sock.getsockname())
        assert vehicle.recvfrom(2048)[0] == frames[1]
    else:  # the tap talks first to the vehicle once MAVSDK (here: gcs) spoke to it
        tap = MavlinkTap(f"udpout://127.0.0.1:{vehicle.getsockname()[1]}", tmp_path / TLOG_FILE)
        gcs.bind(("127.0.0.1", 0))
        gcs.sendto(frames[0], ("127.0.0.1", int(tap.gcs_url.rsplit(":", 1)[1])))
        data, tap_addr = vehicle.recvfrom(2048)
        assert data == frames[0]
        vehicle.sendto(frames[1], tap_addr)
        assert gcs.recvfrom(2048)[0] == frames[1]
    time.sleep(0.1)
    tap.close()
    vehicle.close()
    gcs.close()
    msgs = _messages(tmp_path / TLOG_FILE)
    assert [m.custom_mode for m in msgs] == [0, 1]
    assert tap.stats.messages_logged == 2 and tap.stats.write_errors == 0


@pytest.mark.e2e
def test_a_sitl_flights_tlog_reads_with_pymavlink(tmp_path: Path) -> None:
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=10.0, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides={"safety.max_mission_time_s": 60.0})
    tlog = Path(result.log_dir) / TLOG_FILE
    msgs = _messages(tlog)
    kinds = [m.get_type() for m in msgs]
    for kind in ("HEARTBEAT", "GLOBAL_POSITION_INT", "SET_POSITION_TARGET_LOCAL_NED",
                 "SYSTEM_TIME", "COMMAND_LONG", "COMMAND_ACK"):
        assert kind in kinds, kind
    stamps = [m._timestamp for m in msgs]
    assert stamps == sorted(stamps)
    t0 = tlog.stat().st_mtime
    assert t0 - 3600 < stamps[0] <= stamps[-1] <= t0 + 1  # unix seconds, this flight
    setpoints = [m for m in msgs if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert {m.get_srcSystem() for m in setpoints} == {245}  # MAVSDK's GCS system id
    assert len(setpoints) > 100
    positions = [m for m in msgs if m.get_type() == "GLOBAL_POSITION_INT"
                 and m.get_srcSystem() == 1]
    assert max(m.relative_alt for m in positions) > 40_000  # mm: the mission's 50 m
    # analyze reads it for the vehicle's own view
    from mexgen_gcs.analysis.flightdata import load_flight
    from mexgen_gcs.analysis.report import write_report

    report = write_report(load_flight(result.log_dir), tmp_path / "report")
    text = report.markdown.read_text()
    assert "## The vehicle's own view (vehicle.tlog)" in text
    assert "245/190 (GCS, INVALID)" in text and "1/1 (QUADROTOR, PX4)" in text
    link = json.loads(report.summary_json.read_text())["vehicle_link"]
    modes = [m for _, m, _ in link["modes"]]
    assert modes.index("TAKEOFF") < modes.index("OFFBOARD") < modes.index("RTL")
    assert link["positions"] == len(positions)


def test_a_torn_tlog_is_read_as_far_as_it_goes(tmp_path: Path) -> None:
    import struct

    from mexgen_gcs.analysis.vehicle_link import read_vehicle_link

    frames = _encoded(3)
    path = tmp_path / TLOG_FILE
    path.write_bytes(b"".join(struct.pack(">Q", int((1.8e9 + i) * 1e6)) + f
                             for i, f in enumerate(frames)) + struct.pack(">Q", 1) + b"\xfd\x09")
    link = read_vehicle_link(path)
    assert link.messages == 3 and link.duration_s == pytest.approx(2.0)
    assert link.systems == {"1/1": "QUADROTOR, PX4"}
    assert [m for _, m, _ in link.modes] and link.modes[0][0] == 0.0


def test_a_taken_port_is_an_error_naming_it(tmp_path: Path) -> None:
    from mexgen_gcs.errors import VehicleError
    from mexgen_gcs.io.vehicle import MavsdkVehicle

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", 0))
        url = f"udpin://127.0.0.1:{holder.getsockname()[1]}"
        vehicle = MavsdkVehicle(tlog_path=tmp_path / TLOG_FILE)
        with pytest.raises(VehicleError, match="Address already in use"):
            asyncio.run(vehicle.connect(url, 1.0))
        asyncio.run(vehicle.close())
