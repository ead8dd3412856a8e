"""What the simulator copies from real PX4 (observed on PX4 SITL SIH, see sim/README.md):
STATUSTEXT wordings and chunking, silent mode changes, HEARTBEAT flags and CRITICAL state in a
failsafe, the geofence breach, home re-set at arming, and its clocks (rate error, SYSTEM_TIME
on the host's clock)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil

from mexgen_gcs.core.area import SearchArea
from sim import px4_modes as modes
from sim.autopilot import HOME_ERROR_MAX_M, Autopilot
from sim.clock import SimClock
from sim.fence import Fence
from sim.kinematics import Limits
from sim.params import ParamTable
from sim.vehicle import MavlinkVehicle
from tests.sim.mav_helpers import command, start, wait_for
from tests.sim.sim_helpers import SimFactory
from tests.sim.test_sim_vehicle_mavlink import FRAME, TARGET, Harness

M = mavutil.mavlink
_VELOCITY_MASK = 0b0000_1001_1100_0111


def _joined(msgs: list[Any]) -> list[str]:
    """STATUSTEXT chunks (same id, chunk_seq 0, 1, ...) joined into PX4's texts."""
    out: list[str] = []
    for m in msgs:
        if m.chunk_seq == 0:
            out.append(m.text)
        else:
            out[-1] += m.text
    return out


def _texts(h: Harness) -> list[str]:
    return _joined(h.received("STATUSTEXT"))


def _after_tick(h: Harness) -> list[str]:
    """STATUSTEXT the vehicle sends on its next tick (state changes are announced there)."""
    h.vehicle.tick()
    return _texts(h)


def test_px4_wordings_and_silent_mode_changes() -> None:
    h = Harness()
    h.ap.alt0_amsl_m = FRAME.alt0_m
    h.ap.params.set("MIS_TAKEOFF_ALT", 10.0)
    assert h.ack(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert h.ack(M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
    h.run(8.0)
    assert h.ap.mode == modes.HOLD
    texts = _texts(h)
    assert texts == ["Armed by external command\t", "Using default takeoff altitude: 10.0 m\t",
                     "Takeoff detected\t"], texts
    assert h.ack(M.MAV_CMD_DO_SET_MODE, 129, 3) == M.MAV_RESULT_ACCEPTED  # POSCTL: silent
    h.vehicle.tick()
    sent = h.received()
    hb = [m for m in sent if m.get_type() == "HEARTBEAT"][-1]
    assert hb.base_mode & M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    assert [m for m in sent if m.get_type() == "STATUSTEXT"] == []
    assert h.ack(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_ACCEPTED
    # PX4 main: 20 m AMSL home (FRAME) + 30 m RTL_RETURN_ALT
    assert _after_tick(h) == ["Returning to launch\t",
                         "RTL: start return at 50 m (30 m above destination)\t"]
    h.run(60.0)
    assert not h.ap.armed
    assert _texts(h) == ["RTL: land at destination\t", "Landing detected\t",
                         "Disarmed by landing\t"]


def test_geofence_breach_hold_failsafe_and_offboard_ignored() -> None:
    h = Harness()
    h.airborne(20.0)
    h.ap.fence = Fence(inclusion_polygons=(SearchArea.rectangle(-100, 100, -100, 60),))

    def north() -> None:
        h.send(h.gcs.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, _VELOCITY_MASK, 0, 0, 0, 10.0, 0.0, 0.0, 0, 0, 0,
            0.0, 0))

    north()
    assert h.ack(M.MAV_CMD_DO_SET_MODE, 129, 6) == M.MAV_RESULT_ACCEPTED
    h.vehicle.tick()
    hb = h.received("HEARTBEAT")[-1]  # offboard: STABILIZE only, as PX4 (no AUTO/GUIDED)
    assert hb.base_mode == (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
                            | M.MAV_MODE_FLAG_STABILIZE_ENABLED)
    h.run(20.0, north)  # keeps streaming north after the breach
    assert h.ap.mode == modes.HOLD and h.ap.failsafe
    assert h.ap.state.ground_speed_m_s < 0.05
    assert h.ap.state.north_m == pytest.approx(60.0, abs=1.0)  # back where it crossed
    assert _texts(h) == ["Geofence: approaching or outside geofence", "Failsafe activated\t"]
    h.run(1.1, north)
    hb = h.received("HEARTBEAT")[-1]
    assert hb.system_status == M.MAV_STATE_CRITICAL
    assert h.ack(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_ACCEPTED
    assert not h.ap.failsafe
    h.run(1.1)
    assert h.received("HEARTBEAT")[-1].system_status == M.MAV_STATE_ACTIVE


def test_home_is_reset_at_arming_and_takeoff_by_a_small_error() -> None:
    now = [0.0]
    clock = SimClock(1.0, monotonic=lambda: now[0], unix_now=lambda: 1.7e9)
    homes = []
    for seed in range(20):
        ap = Autopilot(ParamTable(), Limits(), 1800.0, 20.0, np.random.default_rng(seed))
        ap.step(0.5, 0.5, 0.5)
        assert ap.arm(0.5) is not None and ap.home_set_sim_s == 0.5
        homes.append(ap.home_enu_m)
    arr = np.array(homes)
    assert np.all(np.abs(arr) <= HOME_ERROR_MAX_M) and np.std(arr[:, 0]) > 0.02
    sent: list[Any] = []
    v = MavlinkVehicle(ap, clock, FRAME, lambda d, a: sent.append(d), [TARGET])
    clock.sim_s = 0.5
    home = v.telemetry.home_position()
    assert home.time_usec == 500_000  # time since boot, as PX4
    assert home.z == pytest.approx(-ap.home_enu_m[2])


def test_clock_rate_error_and_host_system_time() -> None:
    now = [100.0]
    clock = SimClock(4.0, monotonic=lambda: now[0], unix_now=lambda: 1.7e9 + now[0],
                     rate_error=-0.02, system_time="host")
    now[0] += 0.2
    clock.sim_s = clock.due_s()
    assert clock.sim_s == pytest.approx(0.2 * 3.92)
    assert clock.unix() == pytest.approx(1.7e9 + 100.0 + 0.784)
    assert clock.system_time_unix() == pytest.approx(1.7e9 + 100.2)  # the host's clock
    with pytest.raises(ValueError):
        SimClock(4.0, rate_error=0.9)
    with pytest.raises(ValueError):
        SimClock(4.0, system_time="gps")


def test_process_clock_like_px4_sitl(sim_factory: SimFactory, client: Any) -> None:
    """--clock-rate-error and --system-time host, measured as a GCS would (SYSTEM_TIME)."""
    start(sim_factory, client, speedup=4.0,
          extra=["--clock-rate-error", "-0.04", "--system-time", "host"])
    assert command(client, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_SYSTEM_TIME,
                   100_000) == M.MAV_RESULT_ACCEPTED

    def sample() -> tuple[float, float, float]:
        m = wait_for(client, "SYSTEM_TIME")
        return time.monotonic(), m.time_unix_usec / 1e6, m.time_boot_ms / 1e3

    a = sample()
    time.sleep(3.0)
    while client.recv_match(blocking=False) is not None:
        pass
    b = sample()
    wall = b[0] - a[0]
    assert (b[1] - a[1]) / wall == pytest.approx(1.0, abs=0.05)
    assert (b[2] - a[2]) / wall == pytest.approx(3.84, abs=0.12)
    assert b[1] == pytest.approx(time.time(), abs=0.5)
