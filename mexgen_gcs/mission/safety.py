"""Safety rules: pure decisions from the mission's observed state, checked a few times a second.

All times are mission (vehicle) seconds. The vehicle's own failsafes (PX4: offboard loss,
geofence, battery) stay the last line of defence and outrank these rules: a mode the GCS did
not command is a takeover (``MissionContext.check_takeover``), after which no rule here runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum


class Action(Enum):
    NONE = "none"
    HOLD = "hold"
    """Stop and hover (zero-velocity setpoints), keep the mission alive."""
    RTL = "rtl"
    """End the mission and return to launch."""
    RESUME_OFFBOARD = "resume_offboard"


@dataclass(frozen=True, slots=True)
class SafetyLimits:
    max_mission_time_s: float
    battery_rtl_percent: float
    link_loss_timeout_s: float
    on_link_regained: str  # resume | rtl
    radio_heartbeat_timeout_s: float
    radio_loss_timeout_s: float


@dataclass(frozen=True, slots=True)
class SafetyInputs:
    elapsed_s: float
    battery_percent: float
    link_age_s: float
    """Vehicle seconds since the last telemetry message."""
    link_connected: bool
    radio_silent_s: float
    """Mission seconds since the last radio heartbeat or detection."""
    link_was_lost: bool


@dataclass(frozen=True, slots=True)
class Decision:
    action: Action
    reason: str


def decide(inp: SafetyInputs, lim: SafetyLimits) -> Decision:
    """The first rule that fires wins; order = severity."""
    link_ok = inp.link_connected and inp.link_age_s <= lim.link_loss_timeout_s
    if not link_ok:
        return Decision(Action.HOLD, "link_lost")
    if inp.link_was_lost:
        if lim.on_link_regained == "rtl":
            return Decision(Action.RTL, "link_regained_rtl")
        return Decision(Action.RESUME_OFFBOARD, "link_regained_resume")
    if math.isfinite(inp.battery_percent) and inp.battery_percent < lim.battery_rtl_percent:
        return Decision(Action.RTL, "battery_low")
    if inp.elapsed_s > lim.max_mission_time_s:
        return Decision(Action.RTL, "max_mission_time")
    if inp.radio_silent_s > lim.radio_loss_timeout_s:
        return Decision(Action.RTL, "radio_lost")
    if inp.radio_silent_s > lim.radio_heartbeat_timeout_s:
        return Decision(Action.HOLD, "radio_silent")
    return Decision(Action.NONE, "ok")
