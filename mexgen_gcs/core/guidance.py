"""Guidance: from a chosen heading to a velocity setpoint, with the area guard.

Frames: positions and velocities in local ENU metres (m/s) about home; setpoints leave in
MAVLink NED (north, east, down) m/s with a compass yaw in degrees.

The guard keeps the vehicle inside the search area, so that the geofence (the area plus
``safety.geofence_margin_m``) is never touched in a normal mission. For every candidate
velocity command it predicts where the vehicle would come to rest if that command were the
last before braking: the current velocity carries on for ``latency_s`` (telemetry and command
latency), then the velocity moves toward the command at the acceleration limit ``a`` for
``period_s`` (until the next command), then it brakes at ``a``; ``a`` is what the autopilot
allows (``min(flight.max_accel_m_s2, 3 m/s^2)``, PX4's MPC_ACC_HOR default). The planner's
heading is flown (``fly``) if that stopping point stays inside the area; else the heading
closest to it that stays inside (``edge``: sliding along the boundary); else whichever of
those, braking or heading for the centre goes least far out (``guard``). Since every command
keeps a stop inside possible, the vehicle stays inside the area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mexgen_gcs.core.area import SearchArea, polygon_distances
from mexgen_gcs.core.geo import enu_to_heading_deg, heading_to_enu_unit
from mexgen_gcs.core.jit import kernel

PX4_MPC_ACC_HOR_M_S2 = 3.0
"""PX4's default horizontal acceleration limit: the braking a mission can count on."""
LATENCY_S = 0.3
"""Telemetry and command latency before a new setpoint starts to act (vehicle seconds)."""
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


def predicted_excursion_m(area: SearchArea, xy_m: np.ndarray, v_en_m_s: np.ndarray,
                          commands_en_m_s: np.ndarray, accel_m_s2: float, latency_s: float,
                          period_s: float) -> np.ndarray:
    """(K,) how far outside the area the vehicle at `xy_m` with velocity `v_en_m_s` would get
    for each of the (K, 2) velocity commands, if it braked after the next one (see the module
    docstring); 0 where it stays inside. One compiled call (`_excursions`): the guidance asks
    it of ~27 commands at every setpoint, where numpy's per-call cost was most of the
    experiment runner's world time."""
    u = np.ascontiguousarray(commands_en_m_s, dtype=np.float64).reshape(-1, 2)
    return _excursions(np.asarray(xy_m, dtype=np.float64), np.asarray(v_en_m_s, np.float64),
                       u, float(accel_m_s2), float(latency_s), float(period_s),
                       area.vertices_m)


@kernel
def _excursions(xy: np.ndarray, v: np.ndarray, u: np.ndarray, accel: float, latency_s: float,
                period_s: float, vertices: np.ndarray) -> np.ndarray:
    """:func:`predicted_excursion_m`: for each command u[k], the position p1 after the next
    period (velocity ramping toward u at ``accel``) and the rest point after braking from
    there (:func:`stopping_point` with no reaction time); the farther outside of the two."""
    k_cmd = u.shape[0]
    pts = np.empty((2 * k_cmd, 2))
    vx, vy = v[0], v[1]
    p0x, p0y = xy[0] + vx * latency_s, xy[1] + vy * latency_s
    for k in range(k_cmd):
        dx, dy = u[k, 0] - vx, u[k, 1] - vy
        gap = np.sqrt(dx * dx + dy * dy)
        ux, uy = (dx / gap, dy / gap) if gap > 1e-9 else (0.0, 0.0)
        ramp = min(gap / accel, period_s)  # time spent accelerating toward u
        v1x, v1y = vx + ux * accel * ramp, vy + uy * accel * ramp
        rest = period_s - ramp
        p1x = p0x + vx * ramp + 0.5 * ux * accel * ramp * ramp + v1x * rest
        p1y = p0y + vy * ramp + 0.5 * uy * accel * ramp * ramp + v1y * rest
        speed = np.sqrt(v1x * v1x + v1y * v1y)
        pts[k, 0], pts[k, 1] = p1x, p1y
        pts[k_cmd + k, 0] = p1x + v1x * speed / (2.0 * accel)
        pts[k_cmd + k, 1] = p1y + v1y * speed / (2.0 * accel)
    dist = np.empty(2 * k_cmd)
    polygon_distances(pts, vertices, True, np.empty(2 * k_cmd, np.bool_), dist)
    out = np.empty(k_cmd)
    for k in range(k_cmd):
        out[k] = max(dist[k], dist[k_cmd + k])
    return out


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
    latency_s: float = LATENCY_S,
    period_s: float = 0.05,
) -> Setpoint:
    """Fly `heading_deg` at `speed_m_s`; `None` holds position (zero velocity, keep yaw);
    the guard (module docstring) bends or overrides either to stay inside the area.
    `period_s`: vehicle seconds until the next setpoint."""
    vd = altitude_rate_m_s(alt_m, target_alt_m)
    xy = np.asarray(vehicle_en_m, dtype=np.float64)
    v = np.asarray(velocity_en_m_s, dtype=np.float64)
    centre_deg = _to_centre_deg(area, xy)
    if heading_deg is None:
        headings = np.array([centre_deg])
        commands = np.zeros((2, 2))
        commands[1] = speed_m_s * heading_to_enu_unit(centre_deg)
    else:
        headings = np.concatenate([(heading_deg + _DEVIATIONS_DEG) % 360.0, [centre_deg]])
        commands = np.vstack([speed_m_s * heading_to_enu_unit(headings), np.zeros((1, 2))])
    out = predicted_excursion_m(area, xy, v, commands, brake_m_s2, latency_s, period_s)
    if heading_deg is None:
        if out[0] == 0.0:
            return Setpoint(0.0, 0.0, vd, yaw_deg, "hold")
    else:
        inside = out[: len(_DEVIATIONS_DEG)] == 0.0
        if inside[0]:
            return _along(heading_deg, speed_m_s, vd, "fly")
        if inside.any():
            return _along(float(headings[int(np.argmax(inside))]), speed_m_s, vd, "edge")
    # nothing keeps it inside: the command that goes least far out (ties: brake first)
    last = len(commands) - 1
    best = int(np.argmin(out[::-1]))
    best = last - best
    if not np.any(commands[best]):
        return Setpoint(0.0, 0.0, vd, yaw_deg, "guard")
    h = centre_deg if heading_deg is None else float(headings[best])
    return _along(h, speed_m_s, vd, "guard")


def _to_centre_deg(area: SearchArea, xy: np.ndarray) -> float:
    to_centre = area.centre_m - xy
    return float(enu_to_heading_deg(to_centre[0], to_centre[1]))


def _along(heading_deg: float, speed_m_s: float, vd: float, reason: str) -> Setpoint:
    h = math.radians(heading_deg)
    return Setpoint(speed_m_s * math.cos(h), speed_m_s * math.sin(h), vd, heading_deg % 360.0,
                    reason)
