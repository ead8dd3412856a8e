"""The state of one running mission: its ports, its decision core and everything that changes
while it flies. The phases and tasks read and change it; the views are pure functions of it.

Frames: local ENU metres about the mission home horizontally; heights (``up``) are above the
vehicle's own home (MAVSDK relative altitude); yaw in radians inside ``VehicleState``.
Times: ``t`` values are mission time from ``clock`` (the vehicle's clock, unix seconds).
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mexgen_gcs.config.mission import Mission
from mexgen_gcs.core.mission_core import MissionCore
from mexgen_gcs.core.planner import VehicleState
from mexgen_gcs.io.clock import Clock
from mexgen_gcs.io.records import Plan
from mexgen_gcs.io.snapshot import SnapshotBus
from mexgen_gcs.io.vehicle import Telemetry, Vehicle
from mexgen_gcs.mission.commander import HOLD, Commander
from mexgen_gcs.mission.logsink import MissionLog
from mexgen_gcs.mission.pose_history import Pose, PoseHistory
from mexgen_gcs.mission.state import (
    ControllerOptions,
    EndReason,
    MissionEnd,
    MissionState,
    ReturnAction,
    StopRequest,
    TakeoverInfo,
)

log = logging.getLogger("mexgen_gcs.mission")

#: a telemetry gap this long (wall s) means PX4 may have lost our offboard setpoints too
#: (COM_OF_LOSS_T, 1 s; PX4 SITL scales it with the speed factor so it stays ~1 s wall)
OFFBOARD_LOSS_GAP_S = 0.9


class MissionContext:
    def __init__(
        self,
        mission: Mission,
        vehicle: Vehicle,
        receiver: Any,
        clock: Clock,
        core: MissionCore,
        flight_log: MissionLog,
        *,
        method: str,
        rng: np.random.Generator,
        connect_url: str,
        options: ControllerOptions,
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
        self.opt = options
        self.truth = truth
        self.frame = mission.local_frame()
        self.area = mission.search_area()
        self.bus = SnapshotBus()
        self.commands: asyncio.Queue[str] = asyncio.Queue(maxsize=32)
        self.commander = Commander(vehicle, self.event, grace_s=options.mode_grace_s)
        self.poses = PoseHistory()
        self.interrupt = asyncio.Event()
        """Set on a takeover, a fault or a stop request: the running phase ends."""
        # what the mission is doing
        self.state = MissionState.CONNECTING
        self.phase = "preflight"
        self.end_reason: EndReason | None = None
        self.stop: StopRequest | None = None
        self.takeover: TakeoverInfo | None = None
        self.error: str | None = None
        self.faults = 0
        self.heading_deg: float | None = None
        self.target_alt_m: float | None = None
        """The altitude the last plan chose (None: flight.alt_m)."""
        self.hold_reason: str | None = None
        self.operator_pause = False
        self.link_was_lost = False
        self.landed_ok = False
        self.armed_by_us = False
        self.escalated = False
        """A stop that could not be obeyed: the mission exits without commanding more."""
        # times (mission clock)
        self.t_start = clock.now()
        self.t_airborne: float | None = None
        self.last_radio_t = clock.now()
        self.last_heartbeat_t = -math.inf
        self.heartbeat_listening: tuple[str, ...] | None = None
        self.next_plan_t = 0.0
        self.last_plan: Plan | None = None
        # for views
        self.events: collections.deque[str] = collections.deque(maxlen=200)
        self.standing_warnings: dict[str, str] = {}
        """Warnings that hold for the whole flight (no geofence on the vehicle), by kind: the
        UI shows them beside the live ones."""
        self.track: collections.deque[tuple[float, float]] = collections.deque(maxlen=600)
        self.det_times: dict[str, collections.deque[float]] = {
            t: collections.deque(maxlen=500) for t in core.tag_ids}
        self.counters: dict[str, int] = collections.Counter()
        self.faults_handled = 0
        """Faults a phase has already acted on (the watcher raises only for new ones)."""
        self.logged_rejects: dict[str, int] = {}
        self.print_progress = options.print_progress
        self._last_update_mono: float | None = None
        self.position_mono = -math.inf
        """When the last position arrived (time.monotonic)."""
        self.telemetry_gap_seen = False

    # -- logging -----------------------------------------------------------------------------

    def event(self, kind: str, level: int = logging.INFO, **fields: Any) -> None:
        """An event: in memory (UI, result), on the Python logger and in the flight log."""
        t = self.clock.now()
        text = kind + ("" if not fields else " " + " ".join(f"{k}={v}" for k, v in fields.items()))
        self.events.append(f"{t - self.t_start:7.1f}s {text}")
        log.log(level, text)
        self.log.write("event" if level < logging.ERROR else "error", t=t, kind=kind, **fields)

    def warn(self, kind: str, text: str, *, standing: str | None = None, **fields: Any) -> None:
        """A warning the operator must see: a `warning` record, an event (for the report), and
        with `standing` a line in the UI's warnings for the rest of the flight."""
        self.log.write("warning", t=self.clock.now(), kind=kind, text=text, **fields)
        self.event(kind, level=logging.WARNING, warning=text, **fields)
        if standing is not None:
            self.standing_warnings[kind] = standing

    def count(self, key: str, n: int = 1) -> int:
        self.counters[key] += n
        return self.counters[key]

    # -- what ends a phase -------------------------------------------------------------------

    def fault(self, where: str, exc: BaseException) -> None:
        """An unexpected exception in `where`: logged; the running phase takes its safe action."""
        self.faults += 1
        text = f"{where}: {type(exc).__name__}: {exc}"
        if self.error is None:
            self.error = text
        log.error("fault in %s", where, exc_info=exc)
        try:
            self.event("fault", level=logging.ERROR, where=where,
                       error=f"{type(exc).__name__}: {exc}")
        except Exception:  # the log itself may be what failed: the fault stands anyway
            log.exception("could not log the fault")
        self.interrupt.set()

    def request_stop(self, request: StopRequest) -> None:
        """End the mission (operator, signal, rule): the first request gives the reason."""
        if self.stop is None:
            self.stop = request
        elif request.operator and request.action is ReturnAction.LAND:
            self.stop = request  # an operator's land is never overridden
        self.interrupt.set()

    def finish(self, reason: EndReason, action: ReturnAction = ReturnAction.RTL) -> None:
        """End the mission from inside a phase task (raises MissionEnd)."""
        if self.end_reason is None:
            self.end_reason = reason
            self.event("mission_end", reason=reason)
        raise MissionEnd(reason, action)

    def set_end(self, reason: EndReason) -> None:
        if self.end_reason is None:
            self.end_reason = reason
            self.event("mission_end", reason=reason)

    # -- telemetry listeners -----------------------------------------------------------------

    def on_update(self, keys: frozenset[str], tel: Telemetry) -> None:
        """Hub listener: pose history, link gaps and the takeover check on every update."""
        now = self.vehicle.hub.latest.updated_wall
        if self._last_update_mono is not None and now - self._last_update_mono > (
                OFFBOARD_LOSS_GAP_S):
            self.telemetry_gap_seen = True
        self._last_update_mono = now
        if "lat_deg" in keys and tel.has_position:
            self.position_mono = now
            e, n, _ = self.frame.to_enu(tel.lat_deg, tel.lon_deg)
            self.poses.add(Pose(self.clock.now(), float(e), float(n), tel.rel_alt_m,
                                tel.yaw_deg))
        if keys & {"flight_mode", "armed", "in_air"}:
            self.check_takeover()

    def check_takeover(self) -> None:
        """A mode the GCS did not command (or a disarm in flight) is a takeover: stop every
        command at once, log it with the autopilot's reasons, end the phase. HOLD after a
        link gap is PX4's offboard-loss failsafe: the link rules decide (resume or return)."""
        what = self.commander.check()
        if what is None:
            return
        tel = self.vehicle.hub.latest
        if (tel.armed and tel.flight_mode == HOLD and self.phase == "search"
                and (self.link_was_lost or self.telemetry_gap_seen)):
            if not self.link_was_lost:
                self.event("offboard_lost", level=logging.WARNING, mode=tel.flight_mode,
                           reason="telemetry gap: PX4's offboard-loss failsafe")
            self.link_was_lost = True
            self.commander.expectation = None  # until the link rules resume or return
            return
        self.commander.release()
        info = TakeoverInfo(self.clock.now(), tel.flight_mode, tel.armed,
                            takeover_reason(what, self.vehicle.hub.recent_status_text(10.0)),
                            self.phase)
        if self.takeover is None:
            self.takeover = info
        self.state = MissionState.TAKEOVER
        self.event("takeover", level=logging.WARNING, mode=tel.flight_mode, armed=tel.armed,
                   phase=self.phase, what=what, reason=info.reason)
        self.set_end(EndReason.AUTOPILOT_TAKEOVER)
        self.interrupt.set()

    # -- the vehicle's state in the mission frame --------------------------------------------

    def vehicle_state(self) -> tuple[VehicleState, tuple[float, float], float]:
        """(state for the core, (east, north) m, height above the vehicle's home m)."""
        tel = self.vehicle.hub.latest
        e, n, _ = self.frame.to_enu(tel.lat_deg, tel.lon_deg)
        up = tel.rel_alt_m
        vs = VehicleState(np.array([float(e), float(n), up]),
                          np.array([tel.v_east_m_s, tel.v_north_m_s]), math.radians(tel.yaw_deg))
        return vs, (float(e), float(n)), up

    def mission_elapsed_s(self, t: float) -> float:
        return t - (self.t_airborne if self.t_airborne is not None else self.t_start)


SERIOUS = frozenset({"warning", "error", "critical", "alert", "emergency"})


def takeover_reason(what: str, recent: list[Any], info_within_s: float = 3.0) -> str:
    """What the GCS saw, plus what the autopilot said: its warnings and worse of the last ten
    seconds, else its messages of the last few seconds."""
    serious = [st for st in recent if st.severity in SERIOUS]
    now = time.monotonic()
    latest = [st for st in recent if st.mono_s >= now - info_within_s]
    said = [f"[{st.severity}] {st.text}" for st in (serious or latest)[-3:]]
    return what + ("; autopilot: " + " | ".join(said) if said else "")
