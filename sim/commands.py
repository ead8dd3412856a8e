"""MAVLink command protocol (COMMAND_LONG / COMMAND_INT) of the simulated PX4 vehicle.

Every command addressed to this vehicle gets exactly one COMMAND_ACK: ACCEPTED when done,
DENIED when the vehicle cannot do it now or a parameter is out of range, TEMPORARILY_REJECTED
when retrying later may work, UNSUPPORTED for commands this vehicle does not implement.
Positions in commands are WGS84 (altitude AMSL unless the COMMAND_INT frame is relative);
they are mapped to the autopilot's local ENU frame about home.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.core.geo import LocalFrame
from sim import px4_modes as modes
from sim.autopilot import Autopilot, Result
from sim.clock import SimClock

FORCE_MAGIC = 21196
MAX_REPOSITION_M = 20_000.0
_GLOBAL_FRAMES = {0, 3, 5, 6, 10, 11}
_RELATIVE_FRAMES = {3, 6, 10, 11}  # relative-altitude and terrain (flat ground) frames
_C = mavlink


@dataclass(frozen=True, slots=True)
class Command:
    """A command with COMMAND_LONG semantics: params 5..7 are lat/lon degrees and altitude."""

    command: int
    params: tuple[float, float, float, float, float, float, float]
    relative_alt: bool = False


class VehiclePort(Protocol):
    """What the command protocol needs from the MAVLink side (``sim.vehicle.MavlinkVehicle``),
    stated here so that this module does not import it (no import cycle)."""

    ap: Autopilot
    clock: SimClock
    frame: LocalFrame
    mav: mavlink.MAVLink

    def send(self, msg: Any) -> None: ...

    def send_message(self, msg_id: int) -> bool: ...

    def can_stream(self, msg_id: int) -> bool: ...

    def reset_intervals(self, msg_id: int | None = None) -> None: ...

    def set_interval(self, msg_id: int, interval_s: float | None) -> None: ...

    def command_done(self, command: int, result: int) -> None: ...


class CommandHandler:
    """Dispatches commands to the autopilot and acks them."""

    def __init__(self, vehicle: VehiclePort) -> None:
        self.v = vehicle
        self._handlers: dict[int, Callable[[Command], Result]] = {
            _C.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            _C.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            _C.MAV_CMD_NAV_LAND: self._land,
            _C.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda c: self.v.ap.return_to_launch(),
            _C.MAV_CMD_NAV_LOITER_UNLIM: lambda c: self.v.ap.hold(),
            _C.MAV_CMD_DO_SET_MODE: self._set_mode,
            _C.MAV_CMD_DO_REPOSITION: self._reposition,
            _C.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
            _C.MAV_CMD_DO_SET_HOME: self._set_home,
            _C.MAV_CMD_REQUEST_MESSAGE: self._request_message,
            _C.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_message_interval,
            _C.MAV_CMD_GET_HOME_POSITION: lambda c: self._send(_C.MAVLINK_MSG_ID_HOME_POSITION),
            _C.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
                lambda c: self._send(_C.MAVLINK_MSG_ID_AUTOPILOT_VERSION),
        }

    # -- entry points ---------------------------------------------------------------------

    def command_long(self, msg: Any) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7)
        self._run(msg, Command(msg.command, tuple(float(p) for p in params)))  # type: ignore[arg-type]

    def command_int(self, msg: Any) -> None:
        global_frame = msg.frame in _GLOBAL_FRAMES
        x = msg.x / 1e7 if global_frame else float(msg.x)
        y = msg.y / 1e7 if global_frame else float(msg.y)
        params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4),
                  x, y, float(msg.z))
        self._run(msg, Command(msg.command, params, relative_alt=msg.frame in _RELATIVE_FRAMES))

    def _run(self, msg: Any, cmd: Command) -> None:
        handler = self._handlers.get(cmd.command)
        if handler is None:
            result = Result.UNSUPPORTED
        else:
            try:
                result = handler(cmd)
            except (ValueError, OverflowError):  # NaN/inf/out-of-range parameters
                result = Result.DENIED
        self.v.send(self.v.mav.command_ack_encode(
            cmd.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))
        self.v.command_done(cmd.command, int(result))

    # -- helpers ------------------------------------------------------------------------------

    def _send(self, msg_id: int) -> Result:
        return Result.ACCEPTED if self.v.send_message(msg_id) else Result.DENIED

    def _target_enu(self, cmd: Command) -> tuple[float, float, float]:
        """Params 5..7 as an ENU point; NaN fields keep the vehicle's current value."""
        s = self.v.ap.state
        lat, lon, alt = cmd.params[4], cmd.params[5], cmd.params[6]
        if lat == 0.0 and lon == 0.0:
            lat = lon = math.nan  # zeros, as simple clients send them, mean "here" (as PX4)
        if math.isfinite(lat) != math.isfinite(lon):
            raise ValueError("latitude and longitude must both be given")
        if math.isfinite(lat):
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise ValueError("lat/lon out of range")
            e, n, _ = self.v.frame.to_enu(lat, lon, self.v.frame.alt0_m)
            east, north = float(e), float(n)
        else:
            east, north = s.east_m, s.north_m
        if not math.isfinite(alt):
            up = s.up_m
        elif cmd.relative_alt:
            up = alt + self.v.ap.home_enu_m[2]
        else:
            up = alt - self.v.frame.alt0_m
        if math.hypot(east, north) > MAX_REPOSITION_M or not -10.0 <= up <= 2000.0:
            raise ValueError("target too far from home")
        return east, north, up

    # -- handlers ----------------------------------------------------------------------------

    def _arm_disarm(self, cmd: Command) -> Result:
        arm, force = cmd.params[0], cmd.params[1] == FORCE_MAGIC
        if arm == 1.0:
            return self.v.ap.arm(self.v.clock.wall_s(), force=force)
        if arm == 0.0:
            return self.v.ap.disarm(force=force)
        return Result.DENIED

    def _takeoff(self, cmd: Command) -> Result:
        alt = cmd.params[6]
        if not math.isfinite(alt):
            return self.v.ap.takeoff(None)
        rel = alt + self.v.ap.home_enu_m[2] if cmd.relative_alt else alt - self.v.frame.alt0_m
        return self.v.ap.takeoff(rel)

    def _land(self, cmd: Command) -> Result:
        p = cmd.params
        self._target_enu(Command(cmd.command, (*p[:6], math.nan)))  # validates lat/lon only
        # (PX4 lands where it is; the position only has to make sense)
        return self.v.ap.land()

    def _set_mode(self, cmd: Command) -> Result:
        base, main, sub = cmd.params[0], cmd.params[1], cmd.params[2]
        if not (math.isfinite(base) and int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
            return Result.DENIED
        if not (math.isfinite(sub)):
            sub = 0.0
        mode = modes.from_ids(int(main), int(sub))  # ValueError -> DENIED
        return self.v.ap.set_mode(mode, self.v.clock.wall_s())

    def _reposition(self, cmd: Command) -> Result:
        speed = cmd.params[0]
        target = self._target_enu(cmd)
        speed_m_s = speed if math.isfinite(speed) and speed > 0.0 else None
        return self.v.ap.reposition(target, speed_m_s)

    def _change_speed(self, cmd: Command) -> Result:
        speed = cmd.params[1]
        if not math.isfinite(speed) or speed > 50.0:
            return Result.DENIED
        return self.v.ap.change_speed(speed)

    def _set_home(self, cmd: Command) -> Result:
        if cmd.params[0] == 1.0:
            s = self.v.ap.state
            return self.v.ap.set_home((s.east_m, s.north_m, 0.0 if not self.v.ap.in_air
                                       else self.v.ap.home_enu_m[2]))
        if not (math.isfinite(cmd.params[4]) and math.isfinite(cmd.params[5])):
            return Result.DENIED
        return self.v.ap.set_home(self._target_enu(cmd))

    def _request_message(self, cmd: Command) -> Result:
        msg_id = cmd.params[0]
        if not (math.isfinite(msg_id) and 0 <= msg_id < 2**24):
            return Result.DENIED
        return self._send(int(msg_id))

    def _set_message_interval(self, cmd: Command) -> Result:
        msg_id, interval_us = cmd.params[0], cmd.params[1]
        if not (math.isfinite(msg_id) and math.isfinite(interval_us)):
            return Result.DENIED
        mid = int(msg_id)
        if not self.v.can_stream(mid):
            return Result.DENIED
        if interval_us == 0.0:
            self.v.reset_intervals(mid)
        elif interval_us < 0.0:
            if mid == _C.MAVLINK_MSG_ID_HEARTBEAT:
                return Result.DENIED
            self.v.set_interval(mid, None)
        else:
            self.v.set_interval(mid, interval_us / 1e6)
        return Result.ACCEPTED
