"""Guidance: from a chosen heading to a velocity setpoint, with the area guard.

Frames: positions in local ENU metres about home; setpoints leave in MAVLink NED
(north, east, down) m/s with a compass yaw in degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.geo import enu_to_heading_deg


@dataclass(frozen=True, slots=True)
class Setpoint:
    v_north_m_s: float
    v_east_m_s: float
    v_down_m_s: float
    yaw_deg: float
    reason: str
    """fly | hold | guard (steering back inside the area)."""


def altitude_rate_m_s(alt_m: float, target_alt_m: float, gain: float = 0.5,
                      limit_m_s: float = 2.0) -> float:
    """NED down-velocity that brings the relative altitude to the target (P control)."""
    if not math.isfinite(alt_m):
        return 0.0
    return float(np.clip(gain * (alt_m - target_alt_m), -limit_m_s, limit_m_s))


def velocity_setpoint(
    heading_deg: float | None,
    speed_m_s: float,
    vehicle_en_m: tuple[float, float],
    alt_m: float,
    target_alt_m: float,
    area: SearchArea,
    yaw_deg: float,
    guard_margin_m: float = 0.0,
) -> Setpoint:
    """Fly `heading_deg` at `speed_m_s`; `None` holds position (zero velocity, keep yaw).

    Guard: when the vehicle is outside the area (by more than `guard_margin_m`), it steers
    straight back toward the area centre whatever the planner chose.
    """
    vd = altitude_rate_m_s(alt_m, target_alt_m)
    xy = np.asarray(vehicle_en_m, dtype=np.float64)
    if float(area.distance_outside_m(xy)) > guard_margin_m:
        to_centre = area.centre_m - xy
        h = float(enu_to_heading_deg(to_centre[0], to_centre[1]))
        return _along(h, speed_m_s, vd, "guard")
    if heading_deg is None:
        return Setpoint(0.0, 0.0, vd, yaw_deg, "hold")
    return _along(heading_deg, speed_m_s, vd, "fly")


def _along(heading_deg: float, speed_m_s: float, vd: float, reason: str) -> Setpoint:
    h = math.radians(heading_deg)
    return Setpoint(speed_m_s * math.cos(h), speed_m_s * math.sin(h), vd, heading_deg % 360.0,
                    reason)
