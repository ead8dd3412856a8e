"""The mission controller: one asyncio TaskGroup flies a whole tag-localisation mission.

Frames: the decision logic works in local ENU metres about home; telemetry and setpoints are
MAVLink NED / WGS84 and are converted at the edge (``_vehicle_state``, ``guidance``).

Tasks (each owned by the TaskGroup in ``run``): telemetry (the vehicle adapter's streams),
radio ingest, telemetry log, snapshot publisher, and the flight sequence; once airborne the
sequence adds the filter cadence, the planner loop (planning runs in a worker thread so
telemetry and setpoints never stall), the setpoint streamer and the safety monitor. The
sequence ends the group by raising ``_MissionOver``; every failure on the way becomes a logged
event and a safe action (hold, or return to launch), never an unhandled crash in the air.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mexgen_gcs.core.mission_core import MissionCore, PlanRequest, VehicleState
from mexgen_gcs.errors import MexgenError, PlannerError, VehicleError
from mexgen_gcs.io.clock import Clock
from mexgen_gcs.io.vehicle import Telemetry, Vehicle, wait_until
from mexgen_gcs.mission import safety, views
from mexgen_gcs.mission.guidance import Setpoint, velocity_setpoint
from mexgen_gcs.mission.planning import MissionPlanner, PlanOutcome
from mexgen_gcs.mission.snapshot import MissionSnapshot, SnapshotBus

log = logging.getLogger(__name__)

SETPOINT_HZ = 20.0
SAFETY_HZ = 5.0
SNAPSHOT_HZ = 4.0
TELEMETRY_LOG_HZ = 2.0
CLOUD_LOG_EVERY_S = 5.0


class _MissionOver(Exception):
    """Raised by the flight sequence to end the TaskGroup (a cancel scope)."""


@dataclass
class MissionResult:
    end_reason: str
    exit_code: int
    localised: dict[str, dict[str, float]]
    duration_s: float
    log_dir: str | None = None
    rejects: dict[str, int] = field(default_factory=dict)
    events: list[str] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class ControllerOptions:
    connect_timeout_s: float = 60.0
    ready_timeout_s: float = 60.0
    radio_wait_s: float = 15.0
    takeoff_timeout_s: float = 120.0
    landing_timeout_s: float = 900.0
    headless_progress_s: float = 10.0
    print_progress: bool = True


class MissionController:
    """Flies one mission. Construct with the mission, its ports and a MissionCore."""

    def __init__(
        self,
        mission: Any,
        vehicle: Vehicle,
        receiver: Any,
        clock: Clock,
        core: MissionCore,
        flight_log: Any,
        *,
        method: str,
        rng: np.random.Generator,
        connect_url: str,
        options: ControllerOptions | None = None,
        truth: Callable[[], dict[str, tuple[float, float]]] | None = None,
    ) -> None:
        self.mission = mission
        self.vehicle = vehicle
        self.receiver = receiver
        self.clock = clock
        self.core = core
        self.log = flight_log
        self.method = method
        self.rng = rng
        self.connect_url = connect_url
        self.opt = options or ControllerOptions()
        self.truth = truth
        self.frame = mission.local_frame()
        self.area = mission.search_area()
        self.bus = SnapshotBus()
        self.commands: asyncio.Queue[str] = asyncio.Queue(maxsize=32)
        # mutable mission state (owned by the event loop thread)
        self.state = "connecting"
        self.end_reason: str | None = None
        self.heading_deg: float | None = None
        self.hold_reason: str | None = None
        self.t_start = clock.now()
        self.t_airborne: float | None = None
        self.last_radio_t = clock.now()
        self.heartbeat_listening: tuple[str, ...] | None = None
        self.last_heartbeat_t = -math.inf
        self.last_plan: PlanOutcome | None = None
        self.next_plan_t = 0.0
        self.events: collections.deque[str] = collections.deque(maxlen=200)
        self.track: collections.deque[tuple[float, float]] = collections.deque(maxlen=600)
        self.det_times: dict[str, collections.deque[float]] = {
            t: collections.deque(maxlen=500) for t in core.tag_ids}
        self.link_was_lost = False
        self.operator_pause = False
        self.landed_ok = False
        self.planner = MissionPlanner(mission)
        self._executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="planner")
        self._last_cloud_t = -math.inf
        self._logged_rejects: dict[str, int] = {}

    # -- public ------------------------------------------------------------------------------

    def request(self, command: str) -> None:
        """Operator command: pause | resume | rtl | land | abort | method:<name>."""
        try:
            self.commands.put_nowait(command)
        except asyncio.QueueFull:
            self.event("command_dropped", command=command)

    def event(self, kind: str, level: int = logging.INFO, **fields: Any) -> None:
        text = kind + ("" if not fields else " " + " ".join(f"{k}={v}" for k, v in fields.items()))
        self.events.append(f"{self.clock.now() - self.t_start:7.1f}s {text}")
        log.log(level, text)
        self.log.write("event" if level < logging.ERROR else "error", t=self.clock.now(),
                       kind=kind, **fields)

    async def run(self) -> MissionResult:
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self._radio_ingest(), name="radio")
                tg.create_task(self._snapshots(), name="snapshots")
                tg.create_task(self._sequence(tg), name="sequence")
        except* _MissionOver:
            pass
        except* MexgenError as eg:
            for exc in eg.exceptions:
                self.event("mission_error", level=logging.ERROR, error=str(exc))
            self.end_reason = self.end_reason or f"error: {eg.exceptions[0]}"
        finally:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self.state = "done"
        self._log_rejects()
        self._publish()
        return self._result()

    # -- the flight sequence -----------------------------------------------------------------

    async def _sequence(self, tg: asyncio.TaskGroup) -> None:
        m = self.mission
        self.event("connecting", url=self.connect_url)
        await self.vehicle.connect(self.connect_url, self.opt.connect_timeout_s)
        tg.create_task(self.vehicle.run_telemetry(), name="telemetry")
        tg.create_task(self._telemetry_log(), name="telemetry-log")
        self.state = "preflight"
        await self.vehicle.wait_ready(self.opt.ready_timeout_s)
        tel = self.vehicle.hub.latest
        self.event("vehicle_ready", lat=tel.lat_deg, lon=tel.lon_deg, mode=tel.flight_mode)
        await self._preflight_checks(tel)
        if m.safety.upload_geofence:
            await self._upload_geofence()
        self._operator_before_arming()
        self.state = "takeoff"
        await self.vehicle.arm()
        self.event("armed")
        try:
            await self._fly(m)
        except* _MissionOver:
            pass
        except* Exception as eg:  # anything after arming: log it, then bring the vehicle home
            for exc in eg.exceptions:
                self.event("flight_error", level=logging.ERROR,
                           error=f"{type(exc).__name__}: {exc}")
            self.end_reason = self.end_reason or f"error: {eg.exceptions[0]}"
        await self._return_and_land()
        raise _MissionOver

    async def _fly(self, m: Any) -> None:
        await self.vehicle.takeoff(m.flight.alt_m)
        self.event("takeoff", alt_m=m.flight.alt_m)
        await wait_until(lambda: self.vehicle.hub.latest.rel_alt_m >= 0.95 * m.flight.alt_m,
                         self.opt.takeoff_timeout_s, "climb to mission altitude")
        self.t_airborne = self.clock.now()
        self.core.reset_clock(self.t_airborne)
        await self.vehicle.start_offboard(self.vehicle.hub.latest.yaw_deg)
        self.event("offboard_started")
        self.state = "searching"
        try:
            async with asyncio.TaskGroup() as flight:
                flight.create_task(self._filter_cadence(), name="filter")
                flight.create_task(self._planner_loop(), name="planner")
                flight.create_task(self._setpoints(), name="setpoints")
                flight.create_task(self._safety(), name="safety")
                flight.create_task(self._operator(), name="operator")
        except* _MissionOver:
            pass

    def _operator_before_arming(self) -> None:
        """An abort or RTL asked for before arming ends the mission on the ground."""
        while not self.commands.empty():
            cmd = self.commands.get_nowait()
            self.event("operator_command", command=cmd)
            if cmd in ("abort", "rtl", "land"):
                self.end_reason = f"operator_{cmd}"
                self.event("mission_end", reason=self.end_reason, armed=False)
                raise _MissionOver
            if cmd.startswith("method:") and cmd.split(":", 1)[1] in ("mexgen", "pim", "mc"):
                self.method = cmd.split(":", 1)[1]

    async def _preflight_checks(self, tel: Telemetry) -> None:
        e, n, _ = self.frame.to_enu(tel.home_lat_deg, tel.home_lon_deg, tel.home_abs_alt_m)
        d = float(self.area.distance_outside_m(np.array([float(e), float(n)])))
        if d > self.mission.safety.home_max_distance_m:
            self.end_reason = "home_too_far_from_area"
            self.event("preflight_failed", level=logging.ERROR, reason=self.end_reason,
                       distance_m=round(d, 1))
            raise _MissionOver
        self.event("home_checked", distance_outside_area_m=round(d, 1))
        self.event("waiting_for_radio")
        try:
            await wait_until(lambda: self.last_heartbeat_t > -math.inf, self.opt.radio_wait_s,
                             "radio heartbeat")
        except VehicleError:
            self.end_reason = "no_radio"
            self.event("preflight_failed", level=logging.ERROR, reason="no radio heartbeat within "
                       f"{self.opt.radio_wait_s:.0f} s on {self.mission.receiver.listen}")
            raise _MissionOver from None
        self.event("radio_ok")

    async def _upload_geofence(self) -> None:
        w = self.area.vertices_m
        lat, lon, _ = self.frame.to_geodetic(w[:, 0], w[:, 1], 0.0)
        try:
            await self.vehicle.upload_geofence(list(zip(lat.tolist(), lon.tolist(), strict=True)))
            self.event("geofence_uploaded", vertices=len(w))
        except VehicleError as exc:
            self.event("geofence_not_accepted", level=logging.WARNING, error=str(exc))

    async def _return_and_land(self) -> None:
        tel = self.vehicle.hub.latest
        self.state = "returning"
        if tel.flight_mode not in safety.VEHICLE_OWN_RETURN:
            for attempt in range(3):
                try:
                    await self.vehicle.return_to_launch()
                    self.event("rtl_commanded", reason=self.end_reason)
                    break
                except VehicleError as exc:
                    self.event("rtl_failed", level=logging.ERROR, error=str(exc), attempt=attempt)
                    await asyncio.sleep(1.0)
        try:
            await wait_until(lambda: not self.vehicle.hub.latest.in_air
                             and not self.vehicle.hub.latest.armed,
                             self.opt.landing_timeout_s, "land and disarm")
            self.state = "landed"
            self.landed_ok = True
            self.event("landed_and_disarmed")
        except VehicleError as exc:
            self.event("landing_not_confirmed", level=logging.ERROR, error=str(exc))

    def _finish(self, reason: str) -> None:
        if self.end_reason is None:
            self.end_reason = reason
            self.event("mission_end", reason=reason)
        raise _MissionOver

    # -- flight tasks ------------------------------------------------------------------------

    def _vehicle_state(self) -> tuple[VehicleState, tuple[float, float], float]:
        tel = self.vehicle.hub.latest
        e, n, u = self.frame.to_enu(tel.lat_deg, tel.lon_deg, tel.abs_alt_m)
        up = float(u) if math.isfinite(float(u)) else tel.rel_alt_m
        vs = VehicleState(np.array([float(e), float(n), up]),
                          np.array([tel.v_east_m_s, tel.v_north_m_s]), math.radians(tel.yaw_deg))
        return vs, (float(e), float(n)), tel.rel_alt_m

    async def _filter_cadence(self) -> None:
        period = self.mission.receiver.pulse_period_s
        hb_timeout = self.mission.receiver.heartbeat_timeout_s
        while True:
            await self.clock.sleep(period)
            t = self.clock.now()
            vs, _, _ = self._vehicle_state()
            if not np.all(np.isfinite(vs.xyz_m)):
                continue
            fresh = t - self.last_heartbeat_t <= hb_timeout
            listening = (self.heartbeat_listening if self.heartbeat_listening is not None
                         else self.core.tag_ids) if fresh else None
            report = self.core.pulse(t, vs.xyz_m, vs.yaw_rad, listening)
            for tid, est in report.estimates.items():
                self.log.write("estimate", t=t, tag=tid, existence=est.existence,
                               east_m=est.mean[0], north_m=est.mean[1], v_east_m_s=est.mean[2],
                               v_north_m_s=est.mean[3], cov_pos_m2=est.cov_pos,
                               radius_m=est.radius_m, localised=est.localised,
                               update=report.updated[tid], ess=est.ess)
            if t - self._last_cloud_t >= CLOUD_LOG_EVERY_S:
                self._last_cloud_t = t
                for tid in self.core.tag_ids:
                    self.log.write("cloud", t=t, tag=tid, en_m=self.core.particle_cloud(tid, 100))
            for rec in report.newly_localised:
                lat, lon, _ = self.frame.to_geodetic(rec.estimate.mean[0], rec.estimate.mean[1])
                self.event("tag_localised", tag=rec.tag_id,
                           after_s=round(rec.t - (self.t_airborne or self.t_start), 1),
                           lat=round(float(lat), 7), lon=round(float(lon), 7),
                           radius_m=round(rec.estimate.radius_m, 1))
            self._check_done(t)

    def _check_done(self, t: float) -> None:
        m = self.mission
        if m.kind == "follow":
            if self.t_airborne is not None and t - self.t_airborne >= m.follow.duration_s:
                self._finish("follow_complete")
        elif self.core.all_localised():
            self._finish("all_localised")

    async def _planner_loop(self) -> None:
        interval = self.mission.planner.replan_interval_s
        loop = asyncio.get_running_loop()
        while True:
            t = self.clock.now()
            vs, _, _ = self._vehicle_state()
            request = self.core.plan_request(t, vs) if np.all(np.isfinite(vs.xyz_m)) else None
            self.next_plan_t = t + interval
            if request is not None:
                await self._plan(loop, request, interval)
            await self.clock.sleep(max(self.next_plan_t - self.clock.now(), 0.0))

    async def _plan(self, loop: asyncio.AbstractEventLoop, request: PlanRequest,
                    interval: float) -> None:
        rng = self.rng.spawn(1)[0]
        budget_wall_s = max(interval / self.clock.speedup, 0.5)
        try:
            async with asyncio.timeout(budget_wall_s):
                outcome = await loop.run_in_executor(
                    self._executor, self.planner.plan, request, self.method, rng)
        except TimeoutError:
            self._hold("planner_overrun")
            self.event("planner_overrun", level=logging.ERROR, budget_s=round(budget_wall_s, 2))
            return
        except (PlannerError, ValueError, FloatingPointError) as exc:
            self._hold("planner_error")
            self.event("planner_error", level=logging.ERROR, error=str(exc))
            return
        self.last_plan = outcome
        if self.hold_reason in ("planner_error", "planner_overrun"):
            self.hold_reason = None
        self.heading_deg = outcome.chosen_heading_deg
        self.log.write("plan", t=request.t, method=outcome.method, targets=outcome.targets,
                       headings_deg=outcome.headings_deg,
                       rewards=[r if math.isfinite(r) else None for r in outcome.rewards],
                       chosen_heading_deg=outcome.chosen_heading_deg, timing_ms=outcome.timing_ms,
                       vehicle_en_m=request.vehicle.xyz_m[:2], all_pruned=outcome.all_pruned)

    def _hold(self, reason: str) -> None:
        if self.hold_reason != reason:
            self.hold_reason = reason
            self.state = "holding"

    async def _setpoints(self) -> None:
        speed = self.mission.flight.speed_m_s
        alt = self.mission.flight.alt_m
        margin = 0.0
        while True:
            tel = self.vehicle.hub.latest
            _, en, rel_alt = self._vehicle_state()
            heading = None if (self.hold_reason or self.operator_pause) else self.heading_deg
            if not all(map(math.isfinite, en)):
                sp = Setpoint(0.0, 0.0, 0.0, tel.yaw_deg, "hold")
            else:
                sp = velocity_setpoint(heading, speed, en, rel_alt, alt, self.area, tel.yaw_deg,
                                       margin)
                self.track.append(en)
            if self.state in ("searching", "holding"):
                self.state = "holding" if sp.reason == "hold" else "searching"
            try:
                await self.vehicle.set_velocity_ned(sp.v_north_m_s, sp.v_east_m_s, sp.v_down_m_s,
                                                    sp.yaw_deg)
                self.log.write("setpoint", t=self.clock.now(), v_north_m_s=sp.v_north_m_s,
                               v_east_m_s=sp.v_east_m_s, v_down_m_s=sp.v_down_m_s,
                               yaw_deg=sp.yaw_deg, reason=sp.reason)
            except VehicleError as exc:
                self.event("setpoint_failed", level=logging.WARNING, error=str(exc))
            await asyncio.sleep(1.0 / SETPOINT_HZ)

    async def _safety(self) -> None:
        s = self.mission.safety
        limits = safety.SafetyLimits(
            max_mission_time_s=s.max_mission_time_s, battery_rtl_percent=s.battery_rtl_percent,
            link_loss_timeout_s=s.link_loss_timeout_s, on_link_regained=s.on_link_regained,
            radio_heartbeat_timeout_s=self.mission.receiver.heartbeat_timeout_s,
            radio_loss_timeout_s=s.radio_loss_timeout_s)
        last = "ok"
        while True:
            await asyncio.sleep(1.0 / SAFETY_HZ)
            tel = self.vehicle.hub.latest
            t = self.clock.now()
            inp = safety.SafetyInputs(
                elapsed_s=t - (self.t_airborne or self.t_start),
                battery_percent=tel.battery_percent,
                link_age_s=self.vehicle.hub.age_s(), link_connected=tel.connected,
                radio_silent_s=t - self.last_radio_t, flight_mode=tel.flight_mode,
                link_was_lost=self.link_was_lost)
            d = safety.decide(inp, limits)
            if d.reason != last:
                self.event("safety", action=d.action.value, reason=d.reason,
                           level=logging.WARNING if d.action is not safety.Action.NONE
                           else logging.INFO)
                last = d.reason
            if d.action is safety.Action.RTL:
                self._finish(d.reason)
            elif d.action is safety.Action.HOLD:
                if d.reason == "link_lost":
                    self.link_was_lost = True
                self._hold(d.reason)
            elif d.action is safety.Action.RESUME_OFFBOARD:
                await self._resume_after_link()
            elif self.hold_reason in ("radio_silent", "link_lost"):
                self.hold_reason = None

    async def _resume_after_link(self) -> None:
        tel = self.vehicle.hub.latest
        self.link_was_lost = False
        self.hold_reason = None
        if tel.flight_mode != "OFFBOARD":
            if not tel.in_air:
                self._finish("landed_during_link_loss")
            try:
                await self.vehicle.start_offboard(tel.yaw_deg)
                self.event("offboard_resumed", previous_mode=tel.flight_mode)
            except VehicleError as exc:
                self.event("resume_failed", level=logging.ERROR, error=str(exc))
                self._finish("resume_failed")

    async def _operator(self) -> None:
        while True:
            cmd = await self.commands.get()
            self.event("operator_command", command=cmd)
            if cmd == "pause":
                self.operator_pause = True
            elif cmd == "resume":
                self.operator_pause = False
            elif cmd in ("rtl", "abort"):
                self._finish(f"operator_{cmd}")
            elif cmd == "land":
                with contextlib.suppress(VehicleError):
                    await self.vehicle.land()
                self._finish("operator_land")
            elif cmd.startswith("method:"):
                method = cmd.split(":", 1)[1]
                if method in ("mexgen", "pim", "mc"):
                    self.method = method

    # -- background tasks --------------------------------------------------------------------

    async def _radio_ingest(self) -> None:
        from mexgen_gcs.io.wire import Heartbeat

        queue = self.receiver.queue
        while True:
            _recv_t, _src, tag_id, msg = await queue.get()
            now = self.clock.now()
            self.last_radio_t = now
            if isinstance(msg, Heartbeat):
                self.last_heartbeat_t = now
                self.heartbeat_listening = (tuple(x for x in msg.listening if x in self.det_times)
                                            if msg.listening is not None else None)
                self.log.write("radio", t=now, kind="heartbeat", listening=msg.listening)
                continue
            xyz, yaw_rad = self._receiver_pose(msg)
            self.log.write("detection", t=now, tag=tag_id, rssi_db=msg.rssi_db, t_pulse=msg.t,
                           freq_hz=msg.freq_hz, rx_en_m=xyz, rx_yaw_deg=math.degrees(yaw_rad))
            try:
                self.core.add_detection(tag_id, msg.rssi_db, xyz, yaw_rad)
                self.det_times[tag_id].append(now)
            except (KeyError, ValueError) as exc:  # no pose yet, or a tag the core lacks
                self.event("detection_unused", level=logging.WARNING, tag=tag_id, error=str(exc))

    def _receiver_pose(self, det: Any) -> tuple[np.ndarray, float]:
        """The receiver pose carried in the datagram, else our telemetry now (ENU, radians)."""
        if det.lat is not None and det.lon is not None and det.alt_m is not None:
            e, n, u = self.frame.to_enu(det.lat, det.lon, det.alt_m)  # alt_m is AMSL
            yaw = math.radians(det.yaw_deg) if det.yaw_deg is not None else (
                math.radians(self.vehicle.hub.latest.yaw_deg))
            return np.array([float(e), float(n), float(u)]), yaw
        vs, _, _ = self._vehicle_state()
        return vs.xyz_m, vs.yaw_rad

    def _log_rejects(self) -> None:
        """Account for every rejected datagram in the log: per-reason deltas since the last
        record (a flood of junk costs one line per second, not one per datagram)."""
        now = dict(self.receiver.rejects)
        delta = {k: v - self._logged_rejects.get(k, 0) for k, v in now.items()
                 if v != self._logged_rejects.get(k, 0)}
        if delta:
            self.log.write("reject", t=self.clock.now(), counts=delta, total=now)
            self._logged_rejects = now

    async def _telemetry_log(self) -> None:
        last_print = time.monotonic()
        while True:
            self._log_rejects()
            tel = self.vehicle.hub.latest
            self.log.write("telemetry", t=self.clock.now(), lat=tel.lat_deg, lon=tel.lon_deg,
                           rel_alt_m=tel.rel_alt_m, v_north_m_s=tel.v_north_m_s,
                           v_east_m_s=tel.v_east_m_s, yaw_deg=tel.yaw_deg, mode=tel.flight_mode,
                           armed=tel.armed, in_air=tel.in_air, battery_percent=tel.battery_percent,
                           connected=tel.connected)
            if (self.opt.print_progress
                    and time.monotonic() - last_print >= self.opt.headless_progress_s):
                last_print = time.monotonic()
                print(self.progress_line(), flush=True)
            await self.clock.sleep(1.0 / TELEMETRY_LOG_HZ)  # mission time: same log at any speedup

    async def _snapshots(self) -> None:
        while True:
            self._publish()
            await asyncio.sleep(1.0 / SNAPSHOT_HZ)

    # -- views -------------------------------------------------------------------------------

    def progress_line(self) -> str:
        return views.progress_line(self)

    def snapshot(self) -> MissionSnapshot:
        return views.build_snapshot(self)

    def _publish(self) -> None:
        try:
            self.bus.publish(self.snapshot())
        except Exception as exc:  # a view must never take the mission down
            log.warning("snapshot failed: %s", exc)

    def _result(self) -> MissionResult:
        return views.build_result(self)
