"""MAVLink telemetry messages of the simulated PX4 quadrotor, built from the autopilot state.

Frames: the autopilot works in local ENU about the mission home; MAVLink wants NED
(north, east, down) for local position and velocities, WGS84 lat/lon * 1e7 and millimetres
AMSL for global position. Conversions happen here and nowhere else.
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.core.geo import LocalFrame
from sim import px4_modes as modes
from sim.autopilot import Autopilot
from sim.clock import SimClock
from sim.kinematics import attitude_rad

_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)

CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
)

#: PX4 v1.17.0 release, FIRMWARE_VERSION_TYPE_OFFICIAL.
FLIGHT_SW_VERSION = (1 << 24) | (17 << 16) | (0 << 8) | 255
CELLS = 4


def _cdeg(yaw_deg: float) -> int:
    return round(yaw_deg * 100.0) % 36000


class TelemetryBuilder:
    """Builds each telemetry message on demand from the autopilot's current state."""

    def __init__(self, mav: mavlink.MAVLink, autopilot: Autopilot, clock: SimClock,
                 frame: LocalFrame) -> None:
        self.mav = mav
        self.ap = autopilot
        self.clock = clock
        self.frame = frame
        self._statustext_id = 0

    def geodetic(self, east_m: float, north_m: float, up_m: float) -> tuple[float, float, float]:
        lat, lon, alt = self.frame.to_geodetic(east_m, north_m, up_m)
        return float(lat), float(lon), float(alt)

    def home_geodetic(self) -> tuple[float, float, float]:
        return self.geodetic(*self.ap.home_enu_m)

    def vehicle_geodetic(self) -> tuple[float, float, float]:
        s = self.ap.state
        return self.geodetic(s.east_m, s.north_m, s.up_m)

    # -- messages -------------------------------------------------------------------------

    def heartbeat(self) -> Any:
        ap = self.ap
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if ap.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        main = ap.mode[0]
        # As PX4's HEARTBEAT stream: AUTO|GUIDED|STABILIZE in auto modes, STABILIZE only in
        # offboard, MANUAL_INPUT|STABILIZE in the position/altitude modes.
        if main == modes.MainMode.AUTO:
            base |= (mavlink.MAV_MODE_FLAG_AUTO_ENABLED | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
                     | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED)
        elif main == modes.MainMode.OFFBOARD:
            base |= mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        elif main in (modes.MainMode.POSCTL, modes.MainMode.ALTCTL):
            base |= (mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
                     | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED)
        if not ap.armed:
            status = mavlink.MAV_STATE_STANDBY
        else:  # PX4: CRITICAL while a failsafe action is in charge
            status = mavlink.MAV_STATE_CRITICAL if ap.failsafe else mavlink.MAV_STATE_ACTIVE
        return self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, modes.encode(ap.mode),
            status, 3)

    def sys_status(self) -> Any:
        ap = self.ap
        health = _SENSORS
        if not ap.gps_ok:
            health &= ~(mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_PREARM_CHECK)
        if ap.battery_fraction <= ap.params["BAT_CRIT_THR"]:
            health &= ~(mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
                        | mavlink.MAV_SYS_STATUS_PREARM_CHECK)
        volts_mv, current_ca, remaining = self._battery_numbers()
        return self.mav.sys_status_encode(
            _SENSORS, _SENSORS, health, 250, volts_mv, current_ca, remaining,
            0, 0, 0, 0, 0, 0)

    def _battery_numbers(self) -> tuple[int, int, int]:
        frac = self.ap.battery_fraction
        volts = CELLS * (3.5 + 0.7 * frac)
        current_a = 18.0 if self.ap.armed else 0.5
        return int(volts * 1000.0), int(current_a * 100.0), round(frac * 100.0)

    def global_position_int(self) -> Any:
        s = self.ap.state
        lat, lon, alt = self.vehicle_geodetic()
        return self.mav.global_position_int_encode(
            self.clock.time_boot_ms(), round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0),
            round((s.up_m - self.ap.home_enu_m[2]) * 1000.0),
            round(s.v_north_m_s * 100.0), round(s.v_east_m_s * 100.0),
            round(-s.v_up_m_s * 100.0), _cdeg(s.yaw_deg))

    def local_position_ned(self) -> Any:
        s = self.ap.state
        return self.mav.local_position_ned_encode(
            self.clock.time_boot_ms(), s.north_m, s.east_m, -s.up_m,
            s.v_north_m_s, s.v_east_m_s, -s.v_up_m_s)

    def attitude(self) -> Any:
        roll, pitch, yaw = attitude_rad(self.ap.state)
        return self.mav.attitude_encode(
            self.clock.time_boot_ms(), roll, pitch, yaw, 0.0, 0.0,
            math.radians(self.ap.state.yaw_rate_deg_s))

    def gps_raw_int(self) -> Any:
        s = self.ap.state
        # A GPS's UTC time; PX4 SIH's GPS has none and sends time since boot instead.
        usec = int((self.clock.sim_s if self.clock.system_time == "host" else self.clock.unix())
                   * 1e6)
        if not self.ap.gps_ok:
            return self.mav.gps_raw_int_encode(usec, mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0,
                                               65535, 65535, 65535, 65535, 0)
        lat, lon, alt = self.vehicle_geodetic()
        cog = math.degrees(math.atan2(s.v_east_m_s, s.v_north_m_s)) % 360.0
        return self.mav.gps_raw_int_encode(
            usec, mavlink.GPS_FIX_TYPE_3D_FIX, round(lat * 1e7), round(lon * 1e7),
            round(alt * 1000.0), 70, 110, round(s.ground_speed_m_s * 100.0), _cdeg(cog), 14)

    def home_position(self) -> Any:
        lat, lon, alt = self.home_geodetic()
        he, hn, hu = self.ap.home_enu_m
        # time_usec: when home was set, microseconds since boot (PX4 sends its hrt time).
        return self.mav.home_position_encode(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0), hn, he, -hu,
            [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, int(self.ap.home_set_sim_s * 1e6))

    def extended_sys_state(self) -> Any:
        return self.mav.extended_sys_state_encode(
            mavlink.MAV_VTOL_STATE_UNDEFINED, int(self.ap.landed_state))

    def battery_status(self) -> Any:
        ap = self.ap
        volts_mv, current_ca, remaining = self._battery_numbers()
        p = ap.params
        frac = ap.battery_fraction
        charge = (mavlink.MAV_BATTERY_CHARGE_STATE_EMERGENCY if frac <= p["BAT_EMERGEN_THR"]
                  else mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL if frac <= p["BAT_CRIT_THR"]
                  else mavlink.MAV_BATTERY_CHARGE_STATE_LOW if frac <= p["BAT_LOW_THR"]
                  else mavlink.MAV_BATTERY_CHARGE_STATE_OK)
        voltages = [volts_mv] + [65535] * 9
        consumed_mah = int((1.0 - frac) * 5000.0)
        time_remaining_s = int(frac * ap.battery_endurance_s)
        return self.mav.battery_status_encode(
            0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767, voltages,
            current_ca, consumed_mah, -1, remaining, time_remaining_s, charge)

    def system_time(self) -> Any:
        return self.mav.system_time_encode(int(self.clock.system_time_unix() * 1e6),
                                           self.clock.time_boot_ms())

    def vfr_hud(self) -> Any:
        s = self.ap.state
        _, _, alt = self.vehicle_geodetic()
        throttle = 50 if self.ap.armed and self.ap.in_air else 0
        return self.mav.vfr_hud_encode(s.ground_speed_m_s, s.ground_speed_m_s,
                                       int(s.yaw_deg) % 360, throttle, alt, s.v_up_m_s)

    def autopilot_version(self, sysid: int) -> Any:
        return self.mav.autopilot_version_encode(
            CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
            0x5349_4D00 + sysid)

    def statustext(self, text: str, severity: int) -> list[Any]:
        """As PX4: texts longer than 50 bytes go in 50-byte chunks (``chunk_seq`` 0, 1, ...)
        sharing one ``id``; a text of exactly 50 bytes or less is one message."""
        data = text.encode("ascii", "replace")
        self._statustext_id = (self._statustext_id + 1) & 0xFFFF
        return [self.mav.statustext_encode(severity, data[i:i + 50], self._statustext_id, seq)
                for seq, i in enumerate(range(0, max(len(data), 1), 50))]

    def by_id(self) -> dict[int, Any]:
        """Message id -> zero-argument builder, for the scheduler and REQUEST_MESSAGE."""
        return {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: self.system_time,
            mavlink.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
        }
