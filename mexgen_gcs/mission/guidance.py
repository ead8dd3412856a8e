"""Guidance: from a chosen heading to a velocity setpoint, with the area guard.

Frames: positions and velocities in local ENU metres (m/s) about home; setpoints leave in
MAVLink NED (north, east, down) m/s with a compass yaw in degrees.

The guard keeps the vehicle inside the search area, so that the geofence (the area plus
``safety.geofence_margin_m``) is never touched in a normal mission. It looks at where the
vehicle would come to rest: the stopping point ``p + v * reaction_s + v_hat * |v|^2 / (2 a)``
with ``a`` the braking the autopilot allows (``min(flight.max_accel_m_s2, 3 m/s^2)``, PX4's
MPC_ACC_HOR default) and ``reaction_s`` the time before a new setpoint takes effect.
- If the stopping point of the CURRENT velocity (or the vehicle itself) is outside the area,
  it steers straight back toward the area centre (``guard``): reversing at the same
  acceleration goes no further out than braking would.
- Else, if the planner's heading would put the stopping point outside, it flies the heading
  closest to the planner's whose stopping point stays inside (``edge``: sliding along the
  boundary), or toward the centre if none does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.geo import enu_to_heading_deg, heading_to_enu_unit

PX4_MPC_ACC_HOR_M_S2 = 3.0
"""PX4's default horizontal acceleration limit: the braking a mission can count on."""
REACTION_S = 0.5
"""Telemetry and command latency before a new setpoint acts (plus one setpoint period)."""
_DEVIATIONS_DEG = np.concatenate([[0.0], np.repeat(np.arange(15.0, 181.0, 15.0), 2)
                                  * np.tile([1.0, -1.0], 12)])


@dataclass(frozen=True, slots=True)
class Setpoint:
    v_north_m_s: float
    v_east_m_s: float
    v_down_m_s: float
    yaw_deg: float
    reason: str
    """fly | hold | edge (sliding along the boundary) | guard (steering back toward the
    area centre)."""


def altitude_rate_m_s(alt_m: float, target_alt_m: float, gain: float = 0.5,
                      limit_m_s: float = 2.0) -> float:
    """NED down-velocity that brings the relative altitude to the target (P control)."""
    if not math.isfinite(alt_m):
        return 0.0
    return float(np.clip(gain * (alt_m - target_alt_m), -limit_m_s, limit_m_s))


def stopping_point(xy_m: np.ndarray, v_en_m_s: np.ndarray, brake_m_s2: float,
                   reaction_s: float) -> np.ndarray:
    """Where a vehicle at (..., 2) positions with (..., 2) ENU velocities comes to rest when it
    starts braking at `brake_m_s2` after `reaction_s`."""
    v = np.asarray(v_en_m_s, dtype=np.float64)
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.asarray(xy_m) + v * reaction_s + v * speed / (2.0 * brake_m_s2)


def velocity_setpoint(
    heading_deg: float | None,
    speed_m_s: float,
    vehicle_en_m: tuple[float, float],
    alt_m: float,
    target_alt_m: float,
    area: SearchArea,
    yaw_deg: float,
    velocity_en_m_s: tuple[float, float] = (0.0, 0.0),
    *,
    brake_m_s2: float = PX4_MPC_ACC_HOR_M_S2,
    reaction_s: float = REACTION_S,
) -> Setpoint:
    """Fly `heading_deg` at `speed_m_s`; `None` holds position (zero velocity, keep yaw);
    the guard (module docstring) overrides either to stay inside the area."""
    vd = altitude_rate_m_s(alt_m, target_alt_m)
    xy = np.asarray(vehicle_en_m, dtype=np.float64)
    v = np.asarray(velocity_en_m_s, dtype=np.float64)
    stop = stopping_point(xy, v, brake_m_s2, reaction_s)
    if float(area.distance_outside_m(np.stack([xy, stop])).max()) > 0.0:
        return _along(_to_centre_deg(area, xy), speed_m_s, vd, "guard")
    if heading_deg is None:
        return Setpoint(0.0, 0.0, vd, yaw_deg, "hold")
    candidates = (heading_deg + _DEVIATIONS_DEG) % 360.0
    v_cand = speed_m_s * heading_to_enu_unit(candidates)
    inside = area.distance_outside_m(stopping_point(xy, v_cand, brake_m_s2, reaction_s)) == 0.0
    if inside[0]:
        return _along(heading_deg, speed_m_s, vd, "fly")
    if inside.any():
        return _along(float(candidates[int(np.argmax(inside))]), speed_m_s, vd, "edge")
    return _along(_to_centre_deg(area, xy), speed_m_s, vd, "guard")


def _to_centre_deg(area: SearchArea, xy: np.ndarray) -> float:
    to_centre = area.centre_m - xy
    return float(enu_to_heading_deg(to_centre[0], to_centre[1]))


def _along(heading_deg: float, speed_m_s: float, vd: float, reason: str) -> Setpoint:
    h = math.radians(heading_deg)
    return Setpoint(speed_m_s * math.cos(h), speed_m_s * math.sin(h), vd, heading_deg % 360.0,
                    reason)
