"""Offboard setpoint messages (SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT) -> ENU setpoints.

MAVLink sends NED (north, east, down), body frames (forward, right, down) and WGS84; the
autopilot flies local ENU metres about home (x east, y north, z up). Position or velocity
setpoints are flown (with yaw or yaw rate); acceleration/force-only ones are "unsupported",
and non-finite or out-of-range values "invalid" (both are ignored, as PX4 ignores them).
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.core.geo import LocalFrame
from sim.autopilot import Setpoint
from sim.kinematics import KinematicState

Parsed = Setpoint | Literal["invalid", "unsupported", "frame"]

_POSITION_BITS = 0b111
_VELOCITY_BITS = 0b111000
_IGNORE_YAW = 1024
_IGNORE_YAW_RATE = 2048
_BODY = {mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED, mavlink.MAV_FRAME_BODY_FRD}
_LOCAL = {mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_OFFSET_NED}
_AMSL = {mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT}


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _yaw(mask: int, yaw_rad: float, yaw_rate_rad_s: float) -> tuple[float | None, float | None]:
    yaw = None if mask & _IGNORE_YAW or not math.isfinite(yaw_rad) else math.degrees(yaw_rad)
    rate = (None if mask & _IGNORE_YAW_RATE or not math.isfinite(yaw_rate_rad_s)
            else math.degrees(yaw_rate_rad_s))
    return yaw, rate


def _body_to_ned(forward: float, right: float, yaw_deg: float) -> tuple[float, float]:
    yaw = math.radians(yaw_deg)
    return (forward * math.cos(yaw) - right * math.sin(yaw),
            forward * math.sin(yaw) + right * math.cos(yaw))


def from_local_ned(msg: Any, state: KinematicState) -> Parsed:
    """SET_POSITION_TARGET_LOCAL_NED (origin = home, the EKF origin) -> Setpoint."""
    mask, frame = int(msg.type_mask), int(msg.coordinate_frame)
    if frame not in _LOCAL and frame not in _BODY:
        return "frame"
    yaw, rate = _yaw(mask, msg.yaw, msg.yaw_rate)
    body = frame in _BODY
    if not mask & _POSITION_BITS:
        n, e, d = float(msg.x), float(msg.y), float(msg.z)
        if not _finite(n, e, d):
            return "invalid"
        if body:
            n, e = _body_to_ned(n, e, state.yaw_deg)
        if frame != mavlink.MAV_FRAME_LOCAL_NED:  # offsets from the vehicle
            n, e, d = n + state.north_m, e + state.east_m, d - state.up_m
        return Setpoint(position_enu_m=(e, n, -d), yaw_deg=yaw, yaw_rate_deg_s=rate)
    if not mask & _VELOCITY_BITS:
        vn, ve, vd = float(msg.vx), float(msg.vy), float(msg.vz)
        if not _finite(vn, ve, vd):
            return "invalid"
        if body:
            vn, ve = _body_to_ned(vn, ve, state.yaw_deg)
        return Setpoint(velocity_enu_m_s=(ve, vn, -vd), yaw_deg=yaw, yaw_rate_deg_s=rate)
    return "unsupported"


def from_global_int(msg: Any, frame: LocalFrame, home_up_m: float) -> Parsed:
    """SET_POSITION_TARGET_GLOBAL_INT -> Setpoint (terrain frames: the ground is flat)."""
    mask = int(msg.type_mask)
    yaw, rate = _yaw(mask, msg.yaw, msg.yaw_rate)
    if not mask & _POSITION_BITS:
        lat, lon, alt = msg.lat_int / 1e7, msg.lon_int / 1e7, float(msg.alt)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and math.isfinite(alt)):
            return "invalid"
        if int(msg.coordinate_frame) in _AMSL:
            e, n, u = frame.to_enu(lat, lon, alt)
        else:  # relative-altitude and terrain frames
            e, n, _ = frame.to_enu(lat, lon, frame.alt0_m)
            u = alt + home_up_m  # type: ignore[assignment]  # a float where to_enu gives arrays
        return Setpoint(position_enu_m=(float(e), float(n), float(u)), yaw_deg=yaw,
                        yaw_rate_deg_s=rate)
    if not mask & _VELOCITY_BITS:
        vn, ve, vd = float(msg.vx), float(msg.vy), float(msg.vz)
        if not _finite(vn, ve, vd):
            return "invalid"
        return Setpoint(velocity_enu_m_s=(ve, vn, -vd), yaw_deg=yaw, yaw_rate_deg_s=rate)
    return "unsupported"
