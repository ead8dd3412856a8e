"""The scripted pilot takeover (fault ``pilot_takeover``): flag, schema, behaviour, truth counters.

In-process (autopilot + MAVLink side with a fake clock) for the behaviour on the wire; the real
simulator process with pymavlink (exact counts) and with plain MAVSDK for the whole story.
"""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path
from typing import Any

import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync
from pymavlink import mavutil

from mexgen_gcs.config import load_mission
from mexgen_gcs.errors import ConfigError
from mexgen_gcs.io.truthfile import read_truth_file
from sim import px4_modes as modes
from sim.faults import Fault, FaultSchedule, parse_fault_flag
from sim.takeover import command_name
from tests.sim.mav_helpers import command, start, wait_for
from tests.sim.sim_helpers import DEMO_MISSION, SimFactory, free_udp_port
from tests.sim.test_sim_mavsdk_flight import first
from tests.sim.test_sim_vehicle_mavlink import Harness

M = mavutil.mavlink
_VELOCITY_MASK = 0b0000_1001_1100_0111  # velocity + yaw


def _px4_mode(hb: Any) -> str:
    return str(mavutil.interpret_px4_mode(hb.base_mode, hb.custom_mode))


def test_flag_schema_and_schedule(tmp_path: Path) -> None:
    f = parse_fault_flag("pilot_takeover,at_s=40,mode=altctl,land_after_s=12")
    assert (f.kind, f.at_s, f.mode, f.land_after_s) == ("pilot_takeover", 40.0, "ALTCTL", 12.0)
    d = parse_fault_flag("pilot_takeover,at_s=5")
    assert (d.mode, d.land_after_s) == ("POSCTL", 30.0)
    assert d.describe() == {"kind": "pilot_takeover", "at_s": 5.0, "mode": "POSCTL",
                            "land_after_s": 30.0}
    for bad in ("pilot_takeover,at_s=5,mode=OFFBOARD", "pilot_takeover,at_s=5,land_after_s=-1",
                "pilot_takeover,mode=POSCTL", "pilot_takeover,at_s=5,duration_s=3"):
        with pytest.raises(ValueError):
            parse_fault_flag(bad)
    s = FaultSchedule([Fault("pilot_takeover", 10.0, land_after_s=5.0)])
    assert s.next_start_s(0.0) == 10.0
    assert [w for w, _ in s.update(10.0, 1.0)] == ["start"]
    assert s.next_start_s(10.0) == 15.0  # the LAND switch is a sim-time event
    assert s.update(14.9, 1.49) == [] and s.active("pilot_takeover")
    assert [w for w, _ in s.update(15.0, 1.5)] == ["end"]

    demo = DEMO_MISSION.read_text(encoding="utf-8")
    path = tmp_path / "m.yaml"
    path.write_text(demo.replace(
        "  faults: []", "  faults: [{kind: pilot_takeover, at_s: 60, mode: ALTCTL}]"))
    (fault,) = load_mission(path).sim.faults
    assert (fault.kind, fault.mode, fault.land_after_s) == ("pilot_takeover", "ALTCTL", 30.0)
    path.write_text(demo.replace(
        "  faults: []", "  faults: [{kind: pilot_takeover, at_s: 60, mode: MANUAL}]"))
    with pytest.raises(ConfigError, match="mode"):
        load_mission(path)
    assert command_name(M.MAV_CMD_DO_SET_MODE) == "DO_SET_MODE" and command_name(1) == "1"


def test_pilot_switch_on_the_wire() -> None:
    """RC switch: heartbeat at once, no STATUSTEXT, brakes and holds, setpoints ignored,
    a GCS DO_SET_MODE still obeyed, LAND lands and disarms."""
    h = Harness()
    h.airborne(20.0)

    def east() -> None:
        h.send(h.gcs.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, _VELOCITY_MASK, 0, 0, 0, 0.0, 8.0, 0.0, 0, 0, 0,
            math.radians(90.0), 0))

    east()
    assert h.ack(M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == M.MAV_RESULT_ACCEPTED
    h.run(5.0, east)
    assert h.ap.state.v_east_m_s == pytest.approx(8.0)
    h.received()
    h.ap.pilot_switch(modes.POSCTL)
    h.vehicle.tick()
    hb = h.received("HEARTBEAT")
    assert hb and _px4_mode(hb[0]) == "POSCTL"
    assert hb[0].base_mode & M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    x0 = h.ap.state.east_m
    h.run(8.0, east)  # the GCS keeps streaming: ignored
    assert h.ap.mode == modes.POSCTL
    assert h.ap.state.ground_speed_m_s < 0.05
    assert 8.0 < h.ap.state.east_m - x0 < 8.0 * 8.0 / (2 * 3.0) + 1.0  # braked at <= 4 m/s^2
    assert h.ap.state.up_m == pytest.approx(20.0, abs=0.3)
    texts = [m.text for m in h.received("STATUSTEXT")]
    assert not any("POSCTL" in t or "mode" in t.lower() for t in texts), texts
    # PX4 still obeys the GCS while the pilot has the RC (the pilot may switch back).
    assert h.ack(M.MAV_CMD_DO_SET_MODE, 129, 4, 3) == M.MAV_RESULT_ACCEPTED
    assert h.ap.mode == modes.HOLD
    h.ap.pilot_switch(modes.LAND)
    h.run(30.0)
    assert not h.ap.armed and not h.ap.in_air and h.ap.flight_complete
    assert [e.kind for e in h.vehicle.take_events() if e.kind == "pilot"] == ["pilot", "pilot"]


def test_takeover_counts_what_the_gcs_sent_after_it(sim_factory: SimFactory,
                                                    client: Any) -> None:
    at_s, speedup = 30.0, 5.0
    sim = start(sim_factory, client, speedup=speedup,
                extra=["--fault", f"pilot_takeover,at_s={at_s},land_after_s=8"])

    def setpoint() -> None:
        client.mav.set_position_target_local_ned_send(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, _VELOCITY_MASK, 0, 0, 0, 0.0, 6.0, 0.0, 0, 0, 0,
            math.radians(90.0), 0)

    assert command(client, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert command(client, M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: _px4_mode(m) == "LOITER", 20.0)
    setpoint()
    assert command(client, M.MAV_CMD_DO_SET_MODE, 129, 6, 0) == M.MAV_RESULT_ACCEPTED
    # Stream at 20 Hz until the heartbeat shows the pilot's mode.
    deadline = time.monotonic() + at_s / speedup + 10.0
    streamed_in_offboard = 0
    while True:
        setpoint()
        streamed_in_offboard += 1
        hb = client.recv_match(type="HEARTBEAT", blocking=True, timeout=0.05)
        if hb is not None and _px4_mode(hb) == "POSCTL":
            break
        assert time.monotonic() < deadline, "no takeover"
    for _ in range(10):  # a GCS that did not notice: ignored, and counted
        setpoint()
        time.sleep(0.02)
    assert command(client, M.MAV_CMD_DO_SET_MODE, 129, 4, 3) == M.MAV_RESULT_ACCEPTED
    wait_for(client, "HEARTBEAT", lambda m: _px4_mode(m) == "LOITER", 5.0)
    wait_for(client, "HEARTBEAT", lambda m: _px4_mode(m) == "LAND", 8.0 / speedup + 5.0)
    assert sim.wait_exit(30.0) == 0  # landed and disarmed: the simulator ends by itself

    assert not read_truth_file(sim.truth_path).damage  # every record as documented
    records = read_truth_file(sim.truth_path).records
    faults = [r for r in records if r["type"] == "fault"]
    assert [(f["phase"], f["mode_before"], f["mode_after"]) for f in faults] == [
        ("start", "OFFBOARD", "POSCTL"), ("end", "HOLD", "LAND")]
    assert faults[0]["commands_after_takeover"] == 0
    assert faults[0]["t"] - records[0]["start_unix"] == pytest.approx(at_s, abs=0.05)
    end = records[-1]
    assert end["type"] == "end" and end["reason"] == "landed"
    assert end["commands_after_takeover"] == 1
    assert end["command_names_after_takeover"] == {"DO_SET_MODE": 1}
    # 10 sent on purpose, plus those in flight while the heartbeat travelled (< 0.2 s).
    assert 10 <= end["setpoints_after_takeover"] <= 14
    assert end["mavlink"]["rx_setpoints"] >= streamed_in_offboard + 10
    (cmd,) = [r for r in records if r["type"] == "event"
              and r["kind"] == "gcs_command_after_takeover"]
    assert (cmd["name"], cmd["result"], cmd["mode"]) == ("DO_SET_MODE", 0, "HOLD")
    vehicle = [r for r in records if r["type"] == "vehicle" and r["t"] > faults[0]["t"] + 4.0
               and r["t"] < faults[1]["t"]]
    assert vehicle and all(math.hypot(r["v_east_m_s"], r["v_north_m_s"]) < 0.1 for r in vehicle)


async def test_mavsdk_sees_the_takeover_and_the_pilot_lands(sim_factory: SimFactory) -> None:
    speedup, at_s = 5.0, 40.0
    port = free_udp_port()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        sim = await asyncio.to_thread(
            sim_factory, mavlink_port=port, speedup=speedup,
            extra=["--fault", f"pilot_takeover,at_s={at_s},mode=ALTCTL,land_after_s=10"])
        system = await mavsdk.first_autopilot(timeout_s=20.0)
        assert system is not None
        telemetry, action, offboard = (TelemetryAsync(system), ActionAsync(system),
                                       OffboardAsync(system))
        await first(telemetry.subscribe_health_all_ok(), bool, 20.0)
        await action.arm()
        await action.takeoff()
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, 20.0)
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 5.0, 0.0, 90.0))
        await offboard.start()
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.ALTCTL,
                    at_s / speedup + 10.0)
        # MAVSDK stops its setpoint stream by itself once the mode is not OFFBOARD. (Do not call
        # offboard.stop() now: it sends DO_SET_MODE HOLD, which would override the pilot.)
        assert not await offboard.is_active()
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.LAND, 10.0)
        await first(telemetry.subscribe_armed(), lambda armed: not armed, 30.0)
    assert await asyncio.to_thread(sim.wait_exit, 15.0) == 0
    end = read_truth_file(sim.truth_path).records[-1]
    assert end["reason"] == "landed" and end["commands_after_takeover"] == 0
    assert end["setpoints_after_takeover"] <= 3  # at most those in flight at the switch
