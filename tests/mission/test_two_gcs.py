"""Alongside the pilot's station: the simulator, our GCS (run_sitl: MAVSDK, system 245
component 190) and a second MAVLink client acting as QGroundControl (pymavlink, system 255
component 190, GCS heartbeats at 1 Hz on the simulator's second GCS link). The second station
switches the vehicle to HOLD during the search: our mission ends as a takeover, logged, and
never commands again; the pilot's station then lands the vehicle. A fence the pilot's station
left on the vehicle is shown and not replaced (exit 2)."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from mexgen_gcs.config.area_files import write_area_file
from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.mission.run import SitlPorts, free_udp_port, run_sitl

pytestmark = pytest.mark.e2e

MISSIONS = Path(__file__).parents[2] / "missions"
M = mavutil.mavlink
PX4_AUTO, PX4_LOITER, PX4_LAND, PX4_OFFBOARD = 4, 3, 6, 6
QGC_SYSID, QGC_COMPID = 255, 190


@dataclass
class PilotStation:
    """The second ground station: heartbeats, watches the mode, switches to HOLD once the
    vehicle has flown offboard for `search_s` wall seconds, then LAND `land_after_s` later."""

    port: int
    target_system: int = 1
    search_s: float = 4.0
    land_after_s: float = 4.0
    stop: threading.Event = field(default_factory=threading.Event)
    modes: list[tuple[float, int, int]] = field(default_factory=list)
    hold_sent_mono: float | None = None
    land_sent_mono: float | None = None
    acks: dict[int, int] = field(default_factory=dict)
    heartbeats_from: set[tuple[int, int]] = field(default_factory=set)

    def run(self) -> None:
        conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}",
                                          source_system=QGC_SYSID, source_component=QGC_COMPID)
        offboard_since: float | None = None
        next_hb = 0.0
        try:
            while not self.stop.is_set():
                now = time.monotonic()
                if now >= next_hb and self.heartbeats_from:  # udpin: answer who we heard
                    conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                            M.MAV_STATE_ACTIVE)
                    next_hb = now + 1.0
                msg = conn.recv_match(type=["HEARTBEAT", "COMMAND_ACK"], blocking=True,
                                      timeout=0.2)
                if msg is None:
                    continue
                if msg.get_type() == "COMMAND_ACK":
                    self.acks[msg.command] = msg.result
                    continue
                self.heartbeats_from.add((msg.get_srcSystem(), msg.get_srcComponent()))
                if msg.type == M.MAV_TYPE_GCS:
                    continue
                main, sub = (msg.custom_mode >> 16) & 0xFF, (msg.custom_mode >> 24) & 0xFF
                if not self.modes or self.modes[-1][1:] != (main, sub):
                    self.modes.append((now, main, sub))
                if main == PX4_OFFBOARD:
                    offboard_since = offboard_since or now
                if (self.hold_sent_mono is None and offboard_since is not None
                        and now - offboard_since >= self.search_s):
                    self._set_mode(conn, self.target_system, PX4_AUTO, PX4_LOITER)
                    self.hold_sent_mono = now
                if (self.hold_sent_mono is not None and self.land_sent_mono is None
                        and now - self.hold_sent_mono >= self.land_after_s):
                    self._set_mode(conn, self.target_system, PX4_AUTO, PX4_LAND)
                    self.land_sent_mono = now
        finally:
            conn.close()

    @staticmethod
    def _set_mode(conn: Any, target_system: int, main: int, sub: int) -> None:
        conn.mav.command_long_send(target_system, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                   M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub, 0, 0, 0, 0)


def test_a_mode_change_from_the_pilots_station_is_a_takeover(tmp_path: Path) -> None:
    ports = SitlPorts.free()
    pilot = PilotStation(free_udp_port())
    thread = threading.Thread(target=pilot.run, daemon=True)
    thread.start()
    try:
        result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=5.0, ports=ports,
                          log_dir=tmp_path, sim_args=["--gcs", f"127.0.0.1:{pilot.port}"])
    finally:
        pilot.stop.set()
        thread.join(timeout=5.0)
    assert pilot.hold_sent_mono is not None and pilot.land_sent_mono is not None
    assert pilot.acks.get(M.MAV_CMD_DO_SET_MODE) == M.MAV_RESULT_ACCEPTED
    assert (1, 1) in pilot.heartbeats_from  # the vehicle, seen by the pilot's station
    assert result.end_reason == "autopilot_takeover" and result.exit_code == 1
    assert result.takeover is not None and result.takeover["mode"] == "HOLD"
    records = read_flight_log(result.log_dir).records
    events = [r for r in records if r["type"] in ("event", "error")]
    i = next(n for n, r in enumerate(events) if r.get("kind") == "takeover")
    after = [r["kind"] for r in events[i:]]
    assert not [k for k in after if k.endswith("_commanded") or k == "offboard_resumed"], after
    assert "landed_and_disarmed" in after
    # the commander sent no vehicle command after the takeover
    sent_before = {k for k in result.counters if k.startswith("sent_")}
    assert "sent_return_to_launch" not in sent_before and "sent_land" not in sent_before
    # the vehicle followed the pilot's station: HOLD, then LAND; never OFFBOARD again
    after_hold = [(main, sub) for t, main, sub in pilot.modes if t >= pilot.hold_sent_mono]
    assert (PX4_AUTO, PX4_LOITER) in after_hold and (PX4_AUTO, PX4_LAND) in after_hold
    assert all(main != PX4_OFFBOARD for main, _ in after_hold)


def test_a_fence_left_by_the_pilots_station_is_shown_and_kept(tmp_path: Path) -> None:
    fence = tmp_path / "pilot.plan"
    write_area_file(fence, [(-34.925, 138.595), (-34.925, 138.607), (-34.91, 138.607),
                            (-34.91, 138.595)], (-34.9212, 138.6011, 0.0), "pilot")
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=5.0, ports=SitlPorts.free(),
                      log_dir=tmp_path / "flights", sim_args=["--fence", str(fence)])
    assert result.end_reason == "geofence_on_vehicle" and result.exit_code == 2
    records = read_flight_log(result.log_dir).records
    (failed,) = [r for r in records if r.get("kind") == "preflight_failed"]
    assert len(failed["shapes"]) == 1 and len(failed["shapes"][0]) == 4
    assert failed["shapes"][0][0] == pytest.approx([-34.925, 138.595], abs=1e-6)
    assert not [r for r in records if r.get("kind") in ("armed", "geofence_uploaded")]
