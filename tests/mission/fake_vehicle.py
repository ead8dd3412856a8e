"""A fake vehicle port (implements ``mexgen_gcs.io.vehicle.Vehicle``) and a fake radio receiver,
for fault-injection tests of the mission layer alone.

The fake behaves like PX4 where the mission depends on it: modes by MAVSDK name, takeoff then
HOLD, offboard only with a fresh setpoint and leaving it for HOLD after 1 s without one
(COM_OF_LOSS_T), RTL and LAND that land and auto-disarm, STATUSTEXT on every event, SYSTEM_TIME
at 5 Hz wall on its own clock running ``rate`` times the wall clock. Kinematics are a point
mass tracking the velocity setpoint with a 3 m/s^2 limit. Frames: ENU metres about the mission
home inside; WGS84 and NED at the port, as MAVSDK gives them.

Scripted faults: ``script`` entries fire once, ``after_s`` vehicle seconds after their
``trigger`` ('offboard': the first OFFBOARD; 'armed'; 'start'), calling an action on the fake
(``set_mode``, ``disarm_in_flight``, ``set_battery``, ``raise_in_telemetry``,
``end_telemetry``). ``fail`` makes the
first N calls of a command raise VehicleError. Invariant checked on every tick: never in
OFFBOARD without a setpoint for more than 1 s (``offboard_violations``).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.radio_udp import RadioEvent, ReceiverStats
from mexgen_gcs.io.vehicle import TelemetryHub
from mexgen_gcs.io.wire import Detection, Heartbeat
from sim.params import SPECS

TICK_S = 0.02
ACCEL_M_S2 = 3.0
OFFBOARD_LOSS_S = 1.0


@dataclass
class Scripted:
    trigger: str
    after_s: float
    action: Callable[[FakeVehicle], None]
    fired: bool = False


@dataclass
class CommandRecord:
    wall_s: float
    name: str
    mode_before: str
    args: tuple[Any, ...] = ()


@dataclass
class FakeVehicle:
    frame: LocalFrame
    rate: float = 20.0
    home_en_m: tuple[float, float] = (0.0, 0.0)
    home_alt_amsl_m: float = 100.0
    script: list[Scripted] = field(default_factory=list)
    fail: dict[str, int] = field(default_factory=dict)
    fail_with: dict[str, BaseException] = field(default_factory=dict)
    send_time: bool = True
    params: dict[str, float] = field(default_factory=lambda: {
        s.name: s.default for s in SPECS})
    """The vehicle's parameters (PX4 SITL's defaults, as the simulator serves them)."""
    existing_fence: list[tuple[float, float]] | None = None
    """A fence another station put on the vehicle before the mission."""

    def __post_init__(self) -> None:
        self.hub = TelemetryHub()
        self.mode = "HOLD"
        self.armed = False
        self.in_air = False
        self.pos = np.array([*self.home_en_m, 0.0])  # east, north, up (above home)
        self.vel = np.zeros(3)
        self.yaw_deg = 0.0
        self.battery = 90.0
        self.target_alt_m = 0.0
        self.setpoint: tuple[float, float, float, float] | None = None
        self.last_setpoint_wall = -math.inf
        self.offboard_violations: list[float] = []
        self.commands: list[CommandRecord] = []
        self.setpoints_by_mode: Counter[str] = Counter()
        self.statustexts: list[str] = []
        self.takeover_wall: float | None = None
        self.fence: list[tuple[float, float]] | None = None
        self.unix0 = 1.8e9
        self.t0_wall = time.monotonic()
        self.vehicle_s = 0.0
        self._marks: dict[str, float] = {"start": 0.0}
        self._raise: BaseException | None = None
        self._end_telemetry = False
        self.telemetry_runs = 0
        self.connected = False
        self.link_down_until = -math.inf

    # -- port: life ----------------------------------------------------------------------------

    async def connect(self, url: str, timeout_s: float) -> None:
        self._maybe_fail("connect")
        self.connected = True
        self.hub.update(connected=True)

    async def close(self) -> None:
        self.connected = False

    async def wait_ready(self, timeout_s: float) -> None:
        self._maybe_fail("wait_ready")
        async with asyncio.timeout(timeout_s):
            while not self.hub.latest.has_home:
                await asyncio.sleep(0.01)

    async def run_telemetry(self) -> None:
        self.telemetry_runs += 1
        last_time_sample = -math.inf
        last = time.monotonic()
        while True:
            await asyncio.sleep(TICK_S)
            now = time.monotonic()
            dt_wall, last = now - last, now
            self.vehicle_s += dt_wall * self.rate
            self._step(dt_wall * self.rate, now)
            if not self.link_up():
                continue
            self._publish()
            if self.send_time and now - last_time_sample >= 0.2:
                last_time_sample = now
                self.hub.time_sample(self.unix0 + self.vehicle_s)
            if self._raise is not None:
                exc, self._raise = self._raise, None
                raise exc
            if self._end_telemetry:
                self._end_telemetry = False
                return

    # -- port: commands ------------------------------------------------------------------------

    def _record(self, name: str, *args: Any) -> None:
        self.commands.append(CommandRecord(time.monotonic(), name, self.mode, args))
        self._maybe_fail(name)

    def _maybe_fail(self, name: str) -> None:
        if name in self.fail_with:
            raise self.fail_with.pop(name)
        if self.fail.get(name, 0) > 0:
            self.fail[name] -= 1
            raise VehicleError(name, "DENIED (scripted)")

    async def read_params(self, specs: Sequence[tuple[str, str]]) -> dict[str, float | None]:
        self._record("read_params", len(specs))
        return {name: self.params.get(name) for name, _ in specs}

    async def download_geofence(self) -> list[list[tuple[float, float]]]:
        self._record("download_geofence")
        return [] if self.existing_fence is None else [list(self.existing_fence)]

    async def upload_geofence(self, polygon_latlon_deg: list[tuple[float, float]]) -> bool:
        self._record("upload_geofence", len(polygon_latlon_deg))
        self.fence = polygon_latlon_deg
        return True

    async def arm(self) -> None:
        self._record("arm")
        self.armed = True
        self._marks["armed"] = self.vehicle_s
        self._text("Armed")

    async def takeoff(self, alt_m: float) -> None:
        self._record("takeoff", alt_m)
        if not self.armed:
            raise VehicleError("takeoff", "DENIED (not armed)")
        self.target_alt_m = alt_m
        self._set("TAKEOFF")
        self.in_air = True

    async def start_offboard(self, yaw_deg: float) -> None:
        self._record("start_offboard", yaw_deg)
        self.setpoint = (0.0, 0.0, 0.0, yaw_deg)
        self.last_setpoint_wall = time.monotonic()
        self._set("OFFBOARD")
        self._marks.setdefault("offboard", self.vehicle_s)

    async def set_velocity_ned(self, v_north_m_s: float, v_east_m_s: float, v_down_m_s: float,
                               yaw_deg: float) -> None:
        self._maybe_fail("set_velocity_ned")
        if not self.link_up():
            return
        self.setpoints_by_mode[self.mode] += 1
        self.setpoint = (v_north_m_s, v_east_m_s, v_down_m_s, yaw_deg)
        self.last_setpoint_wall = time.monotonic()

    async def hold(self) -> None:
        self._record("hold")
        self._set("HOLD")

    async def return_to_launch(self) -> None:
        self._record("return_to_launch")
        self._set("RETURN_TO_LAUNCH")

    async def land(self) -> None:
        self._record("land")
        self._set("LAND")

    # -- scripted actions ----------------------------------------------------------------------

    def set_mode(self, mode: str, text: str | None = None) -> None:
        if text:
            self._text(text, "critical")
        self._set(mode)
        self.takeover_wall = time.monotonic()

    def disarm_in_flight(self) -> None:
        self._text("Disarmed by the kill switch", "emergency")
        self.armed = False
        self.in_air = False
        self.pos[2] = 0.0
        self.takeover_wall = time.monotonic()

    def raise_in_telemetry(self, exc: BaseException) -> None:
        self._raise = exc

    def end_telemetry(self) -> None:
        """The telemetry streams end (run_telemetry returns, once)."""
        self._end_telemetry = True

    def drop_link(self, wall_s: float) -> None:
        """Nothing in either direction for `wall_s` wall seconds (setpoints are lost too)."""
        self.link_down_until = time.monotonic() + wall_s

    def link_up(self) -> bool:
        return time.monotonic() >= self.link_down_until

    def commands_after_takeover(self) -> list[str]:
        if self.takeover_wall is None:
            return []
        return [c.name for c in self.commands if c.wall_s > self.takeover_wall]

    # -- the simulation ------------------------------------------------------------------------

    def _text(self, text: str, severity: str = "info") -> None:
        self.statustexts.append(text)
        if self.connected and self.link_up():
            self.hub.status_text(severity, text)

    def _set(self, mode: str) -> None:
        if mode != self.mode:
            self.mode = mode
            self._text(f"mode {mode}")

    def _step(self, dt: float, now_wall: float) -> None:
        for s in self.script:
            mark = self._marks.get(s.trigger)
            if not s.fired and mark is not None and self.vehicle_s - mark >= s.after_s:
                s.fired = True
                s.action(self)
        if self.mode == "OFFBOARD" and self.armed and (
                now_wall - self.last_setpoint_wall > OFFBOARD_LOSS_S):
            if self.link_up() and now_wall - self.link_down_until > OFFBOARD_LOSS_S:
                self.offboard_violations.append(now_wall - self.last_setpoint_wall)
            self._text("Failsafe: offboard setpoints lost, holding", "warning")
            self._set("HOLD")
        if self.mode in ("RETURN_TO_LAUNCH", "LAND") and self.armed and not self.in_air:
            self.armed = False  # PX4 disarms a landed vehicle asked to land
            self._text("Disarmed (landed)")
        want = np.zeros(3)
        if not self.armed:
            self.vel[:] = 0.0
            return
        if self.mode == "TAKEOFF":
            want[2] = 5.0 if self.pos[2] < self.target_alt_m else 0.0
            if self.pos[2] >= self.target_alt_m:
                self._set("HOLD")
        elif self.mode == "OFFBOARD" and self.setpoint is not None:
            vn, ve, vd, yaw = self.setpoint
            want = np.array([ve, vn, -vd])
            self.yaw_deg = yaw
        elif self.mode == "RETURN_TO_LAUNCH":
            to_home = np.asarray(self.home_en_m) - self.pos[:2]
            d = float(np.hypot(*to_home))
            if d > 2.0:
                want[:2] = to_home / d * min(10.0, d)
            else:
                want[2] = -5.0
        elif self.mode == "LAND":
            want[2] = -5.0
        dv = want - self.vel
        limit = ACCEL_M_S2 * dt
        norm = float(np.linalg.norm(dv[:2]))
        if norm > limit:
            dv[:2] *= limit / norm
        self.vel += dv
        self.pos += self.vel * dt
        if self.pos[2] <= 0.0 and self.in_air and self.mode in ("LAND", "RETURN_TO_LAUNCH") \
                and self.vel[2] < 0:
            self.pos[2] = 0.0
            self.vel[:] = 0.0
            self.in_air = False
            self.armed = False
            self._text("Landed, disarmed")

    def _publish(self) -> None:
        e, n, up = self.pos
        lat, lon, _ = self.frame.to_geodetic(e, n)
        hlat, hlon, _ = self.frame.to_geodetic(*self.home_en_m)
        self.hub.update(
            lat_deg=float(lat), lon_deg=float(lon), abs_alt_m=self.home_alt_amsl_m + up,
            rel_alt_m=float(up), v_north_m_s=float(self.vel[1]), v_east_m_s=float(self.vel[0]),
            v_down_m_s=float(-self.vel[2]), yaw_deg=self.yaw_deg % 360.0, armed=self.armed,
            in_air=self.in_air, flight_mode=self.mode, battery_percent=self.battery,
            global_position_ok=True, home_position_ok=True, armable=True,
            home_lat_deg=float(hlat), home_lon_deg=float(hlon),
            home_abs_alt_m=self.home_alt_amsl_m, connected=True)


class FakeReceiver:
    """Heartbeats once a vehicle second and, optionally, a detection of `tag` per heartbeat at
    the vehicle's current pose (rssi from a fixed tag position), timestamped on the vehicle
    clock. Counters as RadioReceiver keeps them."""

    def __init__(self, vehicle: FakeVehicle, tags: tuple[str, ...], *,
                 tag_en_m: tuple[float, float] | None = None, silent: bool = False) -> None:
        self.vehicle = vehicle
        self.tags = tags
        self.tag_en_m = tag_en_m
        self.silent = silent
        self.queue: asyncio.Queue[RadioEvent] = asyncio.Queue(maxsize=1000)
        self.rejects: Counter[str] = Counter()
        self.accepted = 0

    async def run(self) -> None:
        while True:
            await asyncio.sleep(1.0 / self.vehicle.rate)
            if self.silent:
                continue
            t = self.vehicle.unix0 + self.vehicle.vehicle_s
            self._put(Heartbeat(t, None))
            if self.tag_en_m is not None and self.vehicle.in_air:
                d = float(np.hypot(*(self.vehicle.pos[:2] - np.asarray(self.tag_en_m))))
                rssi = -7.0 - 15.0 * math.log10(max(math.hypot(d, self.vehicle.pos[2]), 1.0))
                self._put(Detection(t, self.tags[0], None, rssi))

    def _put(self, ev: Any) -> None:
        self.accepted += 1
        tag = ev.tag if isinstance(ev, Detection) else None
        self.queue.put_nowait(RadioEvent(ev.t, ("127.0.0.1", 1), tag, ev))

    def stats(self) -> ReceiverStats:
        return ReceiverStats(datagrams=self.accepted, accepted=self.accepted, accepted_by_tag={},
                             heartbeats=0, rejects=dict(self.rejects),
                             queue_depth=self.queue.qsize(), last_heartbeat_s=None,
                             last_detection_s=None, socket_errors=0)
