"""Preflight's warm-up leaves nothing for the flight to compile: after it, a flight's filter
cadence, plans with every method and guidance setpoints start no numba compile."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

FLIGHT = textwrap.dedent("""
    import sys
    import numba.core.event as ev
    import numpy as np
    from mexgen_gcs.config.loader import load_mission
    from mexgen_gcs.core.generators import METHODS
    from mexgen_gcs.core.planner import VehicleState
    from mexgen_gcs.core.guidance import velocity_setpoint
    from mexgen_gcs.io.plans import MissionPlanner
    from mexgen_gcs.mission.warmup import warm_up

    mission = load_mission(sys.argv[1])
    if sys.argv[2] == "warm":
        warm_up(mission)

    class Compiles(ev.Listener):
        n = 0
        def on_start(self, event):
            Compiles.n += 1
        def on_end(self, event):
            pass

    ev.register("numba:compile", Compiles())
    rng = np.random.default_rng(7)
    core = mission.mission_core(rng)
    planner = MissionPlanner(mission)
    area = mission.search_area()
    for k in range(1, 41):  # 40 pulses on a circle, detections of every tag, plans every 5
        a = 0.05 * k
        rx = np.array([200.0 * np.cos(a), 200.0 * np.sin(a), 50.0])
        for tid in mission.tag_ids[: 1 + k % len(mission.tag_ids)]:
            core.add_detection(tid, float(rng.uniform(-70.0, -40.0)), rx, a)
        core.pulse(float(k), rx, a, listening=mission.tag_ids)
        if k % 5 == 0:
            req = core.plan_request(float(k), VehicleState(rx, np.array([5.0, 0.0]), a))
            for method in METHODS:
                planner.plan(req, method, rng)
        velocity_setpoint(45.0, 10.0, (float(rx[0]), float(rx[1])), 50.0, 50.0, area, 0.0)
    print(Compiles.n)
""")


def _start(tmp_path: Path, mode: str) -> subprocess.Popen[str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / mode)}  # an empty cache
    return subprocess.Popen([sys.executable, "-c", FLIGHT, str(ROOT / "missions/demo.yaml"),
                             mode], stdout=subprocess.PIPE, text=True, env=env)


def _compiles(proc: subprocess.Popen[str]) -> int:
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    return int(out.split()[-1])


@pytest.mark.long  # two Python processes compiling every kernel from an empty cache
@pytest.mark.timeout(900)
def test_after_warm_up_a_flight_compiles_nothing(tmp_path):
    cold, warm = _start(tmp_path, "cold"), _start(tmp_path, "warm")  # side by side: 2 cores
    assert _compiles(cold) > 0  # the flight alone does compile: the test can fail
    assert _compiles(warm) == 0
