"""End to end: the UI attached to a real SITL flight (``python -m sim`` child process, MAVSDK
over UDP loopback, wire-format radio), watched for a while, then quit: the vehicle is
commanded home, lands and disarms, the simulator exits and the flight log is closed."""

from __future__ import annotations

import functools
from pathlib import Path

import psutil
import pytest

from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.mission.run import SitlPorts, run_sitl
from mexgen_gcs.ui import app as ui_app
from mexgen_gcs.ui.confirm_screen import ConfirmScreen
from tests.ui.ui_helpers import screen_text, until

pytestmark = pytest.mark.e2e

MISSIONS = Path(__file__).parents[2] / "missions"
SPEEDUP = 20.0


def _sim_children() -> list[psutil.Process]:
    out = []
    for p in psutil.Process().children(recursive=True):
        try:
            if "sim" in " ".join(p.cmdline()):
                out.append(p)
        except psutil.Error:
            continue
    return out


def test_ui_on_a_real_flight_quits_with_the_vehicle_home(tmp_path):
    seen: dict[str, object] = {}

    async def operator(pilot) -> None:
        app = pilot.app

        def searching_with_plans() -> bool:
            s = app.snapshot
            return (s is not None and s.state == "searching" and s.plan is not None
                    and s.elapsed_s > 90.0)

        await until(pilot, searching_with_plans, timeout_s=120.0)
        await pilot.pause(0.3)
        seen["snapshot"] = app.snapshot
        seen["screen"] = screen_text(app)
        await pilot.press("q")
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        await pilot.press("y")
        await until(pilot, lambda: app.quit_requested)
        seen["quit_requested"] = True

    attached = functools.partial(ui_app.run_with_ui, headless=True, size=(120, 40),
                                 auto_pilot=operator)
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, runner=attached)

    assert seen.get("quit_requested"), seen
    screen = str(seen["screen"])
    for s in ("LINK OK", "OFFBOARD", "ARMED IN AIR", "SEARCHING", "Planner", "next re-plan",
              "T1", "T4", "p Pause", "r RTL", "q Quit"):
        assert s in screen, s
    assert result.end_reason == "operator_rtl", result.events[-10:]
    text = "\n".join(result.events)
    assert "operator_command command=rtl" in text
    assert "rtl_commanded" in text and "landed_and_disarmed" in text
    log = read_flight_log(result.log_dir)
    assert not log.torn_last_line
    assert log.records[-1]["type"] == "result"
    assert log.records[-1]["end_reason"] == "operator_rtl"
    kinds = [r.get("kind") for r in log.of_type("event")]
    assert kinds.index("rtl_commanded") < kinds.index("landed_and_disarmed")
    assert len(list(log.of_type("plan"))) >= 5
    assert _sim_children() == []
