"""Multirotor point-mass kinematics: velocity-setpoint tracking with bounded acceleration.

Frame: local ENU metres about home (x east, y north, z up = height above home). Yaw is a
compass heading in degrees (0 north, 90 east, clockwise). MAVLink's NED conversion happens at
the MAVLink boundary, not here.

The airframe follows a commanded velocity: horizontally the velocity error is closed at most
at ``max_accel_m_s2`` (as a vector) and the speed is capped at ``max_speed_m_s``; vertically
the climb and descent rates are bounded separately with their own acceleration bound; yaw
turns towards its setpoint at most at ``max_yaw_rate_deg_s``. The ground (z = 0) stops
descent. A position controller (``velocity_towards``) turns a target point into a velocity
command that stops on the point without overshoot. All functions are pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass(frozen=True, slots=True)
class Limits:
    """Airframe and controller limits (the paper's multirotor by default)."""

    max_speed_m_s: float = 15.0
    max_accel_m_s2: float = 4.0
    max_climb_m_s: float = 3.0
    max_descent_m_s: float = 1.5
    max_vert_accel_m_s2: float = 3.0
    max_yaw_rate_deg_s: float = 90.0

    def __post_init__(self) -> None:
        for name in ("max_speed_m_s", "max_accel_m_s2", "max_climb_m_s", "max_descent_m_s",
                     "max_vert_accel_m_s2", "max_yaw_rate_deg_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0")


@dataclass(frozen=True, slots=True)
class KinematicState:
    """Point-mass state in ENU; ``accel_*`` is the last step's acceleration (for attitude)."""

    east_m: float = 0.0
    north_m: float = 0.0
    up_m: float = 0.0
    v_east_m_s: float = 0.0
    v_north_m_s: float = 0.0
    v_up_m_s: float = 0.0
    yaw_deg: float = 0.0
    yaw_rate_deg_s: float = 0.0
    accel_east_m_s2: float = 0.0
    accel_north_m_s2: float = 0.0

    @property
    def ground_speed_m_s(self) -> float:
        return math.hypot(self.v_east_m_s, self.v_north_m_s)

    @property
    def on_ground(self) -> bool:
        return self.up_m <= 0.0


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """Commanded ENU velocity plus either an absolute yaw or a yaw rate (or neither)."""

    v_east_m_s: float = 0.0
    v_north_m_s: float = 0.0
    v_up_m_s: float = 0.0
    yaw_deg: float | None = None
    yaw_rate_deg_s: float | None = None


def wrap_180(angle_deg: float) -> float:
    """Wrap to [-180, 180)."""
    return (angle_deg + 180.0) % 360.0 - 180.0


def _approach(value: float, target: float, max_delta: float) -> float:
    return value + max(-max_delta, min(max_delta, target - value))


def step(state: KinematicState, cmd: VelocityCommand, limits: Limits, dt_s: float
         ) -> KinematicState:
    """Advance ``dt_s`` seconds tracking ``cmd``; cost O(1). ``dt_s`` should be <= ~0.1 s."""
    if dt_s <= 0.0:
        return state
    # Horizontal: accel-limited vector tracking of the (speed-capped) command.
    ce, cn = cmd.v_east_m_s, cmd.v_north_m_s
    speed = math.hypot(ce, cn)
    if speed > limits.max_speed_m_s:
        ce, cn = ce * limits.max_speed_m_s / speed, cn * limits.max_speed_m_s / speed
    de, dn = ce - state.v_east_m_s, cn - state.v_north_m_s
    dv = math.hypot(de, dn)
    max_dv = limits.max_accel_m_s2 * dt_s
    if dv > max_dv:
        de, dn = de * max_dv / dv, dn * max_dv / dv
    ve, vn = state.v_east_m_s + de, state.v_north_m_s + dn
    # Vertical: bounded climb/descent rate and vertical acceleration.
    cu = max(-limits.max_descent_m_s, min(limits.max_climb_m_s, cmd.v_up_m_s))
    vu = _approach(state.v_up_m_s, cu, limits.max_vert_accel_m_s2 * dt_s)
    # Trapezoidal position integration.
    east = state.east_m + 0.5 * (state.v_east_m_s + ve) * dt_s
    north = state.north_m + 0.5 * (state.v_north_m_s + vn) * dt_s
    up = state.up_m + 0.5 * (state.v_up_m_s + vu) * dt_s
    if up <= 0.0:
        up = 0.0
        vu = max(vu, 0.0)
        if state.up_m <= 0.0 and cu <= 0.0:  # resting on the ground: no sliding
            ve = vn = 0.0
            east, north = state.east_m, state.north_m
    # Yaw.
    max_dyaw = limits.max_yaw_rate_deg_s * dt_s
    if cmd.yaw_deg is not None and math.isfinite(cmd.yaw_deg):
        dyaw = max(-max_dyaw, min(max_dyaw, wrap_180(cmd.yaw_deg - state.yaw_deg)))
    elif cmd.yaw_rate_deg_s is not None and math.isfinite(cmd.yaw_rate_deg_s):
        dyaw = max(-max_dyaw, min(max_dyaw, cmd.yaw_rate_deg_s * dt_s))
    else:
        dyaw = 0.0
    return replace(
        state,
        east_m=east, north_m=north, up_m=up,
        v_east_m_s=ve, v_north_m_s=vn, v_up_m_s=vu,
        yaw_deg=(state.yaw_deg + dyaw) % 360.0,
        yaw_rate_deg_s=dyaw / dt_s,
        accel_east_m_s2=(ve - state.v_east_m_s) / dt_s,
        accel_north_m_s2=(vn - state.v_north_m_s) / dt_s,
    )


def velocity_towards(
    state: KinematicState,
    target_east_m: float,
    target_north_m: float,
    target_up_m: float,
    limits: Limits,
    speed_m_s: float | None = None,
    gain_per_s: float = 1.0,
) -> tuple[float, float, float]:
    """ENU velocity command that brings the vehicle to the target point and stops there.

    Horizontal speed is min(speed_m_s, limits.max_speed_m_s, sqrt(2 a d), gain * d): the
    square-root term is the braking profile, the linear term settles the last metres.
    """
    cruise = limits.max_speed_m_s if speed_m_s is None else min(speed_m_s, limits.max_speed_m_s)
    de, dn = target_east_m - state.east_m, target_north_m - state.north_m
    dist = math.hypot(de, dn)
    if dist < 1e-6:
        ve = vn = 0.0
    else:
        brake = math.sqrt(2.0 * 0.8 * limits.max_accel_m_s2 * dist)
        v = min(cruise, brake, gain_per_s * dist)
        ve, vn = de / dist * v, dn / dist * v
    du = target_up_m - state.up_m
    vu_mag = min(math.sqrt(2.0 * 0.8 * limits.max_vert_accel_m_s2 * abs(du)),
                 gain_per_s * abs(du))
    vu = math.copysign(vu_mag, du)
    vu = max(-limits.max_descent_m_s, min(limits.max_climb_m_s, vu))
    return ve, vn, vu


def attitude_rad(state: KinematicState, gravity_m_s2: float = 9.81) -> tuple[float, float, float]:
    """(roll, pitch, yaw) radians from the horizontal acceleration (tilt to accelerate).

    Pitch is nose-down negative when accelerating forwards (aerospace convention).
    """
    yaw = math.radians(state.yaw_deg)
    # Body-frame acceleration: forward along the heading, right 90 deg clockwise of it.
    a_fwd = state.accel_east_m_s2 * math.sin(yaw) + state.accel_north_m_s2 * math.cos(yaw)
    a_right = state.accel_east_m_s2 * math.cos(yaw) - state.accel_north_m_s2 * math.sin(yaw)
    pitch = -math.atan2(a_fwd, gravity_m_s2)
    roll = math.atan2(a_right, gravity_m_s2)
    yaw_wrapped = math.radians(wrap_180(state.yaw_deg))
    return roll, pitch, yaw_wrapped
