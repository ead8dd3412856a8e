"""Radios riding on a MAVLink vehicle (``--radios-only --vehicle URL``).

Parts in-process (URL parsing, pose interpolation, the vehicle clock); then two real processes
on loopback UDP: the simulator's vehicle (``--no-radios --gcs``) and the radios riding on its
GCS stream, flown by a pymavlink client; the datagrams are checked against the vehicle's truth.
"""

from __future__ import annotations

import json
import math
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.config import load_mission
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.io.wire import Detection, decode
from sim.__main__ import main as sim_main
from sim.vehicle_link import PoseHistory, PoseSample, VehicleTrack, parse_vehicle_url
from tests.sim.mav_helpers import command, drain, start, wait_for
from tests.sim.sim_helpers import (
    DEMO_MISSION,
    SimFactory,
    free_udp_port,
    start_radios_only,
    udp_socket,
)

M = mavlink
_VELOCITY_MASK = 0b0000_1001_1100_0111


def test_vehicle_url() -> None:
    assert str(parse_vehicle_url("udpin:0.0.0.0:14550")) == "udpin:0.0.0.0:14550"
    out = parse_vehicle_url("udpout://127.0.0.1:18577")
    assert (out.mode, out.host, out.port) == ("udpout", "127.0.0.1", 18577)
    for bad in ("udp:1.2.3.4:5", "udpin:14550", "udpin:h:port", "udpout:h:0", "tcp:h:1"):
        with pytest.raises(ValueError, match="udpin:HOST:PORT"):
            parse_vehicle_url(bad)


@pytest.mark.parametrize("argv", [
    ["--radios-only"], ["--vehicle", "udpin:0.0.0.0:14550"],
    ["--radios-only", "--vehicle", "udpin:0.0.0.0:14550", "--no-radios"],
    ["--radios-only", "--vehicle", "serial:/dev/ttyUSB0"],
])
def test_bad_flags_exit_2(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        sim_main([str(DEMO_MISSION), *argv])
    assert exc.value.code == 2


def test_pose_history_interpolates_in_vehicle_time() -> None:
    h = PoseHistory(keep_s=10.0)
    assert h.at(1.0) is None
    assert h.add(PoseSample(1.0, -34.0, 138.0, 100.0, 50.0, 350.0))
    assert h.add(PoseSample(1.2, -34.0002, 138.0004, 102.0, 52.0, 10.0))
    assert not h.add(PoseSample(1.1, 0.0, 0.0, 0.0, 0.0, 0.0))  # out of order: ignored
    mid = h.at(1.05)
    assert mid is not None
    assert (mid.lat_deg, mid.lon_deg, mid.alt_m, mid.rel_alt_m) == pytest.approx(
        (-34.00005, 138.0001, 100.5, 50.5))
    assert mid.yaw_deg == pytest.approx(355.0)  # across north, not through south
    assert h.at(1.25) is not None and h.at(1.5) is None and h.at(0.5) is None
    h.add(PoseSample(5.0, -34.0, 138.0, 100.0, 50.0, 0.0))
    assert h.at(3.0) is None  # a 3.8 s gap is not interpolated
    h.add(PoseSample(20.0, -34.0, 138.0, 100.0, 50.0, 0.0))
    assert len(h) == 1  # older than keep_s dropped


def test_vehicle_track_clock_and_state() -> None:
    mav = M.MAVLink(None, srcSystem=3, srcComponent=1)
    gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
    track = VehicleTrack()

    def feed(link: Any, msg: Any) -> None:
        for m in M.MAVLink(None).parse_buffer(msg.pack(link)) or []:
            track.handle(m)

    feed(gcs, gcs.heartbeat_encode(6, 8, 0, 0, 4))  # a GCS is not the vehicle
    assert track.sysid is None
    feed(mav, mav.heartbeat_encode(2, 12, 128 | 1, 0, 4))
    assert track.sysid == 3 and track.armed
    feed(mav, mav.system_time_encode(0, 1000))  # unix not set yet: ignored
    assert track.offset_s is None
    # SITL at speed factor 4: SYSTEM_TIME's unix runs 1x (the host's), boot time 4x.
    for k in range(3):
        feed(mav, mav.system_time_encode(int(1.7e15 + k * 1e6), 10_000 + k * 4000))
    assert track.offset_s is None  # 3 samples over 2 s are not enough to fit
    feed(mav, mav.system_time_encode(int(1.7e15 + 3e6), 22_000))
    assert track.offset_s is None
    feed(mav, mav.system_time_encode(int(1.7e15 + 4e6), 26_000))
    # The vehicle's clock read 0 at unix 1.7e9 - 2.5: whoever listens, from whichever sample.
    assert track.offset_s == pytest.approx(1.7e9 - 2.5) and track.rate == pytest.approx(4.0)
    assert track.unix_of(14.0) == pytest.approx(1.7e9 + 11.5)  # linear in vehicle time
    late = VehicleTrack(3)
    for unix_us, boot_ms in ((1.7e15 + 30e6 + k * 1e6, 130_000 + k * 4000) for k in range(5)):
        for m in M.MAVLink(None).parse_buffer(
                mav.system_time_encode(int(unix_us), boot_ms).pack(mav)) or []:
            late.handle(m)
    assert late.offset_s == pytest.approx(track.offset_s)  # the same anchor 30 s later
    feed(mav, mav.global_position_int_encode(15_000, -349212000, 1386011000, 70_000, 50_000,
                                             0, 0, 0, 9000))
    assert track.has_flown and track.poses.latest_s == 15.0
    feed(mav, mav.heartbeat_encode(2, 12, 1, 0, 3))
    feed(mav, mav.extended_sys_state_encode(0, 1))
    assert track.landed_and_disarmed


def _receive_all(sock: socket.socket, until: Any, timeout_s: float) -> list[tuple[float, Any]]:
    """Datagrams (arrival monotonic time, decoded) until ``until()`` or the timeout."""
    out = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not until():
        try:
            data = sock.recv(2048)
        except TimeoutError:
            continue
        out.append((time.monotonic(), decode(data)))
    return out


def _interp_truth(vehicle: list[dict[str, Any]], t: float, key: str) -> float:
    ts = [r["t"] for r in vehicle]
    return float(np.interp(t, ts, [r[key] for r in vehicle]))


@pytest.mark.parametrize("clock", [[], ["--system-time", "host", "--clock-rate-error", "-0.02"]],
                         ids=["aircraft_clock", "px4_sitl_clock"])
def test_radios_ride_on_the_simulators_vehicle(sim_factory: SimFactory, client: Any,
                                               tmp_path: Path, clock: list[str]) -> None:
    """With PX4 SITL's clocks too (SYSTEM_TIME unix = host clock, sim time at 0.98 K): the
    radios still find the vehicle clock's unix origin, the simulator's start_unix."""
    speedup = 5.0
    gcs_port = free_udp_port()
    radio = udp_socket(timeout_s=0.2)
    sim = start(sim_factory, client, speedup=speedup,
                extra=["--no-radios", "--gcs", f"127.0.0.1:{gcs_port}", *clock])
    rider = start_radios_only(DEMO_MISSION, tmp_path / "rider",
                              vehicle=f"udpin:127.0.0.1:{gcs_port}",
                              radio_port=radio.getsockname()[1])
    try:
        drain(client)  # unread while the radios started: a full socket drops the answer
        client.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 20.0, M.MAV_PARAM_TYPE_REAL32)
        wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
        assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        assert command(client, M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
        early = _receive_all(radio, lambda: False, 20.0 / speedup)
        t_leg = time.monotonic()

        def east() -> None:
            client.mav.set_position_target_local_ned_send(
                0, 1, 1, M.MAV_FRAME_LOCAL_NED, _VELOCITY_MASK, 0, 0, 0, 2.0, 8.0, 0.0, 0, 0, 0,
                math.radians(75.0), 0)

        east()
        assert command(client, M.MAV_CMD_DO_SET_MODE, 129, 6) == M.MAV_RESULT_ACCEPTED
        leg = []
        while time.monotonic() - t_leg < 15.0 / speedup:
            east()
            leg += _receive_all(radio, lambda: False, 0.05)
        assert command(client, M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_ACCEPTED
        rest = _receive_all(radio, lambda: not rider.alive(), 120.0 / speedup + 20.0)
        # Flown, landed, disarmed: both processes end by themselves, cleanly.
        assert rider.wait_exit(10.0) == 0
        assert sim.wait_exit(10.0) == 0
    finally:
        rider.stop()
        radio.close()

    got = [d for _, d in early + leg + rest]
    detections = [d for d in got if isinstance(d, Detection) and d.lat is not None]
    assert len(detections) > 20
    for path in (sim.truth_path, rider.truth_dir / "truth.jsonl"):  # records as documented
        assert not read_truth_file(path).damage, read_truth_file(path).damage.describe()
    sim_truth = read_truth_file(sim.truth_path).records
    rider_truth = read_truth_file(rider.truth_dir / "truth.jsonl").records
    header = rider_truth[0]
    assert header["type"] == "sim" and header["mode"] == "radios-only"
    assert header["clock"]["source"] == "SYSTEM_TIME" and header["vehicle_sysid"] == 1
    # Same seed, same world: the tags the riding radios simulate are the simulator's.
    assert header["tags"] == sim_truth[0]["tags"]
    # On the vehicle's clock: the simulator's unix time of sim time (its SYSTEM_TIME).
    assert header["clock"]["offset_s"] == pytest.approx(sim_truth[0]["start_unix"], abs=0.02)
    assert header["clock"]["rate"] == pytest.approx(1.0 if not clock else 4.9, abs=0.05)
    vehicle = [r for r in sim_truth if r["type"] == "vehicle"]
    t0, t1 = vehicle[0]["t"], vehicle[-1]["t"]
    assert all(t0 <= d.t <= t1 + 2.0 for d in detections)
    frame = load_mission(DEMO_MISSION).local_frame()
    errors = []
    for d in detections:
        e, n, _ = frame.to_enu(d.lat, d.lon, frame.alt0_m)
        de = float(e) - _interp_truth(vehicle, d.t, "east_m")
        dn = float(n) - _interp_truth(vehicle, d.t, "north_m")
        errors.append(math.hypot(de, dn))
        up = d.alt_m - frame.alt0_m
        assert up == pytest.approx(_interp_truth(vehicle, d.t, "up_m"), abs=1.5)
    # Measured 0.27 m (95th percentile) against 1 Hz truth interpolated linearly.
    assert np.percentile(errors, 95) < 1.0, sorted(errors)[-5:]
    moving = [d for d in detections if d.yaw_deg is not None
              and _interp_truth(vehicle, d.t, "v_east_m_s") > 7.5]
    assert moving and all(d.yaw_deg == pytest.approx(75.0, abs=2.0) for d in moving)
    pulses = [r for r in rider_truth if r["type"] == "pulse" and r["sent"]]
    assert {round(p["t_sent"], 6) for p in pulses} >= {round(d.t, 6) for d in detections}
    end = rider_truth[-1]
    assert end["type"] == "end" and end["reason"] == "landed"
    assert end["mavlink"]["pose_gaps"] == 0
    print(json.dumps({"detections": len(detections), "p95_pose_error_m":
                      float(np.percentile(errors, 95))}))
