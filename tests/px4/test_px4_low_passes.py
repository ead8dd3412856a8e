"""Altitude actions against real PX4 SITL (SIH): the demo mission with `flight.min_alt_m: 20`
flown by `mexgen-gcs fly` at speed factor 4. The plans choose the lower altitude, PX4 follows
the GCS's down-velocity to it and no lower, and the mission ends as the demo does: every tag
localised, landed, exit 0 (the return climbs back to PX4's RTL_RETURN_ALT)."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

import pytest

from mexgen_gcs.io.flightlog import read_flight_log
from tests.px4.conftest import Px4Factory
from tests.px4.px4_sitl import radios_on
from tests.px4.test_px4_demo import HOME, TIMEOUT_S, K, free_udp_port
from tests.sim.sim_helpers import DEMO_MISSION

pytestmark = pytest.mark.px4


async def test_the_planner_flies_low_passes_on_px4(px4_factory: Px4Factory,
                                                   tmp_path: Path) -> None:
    mission = tmp_path / "demo_low.yaml"
    text = DEMO_MISSION.read_text(encoding="utf-8")
    assert "flight:\n" in text
    mission.write_text(text.replace("flight:\n", "flight:\n  min_alt_m: 20.0\n", 1),
                       encoding="utf-8")
    px4 = await asyncio.to_thread(px4_factory, speed_factor=K, home=HOME)
    radio_port = free_udp_port()
    with radios_on(px4, mission, radio_port=radio_port, truth_dir=tmp_path / "radios"):
        proc = await asyncio.to_thread(
            subprocess.run,
            [sys.executable, "-m", "mexgen_gcs", "fly", str(mission), "--headless",
             "--connect", px4.mavsdk_url, "--radio", f"udp://127.0.0.1:{radio_port}",
             "--log-dir", str(tmp_path / "flights"), "--seed", "1",
             "--accept-unsafe-params", "NAV_DLL_ACT"],  # as tests/px4/test_px4_demo.py
            capture_output=True, text=True, timeout=TIMEOUT_S)
    print(proc.stdout[-3000:])
    assert proc.returncode == 0, proc.stderr[-3000:]
    log = read_flight_log(next((tmp_path / "flights").iterdir()))
    (result,) = log.of_type("result")
    assert result["end_reason"] == "all_localised", result
    plans = list(log.of_type("plan"))
    low = [r["t"] for r in plans if r["chosen_alt_m"] == 20.0]
    print(f"{len(low)} of {len(plans)} plans chose 20 m")
    assert low, "no plan chose the lower altitude"
    searching = [r["rel_alt_m"] for r in log.of_type("telemetry")
                 if r["t"] > low[0] + 20.0 and r["mode"] == "OFFBOARD" and r["in_air"]]
    print(f"offboard altitude after the first low plan: {min(searching):.1f}-"
          f"{max(searching):.1f} m")
    assert searching and min(searching) < 30.0 and min(searching) > 20.0 - 3.0
    kinds = [r.get("kind") for r in log.of_type("event")]
    assert "landed_and_disarmed" in kinds and "takeover" not in kinds
