"""Mission states, end reasons, results and the signals that move a mission between phases.

States and end reasons are defined once here, as str-valued enums, so logs, snapshots and the
UI read plain words. No frames here.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any


class MissionState(enum.StrEnum):
    CONNECTING = "connecting"
    PREFLIGHT = "preflight"
    TAKEOFF = "takeoff"
    SEARCHING = "searching"
    HOLDING = "holding"
    """Searching, but hovering (planner overdue, radio silent, link lost, operator pause)."""
    RETURNING = "returning"
    """The GCS commanded return to launch (or land) and waits for the landing."""
    TAKEOVER = "takeover"
    """The autopilot or a pilot took control; the GCS only watches (and obeys the operator)."""
    LANDED = "landed"
    DONE = "done"


class EndReason(enum.StrEnum):
    # success (exit 0 once landed and disarmed)
    ALL_LOCALISED = "all_localised"
    ALL_REPORTED = "all_reported"
    """Every tag reported, some before reaching the radius (stalled or budget)."""
    FOLLOW_COMPLETE = "follow_complete"
    # the operator (UI key, Ctrl-C) or the system (signals)
    OPERATOR_ABORT = "operator_abort"
    OPERATOR_RTL = "operator_rtl"
    OPERATOR_LAND = "operator_land"
    SIGNAL_SIGHUP = "signal_sighup"
    SIGNAL_SIGTERM = "signal_sigterm"
    CANCELLED = "cancelled"
    """The task flying the mission was cancelled (e.g. by the UI's task group)."""
    SIGNAL_REPEATED = "signal_repeated"
    """A second stop signal while the first could not be obeyed: immediate exit."""
    # the mission's safety rules
    BATTERY_LOW = "battery_low"
    MAX_MISSION_TIME = "max_mission_time"
    RADIO_LOST = "radio_lost"
    LINK_REGAINED_RTL = "link_regained_rtl"
    LANDED_DURING_LINK_LOSS = "landed_during_link_loss"
    RESUME_FAILED = "resume_failed"
    # the autopilot outranks the GCS
    AUTOPILOT_TAKEOVER = "autopilot_takeover"
    # before arming (nothing armed)
    HOME_TOO_FAR_FROM_AREA = "home_too_far_from_area"
    NO_RADIO = "no_radio"
    VEHICLE_NOT_READY = "vehicle_not_ready"
    # before arming, for the vehicle's set-up (exit 2, like bad input)
    VEHICLE_PARAMS_UNSAFE = "vehicle_params_unsafe"
    """A PX4 parameter leaves the vehicle unsafe for this mission (config.px4_params)."""
    GEOFENCE_REFUSED = "geofence_refused"
    """The vehicle did not take the geofence and safety.require_geofence is true."""
    GEOFENCE_ON_VEHICLE = "geofence_on_vehicle"
    """Another fence is on the vehicle and safety.replace_existing_geofence is false."""
    # failures
    VEHICLE_ERROR = "vehicle_error"
    """A vehicle command or connection failed (the error is in the result record)."""
    ERROR = "error"
    """An unexpected exception (the error is in the result record)."""


SUCCESS = frozenset({EndReason.ALL_LOCALISED, EndReason.ALL_REPORTED,
                     EndReason.FOLLOW_COMPLETE})
SETUP_REFUSED = frozenset({EndReason.VEHICLE_PARAMS_UNSAFE, EndReason.GEOFENCE_REFUSED,
                           EndReason.GEOFENCE_ON_VEHICLE})
"""Refusals before arming that the operator fixes on the vehicle or in the mission: exit 2."""


class ReturnAction(enum.StrEnum):
    """What the return phase commands."""

    RTL = "rtl"
    LAND = "land"
    NONE = "none"
    """Nothing: on the ground, or the autopilot has control."""


@dataclass(frozen=True, slots=True)
class StopRequest:
    """Someone asked the mission to end: why, and what to command."""

    reason: EndReason
    action: ReturnAction
    operator: bool
    """True for the operator's own keys and Ctrl-C: allowed to command after a takeover."""


@dataclass(frozen=True, slots=True)
class TakeoverInfo:
    t: float
    mode: str
    armed: bool
    reason: str
    """The autopilot's recent STATUSTEXTs, or what the GCS saw (e.g. 'disarmed in flight')."""
    phase: str


@dataclass
class MissionResult:
    end_reason: str
    exit_code: int
    localised: dict[str, dict[str, float]]
    duration_s: float
    log_dir: str | None = None
    rejects: dict[str, int] = field(default_factory=dict)
    events: list[str] = field(default_factory=list)
    error: str | None = None
    takeover: dict[str, Any] | None = None
    counters: dict[str, int] = field(default_factory=dict)
    unresolved: dict[str, dict[str, float]] = field(default_factory=dict)
    """The last estimate of every tag not localised (where to look, within its 95 % radius)."""
    reports: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Every reported tag: reason, after_s, radius_m, worked_s, radius_over_time."""


@dataclass(frozen=True, slots=True)
class ControllerOptions:
    """Bounds of the waits. Wall seconds for talking to the vehicle (connect, ready, radio,
    the clock), vehicle seconds for what the vehicle does (climb, landing)."""

    connect_timeout_s: float = 60.0
    ready_timeout_s: float = 60.0
    radio_wait_s: float = 15.0
    clock_wait_s: float = 10.0
    takeoff_timeout_s: float = 120.0
    landing_timeout_s: float = 900.0
    headless_progress_s: float = 10.0
    print_progress: bool = True
    mode_grace_s: float = 3.0
    """Wall seconds a commanded mode change may take before the old mode counts as not ours."""


# -- signals between the tasks of a mission (control flow, not errors) -------------------------


class MissionSignal(Exception):
    """Base of the control-flow exceptions that end a phase."""


class MissionEnd(MissionSignal):
    """The mission ends for `reason`; the phase's return action follows."""

    def __init__(self, reason: EndReason, action: ReturnAction = ReturnAction.RTL) -> None:
        super().__init__(reason.value)
        self.reason = reason
        self.action = action


class Takeover(MissionSignal):
    """The autopilot took control (see ``MissionContext.takeover``)."""


class Fault(MissionSignal):
    """An unexpected exception somewhere (see ``MissionContext.error``)."""


class PhaseDone(MissionSignal):
    """A phase's main task finished normally."""
