"""The only way the mission commands the vehicle, and what it expects the vehicle to do.

The autopilot outranks the GCS. Every command says which flight modes it should lead to; a
mode the GCS did not command while flying (HOLD from a geofence breach, POSCTL/ALTCTL/MANUAL/
STABILIZED/ACRO from a pilot, RTL/LAND failsafes) or a disarm in flight is a takeover:
``release()`` then stops every command and setpoint at once, and only the operator
(``operator=True``: a UI key, Ctrl-C) may command again. Mode names are MAVSDK's
``FlightMode`` names. Frames: setpoints are NED m/s with a compass yaw in degrees.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from mexgen_gcs.io.vehicle import Telemetry, Vehicle

log = logging.getLogger(__name__)

OFFBOARD = "OFFBOARD"
HOLD = "HOLD"
TAKEOFF = "TAKEOFF"
RTL = "RETURN_TO_LAUNCH"
LAND = "LAND"
PILOT_MODES = frozenset({"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED", "RATTITUDE"})
UNKNOWN_MODES = frozenset({"UNKNOWN", "READY", ""})
"""Modes that say nothing before the vehicle is seen armed (no telemetry yet, PX4's pre-arm
READY); in flight a mode MAVSDK cannot name is a mode the GCS did not command."""


@dataclass(frozen=True, slots=True)
class Expectation:
    """Modes the GCS commanded, plus the previous ones while the change lands: until the
    vehicle first reports a commanded mode, or `grace_until_mono` at the latest."""

    modes: frozenset[str]
    grace_modes: frozenset[str] = frozenset()
    grace_until_mono: float = 0.0
    disarm_ok: bool = False
    """Landing: a disarm is the expected end, not a takeover."""


def judge(exp: Expectation | None, tel: Telemetry, seen_armed: bool, now_mono: float
          ) -> str | None:
    """None when the vehicle does what the GCS expects; else what it does instead."""
    if exp is None:
        return None
    if not tel.armed:
        if exp.disarm_ok or not seen_armed:
            return None
        return "disarmed in flight"
    mode = tel.flight_mode
    if mode in exp.modes or (mode in UNKNOWN_MODES and not seen_armed):
        return None
    if mode in exp.grace_modes and now_mono <= exp.grace_until_mono:
        return None
    who = "a pilot" if mode in PILOT_MODES else "the autopilot"
    return f"mode {mode} set by {who} (the GCS expects {'/'.join(sorted(exp.modes))})"


@dataclass
class CommandLog:
    """Counts for the result record: commands sent, refused (not in control), failed."""

    sent: dict[str, int] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)
    setpoints: int = 0
    setpoints_refused: int = 0


class Commander:
    """Wraps the vehicle port. `event(kind, **fields)` logs what happens."""

    def __init__(self, vehicle: Vehicle, event: Callable[..., None], *, grace_s: float = 3.0,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.vehicle = vehicle
        self._event = event
        self.grace_s = grace_s
        self._monotonic = monotonic
        self.in_control = True
        self.expectation: Expectation | None = None
        self.seen_armed = False
        self.counts = CommandLog()
        self.last_setpoint_mono = -float("inf")
        self.last_command_mono = -float("inf")

    # -- expectations ------------------------------------------------------------------------

    def expect(self, modes: frozenset[str] | set[str], *,
               grace: frozenset[str] | set[str] = frozenset(), disarm_ok: bool = False) -> None:
        """From now on the vehicle should be in one of `modes`; the current mode and `grace`
        are accepted for ``grace_s`` while the change lands."""
        current = self.vehicle.hub.latest.flight_mode
        self.expectation = Expectation(frozenset(modes), frozenset(grace) | {current},
                                       self._monotonic() + self.grace_s, disarm_ok)

    def check(self) -> str | None:
        """What the vehicle does that the GCS did not command, or None (see `judge`)."""
        tel = self.vehicle.hub.latest
        if tel.armed:
            self.seen_armed = True
        if not self.in_control:
            return None
        exp = self.expectation
        if exp is not None and exp.grace_modes and tel.flight_mode in exp.modes:
            self.expectation = replace(exp, grace_modes=frozenset())  # the change has landed
        return judge(self.expectation, tel, self.seen_armed, self._monotonic())

    def release(self) -> None:
        """A takeover: no command or setpoint leaves from now on unless the operator asks."""
        self.in_control = False
        self.expectation = None

    # -- commands ----------------------------------------------------------------------------

    def _allowed(self, what: str, operator: bool) -> bool:
        if self.in_control:
            return True
        if operator:
            self.in_control = True
            self._event("operator_retakes_control", command=what)
            return True
        self.counts.refused[what] = self.counts.refused.get(what, 0) + 1
        if self.counts.refused[what] == 1:
            self._event("command_withheld", level=logging.WARNING, command=what,
                        reason="the autopilot has control")
        return False

    def _sent(self, what: str) -> None:
        self.counts.sent[what] = self.counts.sent.get(what, 0) + 1
        self.last_command_mono = self._monotonic()

    def may_be_armed(self) -> bool:
        """Armed as far as anyone knows: telemetry says so, or an arm command went out
        (telemetry's armed flag lags the command by up to a heartbeat)."""
        tel = self.vehicle.hub.latest
        return tel.armed or tel.in_air or "arm" in self.counts.sent

    async def upload_geofence(self, polygon_latlon_deg: list[tuple[float, float]]) -> bool:
        if not self._allowed("upload_geofence", False):
            return False
        await self.vehicle.upload_geofence(polygon_latlon_deg)
        self._sent("upload_geofence")
        return True

    async def arm(self) -> bool:
        if not self._allowed("arm", False):
            return False
        self.counts.sent.setdefault("arm", 0)  # from here on the vehicle may be armed
        await self.vehicle.arm()
        self._sent("arm")
        return True

    async def takeoff(self, alt_m: float) -> bool:
        if not self._allowed("takeoff", False):
            return False
        self.expect({TAKEOFF, HOLD})
        await self.vehicle.takeoff(alt_m)
        self._sent("takeoff")
        return True

    async def start_offboard(self, yaw_deg: float) -> bool:
        if not self._allowed("start_offboard", False):
            return False
        self.expect({OFFBOARD}, grace={HOLD, TAKEOFF})
        await self.vehicle.start_offboard(yaw_deg)
        self.last_setpoint_mono = self._monotonic()
        self._sent("start_offboard")
        return True

    async def set_velocity_ned(self, v_north_m_s: float, v_east_m_s: float, v_down_m_s: float,
                               yaw_deg: float) -> bool:
        if not self.in_control:  # a takeover stops the stream at once, silently
            self.counts.setpoints_refused += 1
            return False
        await self.vehicle.set_velocity_ned(v_north_m_s, v_east_m_s, v_down_m_s, yaw_deg)
        self.last_setpoint_mono = self._monotonic()
        self.counts.setpoints += 1
        return True

    async def return_to_launch(self, *, operator: bool = False) -> bool:
        if not self._allowed("return_to_launch", operator):
            return False
        self.expect({RTL, LAND}, grace={OFFBOARD, HOLD}, disarm_ok=True)
        await self.vehicle.return_to_launch()
        self._sent("return_to_launch")
        return True

    async def land(self, *, operator: bool = False) -> bool:
        if not self._allowed("land", operator):
            return False
        self.expect({LAND}, grace={OFFBOARD, HOLD, RTL}, disarm_ok=True)
        await self.vehicle.land()
        self._sent("land")
        return True

    def summary(self) -> dict[str, Any]:
        c = self.counts
        return {"sent": dict(c.sent), "withheld": dict(c.refused), "setpoints": c.setpoints,
                "setpoints_withheld": c.setpoints_refused}
