"""PX4-like behaviour of the simulated autopilot, driven directly (no MAVLink)."""

from __future__ import annotations

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from sim import px4_modes as modes
from sim.autopilot import Autopilot, LandedState, Result, Setpoint
from sim.fence import Circle, Fence
from sim.kinematics import Limits
from sim.params import ParamTable

DT = 0.05


class Flight:
    """An autopilot with sim and wall clocks advanced together (speedup 1 unless told)."""

    def __init__(self, endurance_s: float = 1800.0, speedup: float = 1.0, **params: float
                 ) -> None:
        self.ap = Autopilot(ParamTable(params), Limits(), endurance_s)
        self.sim_s = 0.0
        self.speedup = speedup

    @property
    def wall_s(self) -> float:
        return self.sim_s / self.speedup

    def run(self, seconds: float, setpoint: Setpoint | None = None) -> None:
        for _ in range(round(seconds / DT)):
            if setpoint is not None:
                self.ap.offboard_setpoint(setpoint, self.wall_s)
            self.sim_s += DT
            self.ap.step(DT, self.sim_s, self.wall_s)

    def until(self, predicate: object, limit_s: float, setpoint: Setpoint | None = None
              ) -> float:
        start = self.sim_s
        while not predicate():  # type: ignore[operator]
            assert self.sim_s - start < limit_s, "condition not reached"
            self.run(DT, setpoint)
        return self.sim_s - start

    def kinds(self) -> list[str]:
        return [e.kind for e in self.ap.events]

    def airborne(self, alt_m: float = 50.0) -> None:
        assert self.ap.arm(self.wall_s) is Result.ACCEPTED
        assert self.ap.takeoff(alt_m) is Result.ACCEPTED
        self.until(lambda: self.ap.mode == modes.HOLD, 60.0)


def test_takeoff_climbs_at_the_rate_limit_then_holds() -> None:
    f = Flight()
    f.ap.params.set("MIS_TAKEOFF_ALT", 20.0)
    assert f.ap.takeoff(None) is Result.DENIED  # not armed
    assert f.ap.arm(f.wall_s) is Result.ACCEPTED
    assert f.ap.takeoff(None) is Result.ACCEPTED
    assert f.ap.mode == modes.TAKEOFF
    f.run(2.0)
    assert f.ap.landed_state is LandedState.TAKEOFF
    took = f.until(lambda: f.ap.mode == modes.HOLD, 60.0) + 2.0
    assert took == pytest.approx(20.0 / 3.0 + 1.5, abs=1.5)
    assert f.ap.state.up_m == pytest.approx(20.0, abs=0.4)
    assert f.ap.landed_state is LandedState.IN_AIR and f.ap.has_flown
    f.run(5.0)
    assert f.ap.state.up_m == pytest.approx(20.0, abs=0.3)


def test_auto_disarm_when_not_taking_off() -> None:
    f = Flight()
    f.ap.arm(f.wall_s)
    f.run(9.5)
    assert f.ap.armed
    f.run(1.0)
    assert not f.ap.armed and "disarmed" in f.kinds()


def test_preflight_disarm_runs_on_the_wall_clock() -> None:
    f = Flight(speedup=20.0)
    f.ap.arm(f.wall_s)
    f.run(100.0)  # 100 s of sim is 5 s of wall
    assert f.ap.armed


def test_offboard_needs_setpoints_and_falls_back_to_hold() -> None:
    f = Flight()
    f.airborne()
    assert f.ap.set_mode(modes.OFFBOARD, f.wall_s) is Result.TEMPORARILY_REJECTED
    sp = Setpoint(velocity_enu_m_s=(5.0, 0.0, 0.0), yaw_deg=90.0)
    f.ap.offboard_setpoint(sp, f.wall_s)
    assert f.ap.set_mode(modes.OFFBOARD, f.wall_s) is Result.ACCEPTED
    f.run(5.0, sp)
    assert f.ap.state.v_east_m_s == pytest.approx(5.0)
    assert f.ap.state.yaw_deg == pytest.approx(90.0)
    f.run(0.9)  # COM_OF_LOSS_T = 1 s: still offboard
    assert f.ap.mode == modes.OFFBOARD
    f.run(0.3)
    # PX4: COM_OBL_RC_ACT 0 (position mode) needs RC; without it NAV_RCL_ACT 2: return.
    assert f.ap.mode == modes.RTL and "failsafe" in f.kinds() and f.ap.failsafe


@pytest.mark.parametrize(("obl", "rcl", "rc", "expected"), [
    (5, 2, False, modes.HOLD), (4, 2, False, modes.LAND), (0, 1, False, modes.HOLD),
    (0, 3, False, modes.LAND), (0, 2, True, modes.POSCTL), (1, 2, True, modes.ALTCTL),
])
def test_offboard_loss_action(obl: int, rcl: int, rc: bool, expected: modes.PX4Mode) -> None:
    f = Flight(COM_OBL_RC_ACT=obl, NAV_RCL_ACT=rcl)
    f.airborne()
    f.ap.rc_available = rc
    sp = Setpoint(velocity_enu_m_s=(5.0, 0.0, 0.0))
    f.ap.offboard_setpoint(sp, f.wall_s)
    assert f.ap.set_mode(modes.OFFBOARD, f.wall_s) is Result.ACCEPTED
    f.run(3.0, sp)
    f.run(1.5)
    assert f.ap.mode == expected
    if expected == modes.HOLD:
        f.run(5.0)
        assert f.ap.state.ground_speed_m_s < 0.05


def test_speed_is_capped_by_mpc_xy_vel_max() -> None:
    f = Flight()
    f.airborne()
    sp = Setpoint(velocity_enu_m_s=(0.0, 15.0, 0.0))
    f.ap.offboard_setpoint(sp, f.wall_s)
    f.ap.set_mode(modes.OFFBOARD, f.wall_s)
    f.run(8.0, sp)
    assert f.ap.state.v_north_m_s == pytest.approx(12.0)
    f.ap.params.set("MPC_XY_VEL_MAX", 20.0)
    f.run(3.0, sp)
    assert f.ap.state.v_north_m_s == pytest.approx(15.0)  # the airframe's limit


def test_position_setpoints_are_flown() -> None:
    f = Flight()
    f.airborne(30.0)
    sp = Setpoint(position_enu_m=(100.0, -50.0, 40.0))
    f.ap.offboard_setpoint(sp, f.wall_s)
    f.ap.set_mode(modes.OFFBOARD, f.wall_s)
    f.run(40.0, sp)
    s = f.ap.state
    assert (s.east_m, s.north_m, s.up_m) == pytest.approx((100.0, -50.0, 40.0), abs=0.3)


@pytest.mark.parametrize(("alt_m", "expected_m"), [(50.0, 50.0), (10.0, 30.0)])
def test_rtl_climbs_to_return_alt_or_stays_higher(alt_m: float, expected_m: float) -> None:
    f = Flight()
    f.airborne(alt_m)
    sp = Setpoint(position_enu_m=(300.0, 200.0, alt_m))
    f.ap.offboard_setpoint(sp, f.wall_s)
    f.ap.set_mode(modes.OFFBOARD, f.wall_s)
    f.run(60.0, sp)
    assert f.ap.return_to_launch() is Result.ACCEPTED
    top = 0.0
    while f.ap.mode == modes.RTL and f.ap.armed:
        f.run(1.0)
        top = max(top, f.ap.state.up_m)
        if f.ap.state.up_m >= expected_m - 1.0:
            assert f.ap.state.ground_speed_m_s <= 5.0 + 1e-6  # MPC_XY_CRUISE
        assert f.sim_s < 400.0
    assert top == pytest.approx(expected_m, abs=0.6)
    assert not f.ap.armed and not f.ap.in_air and f.ap.flight_complete
    assert np.hypot(f.ap.state.east_m, f.ap.state.north_m) < 1.0
    assert "landed" in f.kinds()


def test_battery_drains_and_failsafes() -> None:
    f = Flight(endurance_s=200.0)
    f.airborne(20.0)
    f.ap.battery_fraction = 0.08
    f.run(1.0)
    assert f.ap.mode == modes.HOLD
    f.run(2.5)  # 0.08 - 3.5/200 < 0.07: critical -> RTL
    assert f.ap.mode == modes.RTL
    f.run(5.0)  # below 0.05: emergency -> land
    assert f.ap.mode == modes.LAND
    assert f.kinds().count("battery") == 3  # low, critical, emergency


def test_battery_critical_refuses_arming() -> None:
    f = Flight()
    f.ap.battery_fraction = 0.05
    assert f.ap.arm(f.wall_s) is Result.DENIED


def test_geofence_breach_holds() -> None:
    f = Flight()
    f.ap.fence = Fence(inclusion_polygons=(SearchArea.rectangle(-100, 100, -100, 100),),
                       exclusion_circles=(Circle(0.0, 500.0, 10.0),))
    f.airborne(20.0)
    sp = Setpoint(velocity_enu_m_s=(10.0, 0.0, 0.0))
    f.ap.offboard_setpoint(sp, f.wall_s)
    f.ap.set_mode(modes.OFFBOARD, f.wall_s)
    f.until(lambda: f.ap.mode == modes.HOLD, 30.0, sp)
    assert "geofence" in f.kinds()
    assert 100.0 < f.ap.state.east_m < 102.0
    assert not f.ap.fence.allows(0.0, 495.0) and f.ap.fence.allows(0.0, 0.0)


def test_gps_loss_refuses_arming_unless_forced() -> None:
    f = Flight()
    f.ap.gps_ok = False
    assert f.ap.arm(f.wall_s) is Result.DENIED
    assert f.ap.arm(f.wall_s, force=True) is Result.ACCEPTED


def test_mode_rules() -> None:
    f = Flight()
    assert f.ap.set_mode(modes.MISSION, f.wall_s) is Result.DENIED
    assert f.ap.set_mode((modes.MainMode.MANUAL, modes.AutoSubMode.NONE), 0.0) is Result.DENIED
    assert f.ap.set_mode(modes.RTL, f.wall_s) is Result.DENIED  # disarmed
    assert f.ap.set_mode(modes.POSCTL, f.wall_s) is Result.ACCEPTED
    assert f.ap.mode == modes.POSCTL
    f.ap.arm(f.wall_s)
    assert f.ap.set_mode(modes.TAKEOFF, f.wall_s) is Result.ACCEPTED
    f.until(lambda: f.ap.mode == modes.HOLD, 20.0)
    assert f.ap.state.up_m == pytest.approx(2.5, abs=0.3)  # PX4's MIS_TAKEOFF_ALT
    assert f.ap.disarm() is Result.DENIED  # in the air
    assert f.ap.set_mode(modes.LAND, f.wall_s) is Result.ACCEPTED
    f.until(lambda: not f.ap.armed, 30.0)


def test_px4_custom_mode_encoding() -> None:
    assert modes.encode(modes.OFFBOARD) == 6 << 16
    assert modes.encode(modes.RTL) == (5 << 24) | (4 << 16)
    for mode in (modes.HOLD, modes.TAKEOFF, modes.LAND, modes.RTL, modes.OFFBOARD, modes.POSCTL):
        assert modes.decode(modes.encode(mode)) == mode
    with pytest.raises(ValueError):
        modes.from_ids(4, 0)
    with pytest.raises(ValueError):
        modes.from_ids(42, 0)
    assert modes.name(modes.HOLD) == "HOLD"
