"""Point-mass multirotor kinematics: limits hold, setpoints are reached, no overshoot."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.kinematics import (
    KinematicState,
    Limits,
    VelocityCommand,
    attitude_rad,
    step,
    velocity_towards,
    wrap_180,
)

LIMITS = Limits()
AIR = KinematicState(up_m=50.0)


def fly(state: KinematicState, cmd: VelocityCommand, seconds: float, dt: float = 0.05
        ) -> list[KinematicState]:
    out = [state]
    for _ in range(round(seconds / dt)):
        out.append(step(out[-1], cmd, LIMITS, dt))
    return out


def test_reaches_commanded_velocity_at_max_acceleration() -> None:
    v = 10.0 / math.sqrt(2.0)
    track = fly(AIR, VelocityCommand(v, v, 0.0, yaw_deg=45.0), 10.0)
    end = track[-1]
    assert end.ground_speed_m_s == pytest.approx(10.0)
    # 2.5 s to reach 10 m/s at 4 m/s^2, then 7.5 s cruising: 12.5 + 75 m.
    assert math.hypot(end.east_m, end.north_m) == pytest.approx(87.5, abs=0.3)
    assert end.yaw_deg == pytest.approx(45.0)
    assert track[10].ground_speed_m_s == pytest.approx(0.5 * 4.0, abs=1e-9)


def test_speed_climb_descent_and_yaw_rate_are_capped() -> None:
    end = fly(AIR, VelocityCommand(40.0, 0.0, 10.0, yaw_rate_deg_s=500.0), 10.0)[-1]
    assert end.ground_speed_m_s == pytest.approx(15.0)
    assert end.v_up_m_s == pytest.approx(3.0)
    assert end.yaw_rate_deg_s == pytest.approx(90.0)
    down = fly(AIR, VelocityCommand(0.0, 0.0, -10.0), 5.0)[-1]
    assert down.v_up_m_s == pytest.approx(-1.5)


def test_ground_stops_descent_and_sliding() -> None:
    end = fly(KinematicState(up_m=1.0), VelocityCommand(0.0, 0.0, -1.5), 5.0)[-1]
    assert end.up_m == 0.0 and end.v_up_m_s == 0.0
    rest = fly(KinematicState(), VelocityCommand(5.0, 0.0, 0.0), 2.0)[-1]
    assert (rest.east_m, rest.up_m) == (0.0, 0.0)


@settings(max_examples=60, deadline=None)
@given(ve=st.floats(-30, 30), vn=st.floats(-30, 30), vu=st.floats(-10, 10),
       yaw=st.floats(-720, 720), dt=st.floats(0.001, 0.1))
def test_one_step_never_exceeds_the_limits(ve: float, vn: float, vu: float, yaw: float,
                                           dt: float) -> None:
    s0 = KinematicState(up_m=20.0, v_east_m_s=3.0, v_north_m_s=-2.0, yaw_deg=10.0)
    s1 = step(s0, VelocityCommand(ve, vn, vu, yaw_deg=yaw), LIMITS, dt)
    dv = math.hypot(s1.v_east_m_s - s0.v_east_m_s, s1.v_north_m_s - s0.v_north_m_s)
    assert dv <= LIMITS.max_accel_m_s2 * dt + 1e-9
    assert s1.ground_speed_m_s <= LIMITS.max_speed_m_s + 1e-9
    assert -LIMITS.max_descent_m_s - 1e-9 <= s1.v_up_m_s <= LIMITS.max_climb_m_s + 1e-9
    assert abs(wrap_180(s1.yaw_deg - s0.yaw_deg)) <= LIMITS.max_yaw_rate_deg_s * dt + 1e-6
    assert 0.0 <= s1.yaw_deg < 360.0


@settings(max_examples=25, deadline=None)
@given(east=st.floats(-800, 800), north=st.floats(-800, 800), up=st.floats(5, 120))
def test_position_control_arrives_without_overshoot(east: float, north: float, up: float
                                                    ) -> None:
    s = KinematicState(up_m=30.0)
    start_dist = math.hypot(east, north)
    worst = 0.0
    for _ in range(int(400 / 0.05)):
        ve, vn, vu = velocity_towards(s, east, north, up, LIMITS, speed_m_s=12.0)
        s = step(s, VelocityCommand(ve, vn, vu), LIMITS, 0.05)
        # Progress along the line to the target never passes it by more than a metre.
        along = (s.east_m * east + s.north_m * north) / start_dist if start_dist > 1 else 0.0
        worst = max(worst, along - start_dist)
    assert math.hypot(s.east_m - east, s.north_m - north) < 0.5
    assert s.up_m == pytest.approx(up, abs=0.5)
    assert worst < 1.0
    assert s.ground_speed_m_s <= 12.0 + 1e-9


def test_attitude_tilts_into_acceleration() -> None:
    s = step(AIR, VelocityCommand(0.0, 10.0, 0.0, yaw_deg=0.0), LIMITS, 0.1)
    roll, pitch, yaw = attitude_rad(s)
    assert pitch == pytest.approx(-math.atan2(4.0, 9.81))
    assert roll == pytest.approx(0.0, abs=1e-12) and yaw == pytest.approx(0.0)


def test_limits_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_speed_m_s"):
        Limits(max_speed_m_s=0.0)
