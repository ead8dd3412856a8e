"""PX4-like flight logic of the simulated multirotor: arming, modes, failsafes, guidance.

Frame: local ENU metres about the mission home (x east, y north, z up = height above the
ground, which is flat at home's altitude). Yaw is a compass heading in degrees.

This module has no I/O: the MAVLink side (``sim.vehicle``) calls the command methods, which
return a ``Result`` (MAV_RESULT values), and ``step()`` on sim time; both append ``Event``s
that the caller turns into heartbeats, STATUSTEXT and truth records. Timeouts that measure
the ground station's reactions (offboard setpoint loss, pre-flight auto-disarm) use the wall
time the caller passes in; physics, battery and landing use sim time.

Behaviours mirrored from PX4 (sim/README.md says what was observed on PX4 SITL): arming refused
without a GPS fix; auto-disarm when not taken off within COM_DISARM_PRFLT of arming and
COM_DISARM_LAND after landing; takeoff to MIS_TAKEOFF_ALT then hold; offboard only with a
fresh setpoint and, after COM_OF_LOSS_T without one, COM_OBL_RC_ACT (position mode, which
without RC falls back to NAV_RCL_ACT: return, as PX4 SITL does); RTL climbs to RTL_RETURN_ALT (or
stays higher), returns at MPC_XY_CRUISE, lands; speed capped by MPC_XY_VEL_MAX; battery
critical -> RTL and emergency -> land; geofence breach -> GF_ACTION. STATUSTEXT wordings
are PX4's (``sim.px4_texts``); mode changes are silent, as on PX4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from sim import px4_modes as modes
from sim import px4_texts as texts
from sim.fence import Fence
from sim.guidance import ReturnToLaunch, descend, stopping_point
from sim.kinematics import KinematicState, Limits, VelocityCommand, step, velocity_towards
from sim.params import ParamTable
from sim.px4_modes import MainMode, PX4Mode


class Result(IntEnum):
    """MAV_RESULT values."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


class LandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


@dataclass(frozen=True, slots=True)
class Event:
    """Something that happened to the vehicle. ``severity`` is MAV_SEVERITY (6 info).

    ``announce``: PX4 sends this text as STATUSTEXT; otherwise it is only logged (truth).
    """

    kind: str
    text: str
    severity: int = 6
    announce: bool = True


@dataclass(frozen=True, slots=True)
class Setpoint:
    """Offboard setpoint in ENU. ``position`` None means a velocity setpoint."""

    velocity_enu_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_enu_m: tuple[float, float, float] | None = None
    yaw_deg: float | None = None
    yaw_rate_deg_s: float | None = None


_MANUAL_MODES = {MainMode.MANUAL, MainMode.ACRO, MainMode.STABILIZED, MainMode.RATTITUDE}
_HOLD_LIKE = {modes.HOLD, modes.POSCTL, modes.ALTCTL}
_GROUND_M = 0.05
#: PX4 re-sets home at arming and at takeoff to its position estimate; in SIH that lands
#: within ~0.3 m of the true position (observed). Standard deviations of the simulated error.
HOME_ERROR_STD_M = (0.1, 0.1, 0.15)
HOME_ERROR_MAX_M = 0.3


class Autopilot:
    """The vehicle's state and PX4-like behaviour. Call ``step`` with small sim dt."""

    def __init__(self, params: ParamTable, airframe: Limits, battery_endurance_s: float,
                 alt0_amsl_m: float = 0.0, rng: np.random.Generator | None = None) -> None:
        """``rng``: draws the error of the home re-set at arming/takeoff (None: exact)."""
        if not battery_endurance_s > 0.0:
            raise ValueError("battery_endurance_s must be > 0")
        self.params = params
        self.airframe = airframe
        self.battery_endurance_s = battery_endurance_s
        self.alt0_amsl_m = alt0_amsl_m
        """AMSL altitude of the local frame's origin (for PX4's RTL message)."""
        self.state = KinematicState()
        self.armed = False
        self.mode: PX4Mode = modes.HOLD
        self.landed_state = LandedState.ON_GROUND
        self.home_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.home_set_sim_s = 0.0
        self._rng = rng
        self._now_sim_s = 0.0
        """Sim time home was last set (HOME_POSITION.time_usec, time since boot as PX4)."""
        self.gps_ok = True
        self.battery_fraction = 1.0
        self.fence = Fence()
        self.has_flown = False
        self.failsafe = False
        """A failsafe chose the current mode (HEARTBEAT system_status CRITICAL, as PX4)."""
        self.rc_available = False
        """A pilot's RC transmitter is connected (from a pilot takeover on)."""
        self.events: list[Event] = []
        self._setpoint: Setpoint | None = None
        self._setpoint_wall_s = -math.inf
        self._hold_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._hold_speed_m_s: float | None = None
        self._takeoff_up_m = 0.0
        self._rtl: ReturnToLaunch | None = None
        self._auto_speed_m_s: float | None = None
        self._armed_wall_s = 0.0
        self._left_ground_since_arming = False
        self._on_ground_since_sim_s: float | None = None
        self._battery_level = 0  # 0 ok, 1 low, 2 critical, 3 emergency
        self._fence_breached = False

    # -- derived state -----------------------------------------------------------------

    @property
    def in_air(self) -> bool:
        return self.state.up_m > _GROUND_M

    @property
    def flight_complete(self) -> bool:
        """Landed and disarmed after having flown: the simulator may exit."""
        return self.has_flown and not self.armed and not self.in_air

    def limits(self) -> Limits:
        """Airframe limits tightened by the controller parameters."""
        p = self.params
        return Limits(
            max_speed_m_s=max(0.1, min(self.airframe.max_speed_m_s, p["MPC_XY_VEL_MAX"])),
            max_accel_m_s2=min(self.airframe.max_accel_m_s2, p["MPC_ACC_HOR"]),
            max_climb_m_s=min(self.airframe.max_climb_m_s, p["MPC_Z_VEL_MAX_UP"]),
            max_descent_m_s=min(self.airframe.max_descent_m_s, p["MPC_Z_VEL_MAX_DN"]),
            max_vert_accel_m_s2=self.airframe.max_vert_accel_m_s2,
            max_yaw_rate_deg_s=self.airframe.max_yaw_rate_deg_s,
        )

    def _emit(self, kind: str, text: str, severity: int = 6, announce: bool = True) -> None:
        self.events.append(Event(kind, text, severity, announce))

    def _set_mode(self, mode: PX4Mode) -> None:
        if mode in _HOLD_LIKE:
            self._hold_target = stopping_point(self.state, self.limits(), self.in_air)
            self._hold_speed_m_s = None
        if mode != self.mode:
            self.mode = mode
            self._emit("mode", f"mode {modes.name(mode)}", announce=False)

    # -- commands --------------------------------------------------------------------------

    def arm(self, now_wall_s: float, force: bool = False) -> Result:
        if self.armed:
            return Result.ACCEPTED
        if not force:
            if not self.gps_ok:
                self._emit("preflight", texts.PREFLIGHT_GPS, texts.CRITICAL)
                self._emit("arm_denied", texts.ARM_DENIED_HEALTH, texts.CRITICAL)
                return Result.DENIED
            if self.battery_fraction <= self.params["BAT_CRIT_THR"]:
                self._emit("arm_denied", texts.ARM_DENIED_HEALTH, texts.CRITICAL)
                return Result.DENIED
        self.armed = True
        self.failsafe = False
        self._armed_wall_s = now_wall_s
        self._left_ground_since_arming = self.in_air
        self._on_ground_since_sim_s = None
        self._emit("armed", texts.ARMED)
        if not self.in_air:
            self._auto_home()
        if self.mode == modes.TAKEOFF and not self.in_air:
            self._begin_takeoff(self.params["MIS_TAKEOFF_ALT"], default_alt=True)
        return Result.ACCEPTED

    def disarm(self, force: bool = False, reason: str = texts.DISARMED_BY_COMMAND) -> Result:
        if not self.armed:
            return Result.ACCEPTED
        if self.in_air and not force:
            self._emit("disarm_denied", texts.DISARM_DENIED_IN_AIR, texts.CRITICAL)
            return Result.DENIED
        self.armed = False
        self.failsafe = False
        if self.in_air:  # forced disarm in flight: the airframe drops to the ground
            self.state = replace(self.state, up_m=0.0, v_east_m_s=0.0, v_north_m_s=0.0,
                                 v_up_m_s=0.0)
            self.landed_state = LandedState.ON_GROUND
            self._emit("crash", "Disarmed in flight: vehicle fell", 2)
        self._emit("disarmed", reason)
        return Result.ACCEPTED

    def takeoff(self, target_up_m: float | None) -> Result:
        """Climb to ``target_up_m`` (ENU up = height above the ground), or MIS_TAKEOFF_ALT."""
        alt = self.params["MIS_TAKEOFF_ALT"] if target_up_m is None else target_up_m
        if not (math.isfinite(alt) and 0.0 < alt <= 500.0):
            return Result.DENIED
        if not self.armed or self.in_air:
            return Result.DENIED
        self._command_mode(modes.TAKEOFF)
        self._begin_takeoff(alt, default_alt=target_up_m is None)
        return Result.ACCEPTED

    def _begin_takeoff(self, alt_rel_m: float, default_alt: bool) -> None:
        s = self.state
        self._takeoff_up_m = alt_rel_m
        self._hold_target = (s.east_m, s.north_m, alt_rel_m)
        if default_alt:
            self._emit("takeoff", texts.takeoff_default(alt_rel_m))

    def _command_mode(self, mode: PX4Mode) -> None:
        """A mode the ground station (or the pilot) chose: any failsafe is over."""
        self.failsafe = False
        self._set_mode(mode)

    def _failsafe(self, mode: PX4Mode, kind: str, *reason: str) -> None:
        for text in reason:
            self._emit(kind, text, texts.CRITICAL)
        self._emit("failsafe", texts.FAILSAFE, texts.CRITICAL)
        self.failsafe = True
        if mode == modes.RTL:
            self._start_rtl()
        elif mode == modes.LAND:
            self._set_mode(modes.LAND)
            s = self.state
            self._hold_target = (s.east_m, s.north_m, 0.0)
        else:
            self._set_mode(mode)

    def land(self) -> Result:
        if not self.armed:
            return Result.DENIED
        self._emit("land", texts.LANDING_HERE)
        self._command_mode(modes.LAND)
        s = self.state
        self._hold_target = (s.east_m, s.north_m, 0.0)
        return Result.ACCEPTED

    def return_to_launch(self) -> Result:
        if not self.armed:
            return Result.DENIED
        self._emit("rtl", texts.RETURNING)
        self.failsafe = False
        self._start_rtl()
        return Result.ACCEPTED

    def _start_rtl(self) -> None:
        self._set_mode(modes.RTL)
        home_up = self.home_enu_m[2]
        alt = max(self.state.up_m, home_up + self.params["RTL_RETURN_ALT"])
        self._rtl = ReturnToLaunch(self.home_enu_m[0], self.home_enu_m[1], alt)
        if not self.in_air:
            self._rtl.phase = "land"
        else:
            self._emit("rtl", texts.rtl_start(self.alt0_amsl_m + alt, alt - home_up))

    def hold(self) -> Result:
        self._command_mode(modes.HOLD)
        return Result.ACCEPTED

    def set_mode(self, mode: PX4Mode, now_wall_s: float) -> Result:
        """DO_SET_MODE: the modes this vehicle can enter, with PX4's preconditions."""
        if mode == self.mode:
            self.failsafe = False
            return Result.ACCEPTED
        if mode in _HOLD_LIKE:
            self._command_mode(mode)
            return Result.ACCEPTED
        if mode == modes.OFFBOARD:
            if not self.offboard_setpoint_fresh(now_wall_s):
                return Result.TEMPORARILY_REJECTED
            self._command_mode(mode)
            return Result.ACCEPTED
        if mode == modes.TAKEOFF:
            if self.in_air:
                return Result.DENIED
            self._command_mode(mode)
            if self.armed:
                self._begin_takeoff(self.params["MIS_TAKEOFF_ALT"], default_alt=True)
            return Result.ACCEPTED
        if mode == modes.LAND:
            self._command_mode(mode)
            s = self.state
            self._hold_target = (s.east_m, s.north_m, 0.0)
            return Result.ACCEPTED
        if mode == modes.RTL:
            if not self.armed:
                return Result.DENIED
            self.failsafe = False
            self._start_rtl()
            return Result.ACCEPTED
        if mode[0] in _MANUAL_MODES:
            self._emit("mode_denied", f"Switching to {modes.name(mode)} is currently not "
                       "available	", texts.CRITICAL)
        return Result.DENIED  # MISSION (none uploaded), manual modes, READY, FOLLOW, ...

    def pilot_switch(self, mode: PX4Mode) -> None:
        """The pilot moves the RC mode switch: PX4 changes mode at once and says nothing
        (commander's ACTION_SWITCH_MODE sends no STATUSTEXT on success; HEARTBEAT shows it).
        POSCTL/ALTCTL with centred sticks brake and hold; LAND lands and auto-disarms."""
        self.failsafe = False
        self.rc_available = True
        if mode == modes.LAND:
            s = self.state
            self._hold_target = (s.east_m, s.north_m, 0.0)
        if mode in _HOLD_LIKE:
            self._hold_target = stopping_point(self.state, self.limits(), self.in_air)
            self._hold_speed_m_s = None
        if mode != self.mode:
            self.mode = mode
            self._emit("pilot", f"RC mode switch: {modes.name(mode)}", announce=False)

    def reposition(self, target_enu_m: tuple[float, float, float], speed_m_s: float | None
                   ) -> Result:
        """DO_REPOSITION: fly to a point in hold mode (PX4 'goto')."""
        if not (self.armed and self.in_air):
            return Result.DENIED
        self._command_mode(modes.HOLD)
        self._hold_target = target_enu_m
        self._hold_speed_m_s = speed_m_s
        return Result.ACCEPTED

    def change_speed(self, speed_m_s: float) -> Result:
        if not (math.isfinite(speed_m_s) and speed_m_s != 0.0):
            return Result.DENIED
        self._auto_speed_m_s = None if speed_m_s < 0.0 else speed_m_s
        return Result.ACCEPTED

    def set_home(self, home_enu_m: tuple[float, float, float]) -> Result:
        self.home_enu_m = home_enu_m
        self.home_set_sim_s = self._now_sim_s
        self._emit("home", "Home position set", announce=False)  # PX4 says nothing
        return Result.ACCEPTED

    def _auto_home(self) -> None:
        """PX4 (COM_HOME_EN) sets home to its position estimate at arming and at takeoff."""
        s = self.state
        e, n, u = s.east_m, s.north_m, 0.0 if not self.in_air else s.up_m
        if self._rng is not None:
            de, dn, du = np.clip(self._rng.normal(0.0, HOME_ERROR_STD_M), -HOME_ERROR_MAX_M,
                                 HOME_ERROR_MAX_M)
            e, n, u = e + float(de), n + float(dn), u + float(du)
        self.set_home((e, n, u))

    def offboard_setpoint(self, setpoint: Setpoint, now_wall_s: float) -> None:
        self._setpoint = setpoint
        self._setpoint_wall_s = now_wall_s

    def offboard_setpoint_fresh(self, now_wall_s: float) -> bool:
        return (self._setpoint is not None
                and now_wall_s - self._setpoint_wall_s <= self.params["COM_OF_LOSS_T"])

    # -- simulation step -----------------------------------------------------------------------

    def step(self, dt_s: float, now_sim_s: float, now_wall_s: float) -> None:
        """Advance the vehicle by dt_s of sim time (keep dt_s <= ~0.05 s)."""
        self._now_sim_s = now_sim_s
        self._supervise(now_wall_s)
        limits = self.limits()
        cmd = self._command(limits) if self.armed else VelocityCommand()
        was_in_air = self.in_air
        self.state = step(self.state, cmd, limits, dt_s)
        if self.armed:
            drain = dt_s / self.battery_endurance_s
            self.battery_fraction = max(0.0, self.battery_fraction - drain)
        self._update_landed(was_in_air, now_sim_s)
        self._battery_failsafe()
        self._fence_check()

    def _supervise(self, now_wall_s: float) -> None:
        if self.mode == modes.OFFBOARD and not self.offboard_setpoint_fresh(now_wall_s):
            self._failsafe(self._offboard_loss_mode(), "offboard_lost")
        prflt = self.params["COM_DISARM_PRFLT"]
        if (self.armed and not self._left_ground_since_arming and prflt > 0.0
                and now_wall_s - self._armed_wall_s > prflt):
            self.disarm(reason=texts.DISARMED_PREFLIGHT)

    def _offboard_loss_mode(self) -> PX4Mode:
        """PX4's failsafe for offboard loss (commander/failsafe/failsafe.cpp): COM_OBL_RC_ACT;
        its manual fallbacks need RC, without which NAV_RCL_ACT decides (default: return)."""
        act = int(self.params["COM_OBL_RC_ACT"])
        if act in (0, 1, 2):
            if self.rc_available:
                return modes.POSCTL if act == 0 else modes.ALTCTL
            act = {1: 5, 2: 3, 3: 4}.get(int(self.params["NAV_RCL_ACT"]), 5)
        return {3: modes.RTL, 4: modes.LAND}.get(act, modes.HOLD)  # 5 hold; 6, 7 not simulated

    def _auto_speed(self, limits: Limits) -> float:
        speed = self._auto_speed_m_s or self.params["MPC_XY_CRUISE"]
        return min(speed, limits.max_speed_m_s)

    def _command(self, limits: Limits) -> VelocityCommand:
        s = self.state
        if self.mode == modes.OFFBOARD and self._setpoint is not None:
            sp = self._setpoint
            if sp.position_enu_m is not None:
                ve, vn, vu = velocity_towards(s, *sp.position_enu_m, limits)
            else:
                ve, vn, vu = sp.velocity_enu_m_s
            if not self.in_air and vu <= 0.0:
                ve = vn = 0.0  # on the ground a horizontal setpoint does not slide the airframe
            return VelocityCommand(ve, vn, vu, sp.yaw_deg, sp.yaw_rate_deg_s)
        if self.mode == modes.TAKEOFF:
            ve, vn, vu = velocity_towards(s, *self._hold_target, limits)
            if not self.in_air and self.state.up_m <= 0.0:
                ve = vn = 0.0
            return VelocityCommand(ve, vn, max(vu, 0.0) if s.up_m < self._takeoff_up_m else vu)
        if self.mode == modes.LAND:
            return self._descend(self._hold_target[0], self._hold_target[1], limits)
        if self.mode == modes.RTL:
            return self._return(limits)
        if not self.in_air and self._hold_target[2] <= 0.0:
            return VelocityCommand()
        ve, vn, vu = velocity_towards(s, *self._hold_target, limits, speed_m_s=self._hold_speed_m_s)
        return VelocityCommand(ve, vn, vu)

    def _descend(self, east_m: float, north_m: float, limits: Limits) -> VelocityCommand:
        p = self.params
        return descend(self.state, east_m, north_m, limits, p["MPC_LAND_SPEED"],
                       p["MPC_LAND_ALT2"])

    def _return(self, limits: Limits) -> VelocityCommand:
        assert self._rtl is not None
        p = self.params
        cmd, message = self._rtl.command(self.state, limits, self._auto_speed(limits),
                                         p["MPC_LAND_SPEED"], p["MPC_LAND_ALT2"])
        if message:
            self._emit("rtl", message)
        return cmd

    def _update_landed(self, was_in_air: bool, now_sim_s: float) -> None:
        s = self.state
        if self.in_air:
            self._on_ground_since_sim_s = None
            if not was_in_air and self.armed:
                self._left_ground_since_arming = True
                if not self.has_flown:
                    self._emit("airborne", texts.TAKEOFF_DETECTED)
                self._auto_home()
                self.has_flown = True
            if self.mode == modes.TAKEOFF:
                self.landed_state = LandedState.TAKEOFF
                if s.up_m >= self._takeoff_up_m - 0.3:
                    self._set_mode(modes.HOLD)
                    self.landed_state = LandedState.IN_AIR
            elif s.v_up_m_s < -0.2 and (self.mode == modes.LAND or (
                    self.mode == modes.RTL and self._rtl is not None
                    and self._rtl.phase == "land")):
                self.landed_state = LandedState.LANDING
            else:
                self.landed_state = LandedState.IN_AIR
            return
        if was_in_air:
            self._emit("landed", texts.LANDING_DETECTED)
        self.landed_state = LandedState.ON_GROUND
        if self.armed and self._left_ground_since_arming:
            if self._on_ground_since_sim_s is None:
                self._on_ground_since_sim_s = now_sim_s
            delay = self.params["COM_DISARM_LAND"]
            if delay >= 0.0 and now_sim_s - self._on_ground_since_sim_s >= delay:
                self.disarm(reason=texts.DISARMED_LANDING)

    def _battery_failsafe(self) -> None:
        frac, p = self.battery_fraction, self.params
        level = (3 if frac <= p["BAT_EMERGEN_THR"] else 2 if frac <= p["BAT_CRIT_THR"]
                 else 1 if frac <= p["BAT_LOW_THR"] else 0)
        if level <= self._battery_level:
            self._battery_level = min(self._battery_level, level)
            return
        self._battery_level = level
        # PX4 says these with MAVLink events only; STATUSTEXT only "Failsafe activated".
        if level == 1:
            self._emit("battery", f"Low battery level, return advised ({frac:.0%})", 4, False)
        elif level == 2:
            self._emit("battery", f"Critical battery level ({frac:.0%})", 2, False)
            if self.armed and self.in_air and self.mode not in (modes.RTL, modes.LAND):
                self._failsafe(modes.RTL, "battery")
        elif level == 3:
            self._emit("battery", f"Emergency battery level ({frac:.0%})", 1, False)
            if self.armed and self.in_air and self.mode != modes.LAND:
                self._failsafe(modes.LAND, "battery")

    def _fence_check(self) -> None:
        if self.fence.empty or not (self.armed and self.in_air):
            self._fence_breached = False
            return
        inside = self.fence.allows(self.state.east_m, self.state.north_m)
        if inside or self._fence_breached:
            self._fence_breached = not inside
            return
        self._fence_breached = True
        action = int(self.params["GF_ACTION"])
        if action == 2 and self.mode not in (modes.RTL, modes.LAND):
            self._failsafe(modes.HOLD, "geofence", texts.GEOFENCE)
            # PX4 (navigator geofence_breach_check, GF_PREDICT 0) loiters where the breach was
            # seen: the vehicle brakes past it and comes back to hold there.
            s = self.state
            self._hold_target = (s.east_m, s.north_m, s.up_m)
        elif action == 3 and self.mode not in (modes.RTL, modes.LAND):
            self._failsafe(modes.RTL, "geofence", texts.GEOFENCE)
        elif action == 5:
            self._failsafe(modes.LAND, "geofence", texts.GEOFENCE)
        else:  # 0 none, 1 warning (and 4 terminate, not simulated)
            self._emit("geofence", texts.GEOFENCE, texts.CRITICAL)
