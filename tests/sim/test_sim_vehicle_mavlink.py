"""The MAVLink side in-process: bytes in, bytes out, with a fake clock (no sockets, no timing)."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.core.geo import LocalFrame
from sim import px4_modes as modes
from sim.autopilot import Autopilot
from sim.clock import SimClock
from sim.kinematics import Limits
from sim.params import ParamTable
from sim.vehicle import MavlinkVehicle

M = mavlink
FRAME = LocalFrame(-34.9212, 138.6011, 20.0)
TARGET = ("127.0.0.1", 14540)
GCS = ("127.0.0.1", 5555)
DT = 0.05


class Harness:
    def __init__(self, sysid: int = 1) -> None:
        self.now = 0.0
        self.clock = SimClock(1.0, monotonic=lambda: self.now, unix_now=lambda: 1.7e9)
        self.ap = Autopilot(ParamTable(), Limits(), 1800.0)
        self.sent: list[tuple[bytes, tuple[str, int]]] = []
        self.vehicle = MavlinkVehicle(self.ap, self.clock, FRAME,
                                      lambda d, a: self.sent.append((d, a)), [TARGET], sysid)
        self.gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)

    def send(self, msg: Any, addr: tuple[str, int] = GCS) -> None:
        self.vehicle.handle_datagram(msg.pack(self.gcs), addr)

    def received(self, kind: str | None = None, to: tuple[str, int] = TARGET) -> list[Any]:
        """What was sent to ``to`` since the last call (the rest is dropped)."""
        parser = M.MAVLink(None)
        out = []
        for data, addr in self.sent:
            if addr == to:
                out.extend(parser.parse_buffer(data) or [])
        self.sent.clear()
        return [m for m in out if kind is None or m.get_type() == kind]

    def ack(self, cmd: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.send(self.gcs.command_long_encode(1, 1, cmd, 0, *p))
        acks = [m for m in self.received("COMMAND_ACK") if m.command == cmd]
        assert len(acks) == 1
        return int(acks[0].result)

    def run(self, seconds: float, each: Any = None) -> None:
        for _ in range(round(seconds / DT)):
            if each is not None:
                each()
            self.now += DT
            self.clock.sim_s += DT
            self.ap.step(DT, self.clock.sim_s, self.clock.wall_s())
            self.vehicle.tick()

    def airborne(self, alt_m: float = 30.0) -> None:
        self.ap.params.set("MIS_TAKEOFF_ALT", alt_m)
        assert self.ack(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        assert self.ack(M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
        self.run(alt_m / 3.0 + 4.0)
        assert self.ap.mode == modes.HOLD


def test_replies_go_to_the_target_and_to_whoever_spoke() -> None:
    h = Harness()
    h.run(1.0)
    assert {a for _, a in h.sent} == {TARGET}
    h.send(h.gcs.heartbeat_encode(6, 8, 0, 0, 4))
    h.run(1.0)
    assert {a for _, a in h.sent} == {TARGET, GCS}
    hb = h.received("HEARTBEAT", to=GCS)[0]
    assert hb.autopilot == M.MAV_AUTOPILOT_PX4 and hb.get_srcComponent() == 1


def test_offboard_velocity_body_and_global_setpoints() -> None:
    h = Harness()
    h.airborne()

    def velocity() -> None:  # 5 m/s east (NED y), facing east
        h.send(h.gcs.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b0000_1001_1100_0111, 0, 0, 0, 0.0, 5.0, 0.0,
            0, 0, 0, math.radians(90.0), 0))

    velocity()
    assert h.ack(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == M.MAV_RESULT_ACCEPTED
    h.run(6.0, velocity)
    assert h.ap.state.v_east_m_s == pytest.approx(5.0) and h.ap.state.yaw_deg == pytest.approx(90)

    def body() -> None:  # 3 m/s forward in the body frame = east, now
        h.send(h.gcs.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_BODY_NED, 0b0000_1101_1100_0111, 0, 0, 0, 3.0, 0.0, 0.0,
            0, 0, 0, 0, 0))

    h.run(3.0, body)
    assert h.ap.state.v_east_m_s == pytest.approx(3.0, abs=1e-6)
    assert h.ap.state.v_north_m_s == pytest.approx(0.0, abs=1e-6)

    lat, lon, _ = FRAME.to_geodetic(40.0, 80.0, 0.0)

    def global_position() -> None:  # 25 m above home, relative-altitude frame
        h.send(h.gcs.set_position_target_global_int_encode(
            0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b0000_1101_1111_1000,
            round(float(lat) * 1e7), round(float(lon) * 1e7), 25.0, 0, 0, 0, 0, 0, 0, 0, 0))

    h.run(40.0, global_position)
    s = h.ap.state
    assert (s.east_m, s.north_m, s.up_m) == pytest.approx((40.0, 80.0, 25.0), abs=0.3)

    def accel_only() -> None:
        h.send(h.gcs.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b0000_1100_0011_1111, 0, 0, 0, 0, 0, 0,
            1.0, 0, 0, 0, 0))

    h.received()
    h.run(2.0, accel_only)  # not flown: offboard is lost, the failsafe returns (as PX4 SITL)
    assert h.ap.mode == modes.RTL
    texts = [m.text for m in h.received("STATUSTEXT")]
    assert any("only position/velocity" in t for t in texts)
    assert "Failsafe activated\t" in texts  # PX4's words for the offboard-loss failsafe


def test_command_int_reposition_speed_and_home() -> None:
    h = Harness()
    h.airborne()
    lat, lon, alt = FRAME.to_geodetic(-120.0, 60.0, 40.0)
    h.send(h.gcs.command_int_encode(
        1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0, 8.0, 1, 0, math.nan,
        round(float(lat) * 1e7), round(float(lon) * 1e7), float(alt)))
    assert h.received("COMMAND_ACK")[0].result == M.MAV_RESULT_ACCEPTED
    top = 0.0

    def watch() -> None:
        nonlocal top
        top = max(top, h.ap.state.ground_speed_m_s)

    h.run(40.0, watch)
    s = h.ap.state
    assert (s.east_m, s.north_m, s.up_m) == pytest.approx((-120.0, 60.0, 40.0), abs=0.3)
    assert top == pytest.approx(8.0, abs=0.05)
    assert h.ack(M.MAV_CMD_DO_CHANGE_SPEED, 1, 7.0) == M.MAV_RESULT_ACCEPTED
    assert h.ack(M.MAV_CMD_DO_SET_HOME, 1) == M.MAV_RESULT_ACCEPTED
    h.send(h.gcs.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                     M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0))
    home = h.received("HOME_POSITION")
    assert len(home) == 1 and (home[0].x, home[0].y) == pytest.approx((60.0, -120.0), abs=0.5)


def test_link_down_is_deaf_and_mute() -> None:
    h = Harness()
    h.run(1.0)
    h.vehicle.link_down = True
    h.received()
    h.send(h.gcs.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0,
                                     0))
    h.run(3.0)
    assert h.sent == [] and not h.ap.armed
    h.vehicle.link_down = False
    h.run(1.1)
    assert h.received("HEARTBEAT")


def test_timesync_ping_autopilot_version_and_intervals() -> None:
    h = Harness()
    h.run(2.0)
    h.received()
    h.send(h.gcs.timesync_encode(0, 123456))
    reply = h.received("TIMESYNC")[0]
    assert reply.ts1 == 123456 and reply.tc1 == pytest.approx(2e9, rel=1e-3)
    h.send(h.gcs.ping_encode(42, 7, 0, 0))
    ping = h.received("PING")[0]
    assert (ping.time_usec, ping.seq, ping.target_system) == (42, 7, 255)
    assert h.ack(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == 0
    h.send(h.gcs.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                     M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0))
    version = h.received("AUTOPILOT_VERSION")[0]
    assert version.capabilities & M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    assert h.ack(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, -1) == 0
    h.run(1.0)
    assert not h.received("ATTITUDE")
    assert h.ack(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 0) == 0
    h.run(1.0)
    assert len(h.received("ATTITUDE")) == pytest.approx(10, abs=1)


def test_fence_upload_retries_then_gives_up() -> None:
    h = Harness()
    fence = M.MAV_MISSION_TYPE_FENCE
    h.send(h.gcs.mission_count_encode(1, 1, 3, fence))
    h.run(0.1)
    assert [m.seq for m in h.received("MISSION_REQUEST_INT")] == [0]
    h.run(10.0)  # never answered: re-requested every second, five times, then cancelled
    msgs = h.received()
    assert [m.seq for m in msgs if m.get_type() == "MISSION_REQUEST_INT"] == [0] * 5
    acks = [m for m in msgs if m.get_type() == "MISSION_ACK"]
    assert [a.type for a in acks] == [M.MAV_MISSION_OPERATION_CANCELLED]
    # An invalid polygon (two vertices) is refused as a whole.
    h.send(h.gcs.mission_count_encode(1, 1, 2, fence))
    for seq in range(2):
        h.send(h.gcs.mission_item_int_encode(
            1, 1, seq, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 0, 1,
            2, 0, 0, 0, -349212000 + seq * 1000, 1386011000, 0, fence))
    assert [a.type for a in h.received("MISSION_ACK")] == [M.MAV_MISSION_INVALID]
    assert h.ap.fence.empty
    h.send(h.gcs.mission_clear_all_encode(1, 1, fence))
    assert [a.type for a in h.received("MISSION_ACK")] == [M.MAV_MISSION_ACCEPTED]


def test_gps_loss_stops_global_position_and_health() -> None:
    h = Harness()
    h.ap.gps_ok = False
    h.run(2.0)
    msgs = h.received()
    kinds = {m.get_type() for m in msgs}
    assert "GLOBAL_POSITION_INT" not in kinds and "LOCAL_POSITION_NED" in kinds
    gps = [m for m in msgs if m.get_type() == "GPS_RAW_INT"]
    assert gps and all(m.fix_type == M.GPS_FIX_TYPE_NO_FIX for m in gps)
    status = [m for m in msgs if m.get_type() == "SYS_STATUS"][-1]
    assert not status.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK
    assert h.ack(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
