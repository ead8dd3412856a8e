"""Alongside the pilot's station, against real PX4 SITL (SIH): our GCS (`mexgen-gcs fly`,
MAVSDK, system 245) flies the demo on PX4's API link while a second client acting as
QGroundControl (pymavlink, system 255, GCS heartbeats on a GCS link of its own) switches the
vehicle to HOLD during the search and then lands it. Our mission ends as a takeover, logged,
and sends no command after it; PX4 follows the pilot's station to the ground."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import pytest
from pymavlink import mavutil

from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.mission.run import free_udp_port
from tests.mission.test_two_gcs import PX4_AUTO, PX4_LAND, PX4_LOITER, PX4_OFFBOARD, PilotStation
from tests.px4.conftest import Px4Factory
from tests.px4.px4_sitl import radios_on
from tests.sim.sim_helpers import DEMO_MISSION

pytestmark = pytest.mark.px4

M = mavutil.mavlink
K = 4.0
HOME = (-34.9212, 138.6011, 0.0)  # the demo mission's home


def test_the_pilots_station_takes_over_from_us_on_px4(px4_factory: Px4Factory,
                                                       tmp_path: Path) -> None:
    px4 = px4_factory(speed_factor=K, home=HOME)
    pilot = PilotStation(free_udp_port(), target_system=px4.sysid, search_s=8.0,
                         land_after_s=4.0)
    px4.add_gcs_link(free_udp_port(), pilot.port)
    thread = threading.Thread(target=pilot.run, daemon=True)
    radio_port = free_udp_port()
    with radios_on(px4, DEMO_MISSION, radio_port=radio_port, truth_dir=tmp_path / "radios"):
        thread.start()
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "mexgen_gcs", "fly", str(DEMO_MISSION), "--headless",
                 "--connect", px4.mavsdk_url, "--radio", f"udp://127.0.0.1:{radio_port}",
                 "--log-dir", str(tmp_path / "flights"), "--seed", "1",
                 "--accept-unsafe-params", "NAV_DLL_ACT"],
                capture_output=True, text=True, timeout=600)
        finally:
            pilot.stop.set()
            thread.join(timeout=5.0)
    print(proc.stdout[-3000:], proc.stderr[-3000:])
    assert pilot.hold_sent_mono is not None, pilot.modes
    assert pilot.acks.get(M.MAV_CMD_DO_SET_MODE) == M.MAV_RESULT_ACCEPTED
    assert (px4.sysid, 1) in pilot.heartbeats_from
    assert proc.returncode == 1, proc.stderr[-3000:]
    log = read_flight_log(next((tmp_path / "flights").iterdir()))
    (result,) = log.of_type("result")
    assert result["end_reason"] == "autopilot_takeover", result
    events = [r for r in log.records if r["type"] in ("event", "error")]
    i = next(n for n, r in enumerate(events) if r.get("kind") == "takeover")
    assert events[i].get("mode") == "HOLD", events[i]
    after = [r["kind"] for r in events[i:]]
    assert not [k for k in after if k.endswith("_commanded") or k == "offboard_resumed"], after
    # PX4 followed the pilot's station: HOLD, then LAND, never OFFBOARD again
    after_hold = [(main, sub) for t, main, sub in pilot.modes if t >= pilot.hold_sent_mono]
    assert (PX4_AUTO, PX4_LOITER) in after_hold, pilot.modes
    assert all(main != PX4_OFFBOARD for main, _ in after_hold), pilot.modes
    if pilot.land_sent_mono is not None:
        assert (PX4_AUTO, PX4_LAND) in after_hold, pilot.modes
