"""Guidance of the automatic modes: where to stop, how to descend, the RTL phases.

Frame: local ENU metres about home (z up = height above the flat ground). Pure functions and
one small state machine; the autopilot decides which applies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim import px4_texts as texts
from sim.kinematics import KinematicState, Limits, VelocityCommand, velocity_towards


def stopping_point(s: KinematicState, lim: Limits, in_air: bool) -> tuple[float, float, float]:
    """Where the vehicle comes to rest braking at its limits (PX4 holds there, not behind)."""
    k = 1.0 / (2.0 * lim.max_accel_m_s2)
    v = s.ground_speed_m_s
    up = s.up_m + s.v_up_m_s * abs(s.v_up_m_s) / (2.0 * lim.max_vert_accel_m_s2)
    return (s.east_m + s.v_east_m_s * v * k, s.north_m + s.v_north_m_s * v * k,
            max(up, 0.0) if in_air else 0.0)


def descend(s: KinematicState, east_m: float, north_m: float, lim: Limits,
            land_speed_m_s: float, land_alt_m: float) -> VelocityCommand:
    """Hold (east, north) and descend: at the descent limit, then ``land_speed_m_s`` below
    ``land_alt_m`` (PX4's MPC_LAND_SPEED / MPC_LAND_ALT2)."""
    ve, vn, _ = velocity_towards(s, east_m, north_m, s.up_m, lim)
    rate = land_speed_m_s if s.up_m <= land_alt_m else lim.max_descent_m_s
    return VelocityCommand(ve, vn, -rate)


@dataclass
class ReturnToLaunch:
    """PX4 RTL: brake and climb to ``alt_m`` (RTL_RETURN_ALT or higher if already higher),
    fly home at ``speed_m_s`` facing home, then land there."""

    home_east_m: float
    home_north_m: float
    alt_m: float
    phase: str = "climb"  # climb | return | land
    _climb_xy: tuple[float, float] | None = None

    def command(self, s: KinematicState, lim: Limits, speed_m_s: float, land_speed_m_s: float,
                land_alt_m: float) -> tuple[VelocityCommand, str | None]:
        """The velocity command now, and a message when the phase changes."""
        message = None
        he, hn = self.home_east_m, self.home_north_m
        if self.phase == "climb":
            if s.up_m >= self.alt_m - 0.5:
                self.phase = "return"  # PX4 announced the return when RTL started
            else:
                if self._climb_xy is None:
                    self._climb_xy = stopping_point(s, lim, True)[:2]
                ve, vn, vu = velocity_towards(s, *self._climb_xy, self.alt_m, lim)
                return VelocityCommand(ve, vn, vu), None
        if self.phase == "return":
            dist = math.hypot(he - s.east_m, hn - s.north_m)
            if dist < 1.0 and s.ground_speed_m_s < 0.5:
                self.phase, message = "land", texts.RTL_LAND
            else:
                ve, vn, vu = velocity_towards(s, he, hn, self.alt_m, lim, speed_m_s=speed_m_s)
                yaw = math.degrees(math.atan2(he - s.east_m, hn - s.north_m)) \
                    if dist > 5.0 else None
                return VelocityCommand(ve, vn, vu, yaw_deg=yaw), message
        return descend(s, he, hn, lim, land_speed_m_s, land_alt_m), message
