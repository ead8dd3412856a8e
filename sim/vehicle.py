"""The MAVLink side of the simulated vehicle: a PX4 quadrotor on UDP, as MAVSDK sees one.

Frames: MAVLink NED / WGS84 on the wire, converted to the autopilot's local ENU (about the
mission home) on the way in; see ``sim.telemetry`` for the way out.

It sends HEARTBEAT at 1 Hz and on every mode/arm change, telemetry on wall-clock intervals
(defaults scale with the speedup; SET_MESSAGE_INTERVAL overrides), answers commands with
honest COMMAND_ACKs, parameters with PARAM_VALUE, the fence mission protocol, TIMESYNC and
offboard setpoints. It sends to the configured targets and replies to whatever address sent
it MAVLink (as PX4 does). Garbage and unknown messages are counted and ignored.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.core.geo import LocalFrame
from sim.autopilot import Autopilot, Event, Setpoint
from sim.clock import SimClock
from sim.commands import CommandHandler
from sim.fence import Fence, build_fence, inclusion_items
from sim.mission_protocol import FenceProtocol
from sim.params import decode_param_id, int_from_wire, int_to_wire
from sim.setpoints import Parsed, from_global_int, from_local_ned
from sim.telemetry import TelemetryBuilder

Address = tuple[str, int]

COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1
PEER_TIMEOUT_S = 10.0
MAX_PEERS = 8
MIN_INTERVAL_S = 0.02
#: Heartbeat interval while no client has answered yet. MAVSDK discovers an autopilot on its
#: second heartbeat; beaconing faster until someone talks to us makes connecting take ~0.2 s
#: instead of ~1 s. Once a client is heard the heartbeat is 1 Hz, as PX4's.
UNHEARD_HEARTBEAT_S = 0.2

_M = mavlink
# Default telemetry rates: (rate in sim Hz scaled by speedup, (min, max) wall interval s),
# or a fixed wall interval for the slow ones.
_SIM_RATED: dict[int, tuple[float, float, float]] = {
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: (10.0, 0.02, 0.1),
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: (10.0, 0.02, 0.1),
    _M.MAVLINK_MSG_ID_ATTITUDE: (10.0, 0.02, 0.1),
    _M.MAVLINK_MSG_ID_GPS_RAW_INT: (5.0, 0.04, 0.2),
    _M.MAVLINK_MSG_ID_VFR_HUD: (4.0, 0.05, 0.25),
}
_WALL_RATED: dict[int, float] = {
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    _M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 2.0,
}


class _Writer:
    """The file-like object pymavlink's MAVLink.send writes packed bytes to."""

    def __init__(self, write: Callable[[bytes], None]) -> None:
        self.write = write


class MavlinkVehicle:
    """Owns the MAVLink state of one simulated vehicle; I/O goes through ``sendto``.

    ``handle_datagram`` for every received datagram, ``tick`` regularly (>= 50 Hz wall).
    """

    def __init__(
        self,
        autopilot: Autopilot,
        clock: SimClock,
        frame: LocalFrame,
        sendto: Callable[[bytes, Address], None],
        targets: list[Address],
        sysid: int = 1,
        on_fence: Callable[[Fence], None] | None = None,
        on_command: Callable[[int, int], None] | None = None,
    ) -> None:
        if not 1 <= sysid <= 255:
            raise ValueError(f"sysid must be 1..255, got {sysid}")
        self.ap = autopilot
        self.clock = clock
        self.frame = frame
        self.sysid = sysid
        self._sendto = sendto
        self._targets = list(targets)
        self._peers: dict[Address, float] = {}
        self.link_down = False
        self.mav = mavlink.MAVLink(_Writer(self._write), srcSystem=sysid,
                                   srcComponent=COMPONENT_ID)
        self.telemetry = TelemetryBuilder(self.mav, autopilot, clock, frame)
        self._builders = self.telemetry.by_id()
        self.fence = FenceProtocol(self.mav, self.send, self._lat_lon_to_en, self._fence_set)
        self._on_fence = on_fence
        self.commands = CommandHandler(self)
        self._intervals: dict[int, float | None] = {}
        self.reset_intervals()
        self._next_due: dict[int, float] = {}
        self.stats: dict[str, int] = {"rx_messages": 0, "rx_bad": 0, "rx_unknown": 0,
                                      "rx_ignored": 0, "errors": 0, "tx_messages": 0,
                                      "rx_commands": 0, "rx_setpoints": 0}
        self._on_command = on_command
        self._last_error_wall_s = -math.inf
        self._last_mode = autopilot.mode
        self._last_armed = autopilot.armed
        self._last_landed = autopilot.landed_state
        self._log_events: list[Event] = []
        self._last_unsupported_s = -math.inf

    # -- sending -------------------------------------------------------------------------

    def _write(self, buf: bytes) -> None:
        if self.link_down:
            return
        for addr in self.destinations():
            self._sendto(bytes(buf), addr)

    def destinations(self) -> list[Address]:
        now = self.clock.wall_s()
        for addr, seen in list(self._peers.items()):
            if now - seen > PEER_TIMEOUT_S:
                del self._peers[addr]
        dests = list(self._targets)
        dests.extend(a for a in self._peers if a not in dests)
        return dests

    def send(self, msg: Any) -> None:
        self.mav.send(msg)
        self.stats["tx_messages"] += 1

    def statustext(self, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        for msg in self.telemetry.statustext(text, severity):
            self.send(msg)

    # -- telemetry scheduling ---------------------------------------------------------------

    def reset_intervals(self, msg_id: int | None = None) -> None:
        """Default wall intervals; sim-rated ones are faster when the speedup is higher."""
        k = self.clock.speedup
        defaults: dict[int, float | None] = dict(_WALL_RATED)
        for mid, (rate_hz, lo, hi) in _SIM_RATED.items():
            defaults[mid] = min(hi, max(lo, 1.0 / (rate_hz * k)))
        if msg_id is None:
            self._intervals = defaults
        elif msg_id in defaults:
            self._intervals[msg_id] = defaults[msg_id]

    def can_stream(self, msg_id: int) -> bool:
        return msg_id in self._builders

    def set_interval(self, msg_id: int, interval_s: float | None) -> None:
        """None disables the stream; values are clamped to >= 20 ms."""
        self._intervals[msg_id] = None if interval_s is None else max(MIN_INTERVAL_S, interval_s)
        self._next_due.pop(msg_id, None)

    def send_message(self, msg_id: int) -> bool:
        """Send one message now (REQUEST_MESSAGE); False if this vehicle cannot build it."""
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self.send(self.telemetry.autopilot_version(self.sysid))
            return True
        builder = self._builders.get(msg_id)
        if builder is None:
            return False
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT and not self.ap.gps_ok:
            return False
        self.send(builder())
        if msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            # MAVSDK re-evaluates its health flags on SYS_STATUS: follow the home position
            # with one so that "home ok" shows within a round trip, not a second.
            self.send(self._builders[mavlink.MAVLINK_MSG_ID_SYS_STATUS]())
        return True

    def tick(self) -> None:
        """Send what is due, announce state changes, run protocol retries."""
        now = self.clock.wall_s()
        self._announce_changes()
        if self.link_down:
            return
        for msg_id, interval in self._intervals.items():
            if interval is None:
                continue
            if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT and not self._peers:
                interval = min(interval, UNHEARD_HEARTBEAT_S)
            due = self._next_due.get(msg_id, 0.0)
            if now + 1e-4 < due:
                continue
            self._next_due[msg_id] = max(due + interval, now)
            if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT and not self.ap.gps_ok:
                continue  # no position estimate without GPS
            self.send(self._builders[msg_id]())
        self.fence.tick(now)

    def _announce_changes(self) -> None:
        events, self.ap.events = self.ap.events, []
        self._log_events.extend(events)
        if not self.link_down:
            for ev in events:
                if ev.announce:
                    self.statustext(ev.text, ev.severity)
        if self.ap.mode != self._last_mode or self.ap.armed != self._last_armed:
            self._last_mode, self._last_armed = self.ap.mode, self.ap.armed
            if not self.link_down:
                self.send(self.telemetry.heartbeat())
            self._next_due[mavlink.MAVLINK_MSG_ID_HEARTBEAT] = self.clock.wall_s() + 1.0
        if self.ap.landed_state != self._last_landed:
            # MAVSDK's in_air/landed_state come from this (1 Hz): send changes at once.
            self._last_landed = self.ap.landed_state
            if not self.link_down:
                self.send(self.telemetry.extended_sys_state())

    def take_events(self) -> list[Event]:
        """Autopilot events announced since the last call (for the truth log)."""
        self._announce_changes()
        events, self._log_events = self._log_events, []
        return events

    def command_done(self, command: int, result: int) -> None:
        """Called by the command handler after each COMMAND_ACK it sent."""
        self.stats["rx_commands"] += 1
        if self._on_command is not None:
            self._on_command(command, result)

    # -- receiving -------------------------------------------------------------------------

    def handle_datagram(self, data: bytes, addr: Address) -> None:
        """Parse and dispatch one UDP datagram. Never raises."""
        if self.link_down:
            return
        parser = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
        parser.robust_parsing = True
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception:  # pymavlink raises assorted errors on hostile input
            self.stats["rx_bad"] += 1
            return
        for msg in msgs:
            try:
                self._dispatch(msg, addr)
            except Exception as exc:  # a bug or hostile input must never stop the vehicle
                self.stats["errors"] += 1
                now = self.clock.wall_s()
                if now - self._last_error_wall_s > 5.0:
                    self._last_error_wall_s = now
                    print(f"sim: error handling {msg.get_type()}: {exc!r}", file=sys.stderr)

    def _dispatch(self, msg: Any, addr: Address) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.stats["rx_bad"] += 1
            return
        if kind == "UNKNOWN" or kind.startswith("UNKNOWN_"):
            self.stats["rx_unknown"] += 1
            return
        if msg.get_srcSystem() == self.sysid and msg.get_srcComponent() == COMPONENT_ID:
            self.stats["rx_ignored"] += 1  # our own echo
            return
        self.stats["rx_messages"] += 1
        if addr not in self._peers and len(self._peers) < MAX_PEERS:
            self._peers[addr] = self.clock.wall_s()
            self._greet()
        elif addr in self._peers:
            self._peers[addr] = self.clock.wall_s()
        target_sys = getattr(msg, "target_system", 0)
        target_comp = getattr(msg, "target_component", 0)
        if target_sys not in (0, self.sysid) or target_comp not in (0, COMPONENT_ID):
            self.stats["rx_ignored"] += 1
            return
        now = self.clock.wall_s()
        if kind == "COMMAND_LONG":
            self.commands.command_long(msg)
        elif kind == "COMMAND_INT":
            self.commands.command_int(msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.stats["rx_setpoints"] += 1
            self._setpoint(from_local_ned(msg, self.ap.state), now)
        elif kind == "SET_POSITION_TARGET_GLOBAL_INT":
            self.stats["rx_setpoints"] += 1
            self._setpoint(from_global_int(msg, self.frame, self.ap.home_enu_m[2]), now)
        elif kind in ("PARAM_REQUEST_READ", "PARAM_REQUEST_LIST", "PARAM_SET"):
            self._param(msg)
        elif kind == "PING":
            if msg.target_system == 0 and msg.target_component == 0:  # a request: answer it
                self.send(self.mav.ping_encode(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                               msg.get_srcComponent()))
        elif kind == "TIMESYNC":
            if msg.tc1 == 0:
                self.send(self.mav.timesync_encode(int(self.clock.sim_s * 1e9), msg.ts1))
        elif not self.fence.handle(msg, now):
            self.stats["rx_ignored"] += 1  # HEARTBEAT of the GCS and everything else

    def _greet(self) -> None:
        """A new peer: send the state a client needs at once instead of within a second."""
        for msg_id in (mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                       mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
                       mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                       mavlink.MAVLINK_MSG_ID_HOME_POSITION):
            self.send_message(msg_id)

    # -- parameters ------------------------------------------------------------------------

    def _param_value(self, name: str) -> None:
        table = self.ap.params
        if table.kind(name) == "int":
            value, kind = int_to_wire(round(table[name])), mavlink.MAV_PARAM_TYPE_INT32
        else:
            value, kind = table[name], mavlink.MAV_PARAM_TYPE_REAL32
        self.send(self.mav.param_value_encode(
            name.encode("ascii"), value, kind, len(table), table.index(name)))

    def _param(self, msg: Any) -> None:
        table = self.ap.params
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            for each in table.names():
                self._param_value(each)
            return
        if kind == "PARAM_REQUEST_READ" and msg.param_index >= 0:
            name = table.name_at(msg.param_index)
        else:
            name = decode_param_id(msg.param_id)
        if name is None or not table.has(name):
            return  # PX4 does not answer unknown parameters
        if kind == "PARAM_SET":
            value = float(msg.param_value)
            if table.kind(name) == "int" and msg.param_type != mavlink.MAV_PARAM_TYPE_REAL32:
                value = float(int_from_wire(value))  # bytewise, as PX4 expects
            table.set(name, round(value) if table.kind(name) == "int" else value)
        self._param_value(name)

    # -- offboard setpoints ----------------------------------------------------------------

    def _setpoint(self, parsed: Parsed, now_wall_s: float) -> None:
        if isinstance(parsed, Setpoint):
            self.ap.offboard_setpoint(parsed, now_wall_s)
            return
        self.stats["rx_ignored"] += 1
        if parsed == "unsupported" and now_wall_s - self._last_unsupported_s > 5.0:
            self._last_unsupported_s = now_wall_s  # say so, at most every 5 s
            self.statustext("Offboard: only position/velocity setpoints are supported",
                            mavlink.MAV_SEVERITY_WARNING)

    # -- fence ------------------------------------------------------------------------------

    def _lat_lon_to_en(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        e, n, _ = self.frame.to_enu(lat_deg, lon_deg, self.frame.alt0_m)
        return float(e), float(n)

    def preload_fence(self, polygon_latlon_deg: list[tuple[float, float]]) -> None:
        """Start with an inclusion fence on board, as if another station had uploaded it."""
        fence = build_fence(inclusion_items(polygon_latlon_deg), self._lat_lon_to_en)
        self.fence.fence = fence
        self._fence_set(fence)

    def _fence_set(self, fence: Fence) -> None:
        self.ap.fence = fence
        if self._on_fence is not None:
            self._on_fence(fence)
