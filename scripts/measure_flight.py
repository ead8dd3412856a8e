"""Measure a SITL flight of the GCS: wall time, CPU share and peak memory of the GCS process
(the simulator child excluded), and re-plan interval jitter from the flight log.

    python scripts/measure_flight.py missions/demo.yaml --speedup 10 [--headless] [--seed 1]

Prints one JSON object. Without --headless it needs a terminal (run it inside tmux).
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

from mexgen_gcs.io.flightlog import read_flight_log


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("mission")
    p.add_argument("--speedup", type=float, default=1.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--headless", action="store_true")
    a = p.parse_args()
    out = Path(tempfile.mkdtemp(prefix="measure-"))
    cmd = [sys.executable, "-m", "mexgen_gcs", "sitl", a.mission, "--speedup", str(a.speedup),
           "--seed", str(a.seed), "--log-dir", str(out),
           "--mavlink-port", "0", "--radio-port", "0"] + (["--headless"] if a.headless else [])
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE if a.headless else None)
    ps = psutil.Process(proc.pid)
    peak_rss = 0
    cpu0 = ps.cpu_times()
    while proc.poll() is None:
        try:
            peak_rss = max(peak_rss, ps.memory_info().rss)
            cpu = ps.cpu_times()
        except psutil.NoSuchProcess:
            break
        time.sleep(0.5)
    wall = time.monotonic() - t0
    cpu_s = (cpu.user - cpu0.user) + (cpu.system - cpu0.system)
    log_dir = next(out.iterdir())
    log = read_flight_log(log_dir)
    plans = [r["t"] for r in log.of_type("plan")]
    results = list(log.of_type("result"))
    gaps = [b - a_ for a_, b in itertools.pairwise(plans)]
    result = results[-1] if results else {}
    interval = log.header["mission"]["planner"]["replan_interval_s"]
    print(json.dumps({
        "mission": a.mission, "speedup": a.speedup, "headless": a.headless,
        "exit_code": proc.returncode, "end_reason": result.get("end_reason"),
        "mission_time_s": round(result.get("duration_s", float("nan")), 1),
        "wall_s": round(wall, 1), "gcs_cpu_s": round(cpu_s, 1),
        "gcs_cpu_share_of_one_core": round(cpu_s / wall, 3),
        "gcs_peak_rss_mb": round(peak_rss / 2**20, 1),
        "plans": len(plans), "replan_interval_s": interval,
        "replan_gap_mean_s": round(statistics.mean(gaps), 3) if gaps else None,
        "replan_jitter_std_s": round(statistics.pstdev(gaps), 3) if gaps else None,
        "replan_gap_max_dev_s": round(max(abs(g - interval) for g in gaps), 3) if gaps else None,
        "log_dir": str(log_dir),
    }, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
