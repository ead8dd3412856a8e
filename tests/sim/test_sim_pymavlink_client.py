"""A second MAVLink tool accepts the simulator: pymavlink's own mavutil client.

It sees heartbeats (PX4, quadrotor), position and mode changes, arms with a plain
COMMAND_LONG, reads and writes parameters, and uploads/downloads a geofence with the mission
protocol.
"""

from __future__ import annotations

import itertools
import math
import signal
import time
from typing import Any

import pytest
from pymavlink import mavutil

from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.io.truthfile import read_truth_file
from tests.sim.mav_helpers import command, start, wait_for
from tests.sim.sim_helpers import SimFactory, udp_socket

M = mavutil.mavlink


def test_heartbeat_position_modes_and_arming(sim_factory: SimFactory, client: Any) -> None:
    start(sim_factory, client, speedup=5.0)
    hb = wait_for(client, "HEARTBEAT")
    assert hb.autopilot == M.MAV_AUTOPILOT_PX4 and hb.type == M.MAV_TYPE_QUADROTOR
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert client.flightmode == "LOITER" and not client.motors_armed()

    pos = wait_for(client, "GLOBAL_POSITION_INT")
    assert pos.lat / 1e7 == pytest.approx(-34.9212, abs=1e-6)
    assert pos.lon / 1e7 == pytest.approx(138.6011, abs=1e-6)
    assert pos.relative_alt == 0
    wait_for(client, "SYS_STATUS", lambda m: m.onboard_control_sensors_health
             & M.MAV_SYS_STATUS_SENSOR_GPS and m.onboard_control_sensors_health
             & M.MAV_SYS_STATUS_PREARM_CHECK)

    client.set_mode("POSCTL")  # mavutil's own PX4 mode switch (DO_SET_MODE)
    assert wait_for(client, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: mavutil.interpret_px4_mode(
        m.base_mode, m.custom_mode) == "POSCTL", 3.0)
    assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 3.0)
    # PX4 custom mode AUTO/TAKEOFF through DO_SET_MODE climbs to MIS_TAKEOFF_ALT (2.5 m).
    assert command(client, M.MAV_CMD_DO_SET_MODE, 129, 4, 2) == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: mavutil.interpret_px4_mode(
        m.base_mode, m.custom_mode) == "TAKEOFF", 3.0)
    wait_for(client, "EXTENDED_SYS_STATE", lambda m: m.landed_state in (
        M.MAV_LANDED_STATE_TAKEOFF, M.MAV_LANDED_STATE_IN_AIR))
    wait_for(client, "HEARTBEAT", lambda m: mavutil.interpret_px4_mode(
        m.base_mode, m.custom_mode) == "LOITER", 20.0)
    local = wait_for(client, "LOCAL_POSITION_NED")
    assert local.z == pytest.approx(-2.5, abs=0.4)
    # Disarming in the air is refused; landing is accepted and ends disarmed.
    assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_DENIED
    assert command(client, M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 20.0)


def test_arming_refused_without_gps(sim_factory: SimFactory, client: Any) -> None:
    start(sim_factory, client, speedup=1.0, extra=["--fault", "gps_loss,at_s=0,duration_s=600"])
    wait_for(client, "GPS_RAW_INT", lambda m: m.fix_type < 2)
    sys_status = wait_for(client, "SYS_STATUS")
    assert not sys_status.onboard_control_sensors_health & M.MAV_SYS_STATUS_SENSOR_GPS
    assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
    # PX4's wording: the failing check, then the refusal (its tab marks a MAVLink event).
    assert wait_for(client, "STATUSTEXT", lambda m: "GPS" in m.text).text \
        == "Preflight Fail: GPS fix too low"
    # 52 characters: two chunks of one text, as PX4 sends them.
    first, second = wait_for(client, "STATUSTEXT"), wait_for(client, "STATUSTEXT")
    assert (first.text, second.text) == ("Arming denied: Resolve system health failures firs",
                                         "t\t")
    assert (first.id, first.chunk_seq, second.chunk_seq) == (second.id, 0, 1)
    # Force-arming (PX4's magic number) bypasses the check, as on PX4.
    assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196) == M.MAV_RESULT_ACCEPTED


def test_parameters(sim_factory: SimFactory, client: Any) -> None:
    start(sim_factory, client)
    client.mav.param_request_read_send(1, 1, b"MPC_XY_VEL_MAX", -1)
    value = wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_VEL_MAX")
    assert value.param_value == pytest.approx(12.0)
    assert value.param_type == M.MAV_PARAM_TYPE_REAL32
    client.mav.param_set_send(1, 1, b"RTL_RETURN_ALT", 45.0, M.MAV_PARAM_TYPE_REAL32)
    echo = wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "RTL_RETURN_ALT")
    assert echo.param_value == pytest.approx(45.0)
    client.mav.param_set_send(1, 1, b"MPC_XY_VEL_MAX", 1e6, M.MAV_PARAM_TYPE_REAL32)
    clamped = wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_VEL_MAX")
    assert clamped.param_value == pytest.approx(20.0)
    client.mav.param_request_list_send(1, 1)
    names = {wait_for(client, "PARAM_VALUE").param_id for _ in range(echo.param_count)}
    assert {"MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "COM_DISARM_PRFLT", "MPC_ACC_HOR"} <= names
    # The mission's max_accel_m_s2 sets MPC_ACC_HOR.
    client.mav.param_request_read_send(1, 1, b"MPC_ACC_HOR", -1)
    assert wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "MPC_ACC_HOR"
                    ).param_value == pytest.approx(4.0)


def test_geofence_upload_and_download(sim_factory: SimFactory, client: Any) -> None:
    sim = start(sim_factory, client)
    fence = M.MAV_MISSION_TYPE_FENCE
    # A square about 1 km across, around home.
    corners = [(-34.925, 138.596), (-34.925, 138.606), (-34.917, 138.606), (-34.917, 138.596)]
    client.mav.mission_count_send(1, 1, len(corners), fence)
    for _ in corners:
        req = wait_for(client, "MISSION_REQUEST_INT", lambda m: m.mission_type == fence)
        lat, lon = corners[req.seq]
        client.mav.mission_item_int_send(
            1, 1, req.seq, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            0, 1, len(corners), 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 0.0, fence)
    ack = wait_for(client, "MISSION_ACK")
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == fence

    client.mav.mission_request_list_send(1, 1, fence)
    assert wait_for(client, "MISSION_COUNT").count == len(corners)
    client.mav.mission_request_int_send(1, 1, 2, fence)
    item = wait_for(client, "MISSION_ITEM_INT")
    assert (item.x, item.y) == (round(corners[2][0] * 1e7), round(corners[2][1] * 1e7))

    # Missions are refused honestly: this vehicle flies offboard only.
    client.mav.mission_count_send(1, 1, 3, M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(client, "MISSION_ACK").type == M.MAV_MISSION_UNSUPPORTED

    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        fences = [r for r in read_truth_file(sim.truth_path).records if r["type"] == "fence"]
        if fences:
            break
        time.sleep(0.1)
    polygon = fences[-1]["inclusion_polygons_m"][0]
    frame = LocalFrame(-34.9212, 138.6011, 0.0)
    for (lat, lon), (east, north) in zip(corners, polygon, strict=True):
        e, n, _ = frame.to_enu(lat, lon, 0.0)
        assert (east, north) == pytest.approx((float(e), float(n)), abs=0.05)


def test_telemetry_rate_can_be_changed(sim_factory: SimFactory, client: Any) -> None:
    start(sim_factory, client)
    result = command(client, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                     M.MAVLINK_MSG_ID_BATTERY_STATUS, 50_000)
    assert result == M.MAV_RESULT_ACCEPTED
    t0 = time.monotonic()
    for _ in range(10):
        wait_for(client, "BATTERY_STATUS", timeout_s=2.0)
    rate_hz = 10 / (time.monotonic() - t0)
    assert rate_hz > 8.0  # 20 Hz asked, 1 Hz by default
    battery = wait_for(client, "BATTERY_STATUS")
    assert battery.battery_remaining == 100 and math.isclose(battery.voltages[0] / 1000, 16.8)


def test_link_drop_on_the_wall_clock_and_the_gcs_port(sim_factory: SimFactory, client: Any
                                                      ) -> None:
    gcs = udp_socket(timeout_s=2.0)
    start(sim_factory, client, speedup=10.0, extra=[
        "--fault", "link_drop,at_s=10,duration_s=1.5",
        "--gcs", f"127.0.0.1:{gcs.getsockname()[1]}"])
    parser = M.MAVLink(None)
    first = parser.parse_buffer(gcs.recvfrom(4096)[0])
    assert first and first[0].get_srcSystem() == 1
    gcs.close()
    arrivals = []
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        if client.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2) is not None:
            arrivals.append(time.monotonic())
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]
    # Sim time 10 s at 10x is ~1 s of wall; the drop lasts 1.5 s of wall, not 0.15 s.
    assert 1.3 < max(gaps) < 2.5
    assert gaps.index(max(gaps)) < len(gaps) - 2  # and the heartbeats came back


def test_sigint_stops_cleanly(sim_factory: SimFactory, client: Any) -> None:
    sim = start(sim_factory, client)
    sim.proc.send_signal(signal.SIGINT)
    assert sim.wait_exit(10.0) == 0
    end = read_truth_file(sim.truth_path).records[-1]
    assert end["type"] == "end" and end["reason"] == "signal"
