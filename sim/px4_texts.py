"""PX4's own STATUSTEXT wordings, so that a GCS sees from the simulator what PX4 sends.

Taken from PX4 main (2026-03) ``src/modules/commander`` and ``src/modules/navigator``. A
trailing tab is part of PX4's text: it marks a message that also exists as a MAVLink event
(QGroundControl then shows the event instead); a GCS that logs STATUSTEXT should strip it.
PX4 says nothing when the mode changes (HEARTBEAT shows it), so neither does the simulator.
Severities are MAV_SEVERITY: 2 critical (``mavlink_log_critical``), 6 info.
"""

from __future__ import annotations

CRITICAL = 2
WARNING = 4
INFO = 6

ARMED = "Armed by external command\t"
DISARMED_BY_COMMAND = "Disarmed by external command\t"
DISARMED_LANDING = "Disarmed by landing\t"
DISARMED_PREFLIGHT = "Disarmed by auto preflight disarming\t"
DISARM_DENIED_IN_AIR = "Disarming denied: not landed\t"
ARM_DENIED_HEALTH = "Arming denied: Resolve system health failures first\t"
PREFLIGHT_GPS = "Preflight Fail: GPS fix too low"
TAKEOFF_DETECTED = "Takeoff detected\t"
LANDING_DETECTED = "Landing detected\t"
RETURNING = "Returning to launch\t"
LANDING_HERE = "Landing at current position\t"
FAILSAFE = "Failsafe activated\t"
GEOFENCE = "Geofence: approaching or outside geofence"
RTL_LAND = "RTL: land at destination\t"


def takeoff_default(alt_m: float) -> str:
    """navigator/takeoff.cpp, when the takeoff command leaves the altitude NaN (MAVSDK does)."""
    return f"Using default takeoff altitude: {alt_m:.1f} m\t"


def rtl_start(return_alt_amsl_m: float, above_home_m: float) -> str:
    """navigator/rtl_direct.cpp: integer metres, AMSL and above the destination."""
    return (f"RTL: start return at {round(return_alt_amsl_m)} m "
            f"({round(above_home_m)} m above destination)\t")
