"""Fly the demo against the simulator with a wrong receiver clock and measure how well the GCS
learnt it: the offset of each ``receiver_clock`` record against the simulator's true receiver
clock at that moment, the drift estimate against the fault's, and each used pulse's corrected
time against the time the simulator emitted it (matched by the receiver's own timestamp).

    python scripts/receiver_clock_figures.py --offset-s 600 --drift-ppm 100 [--seed 3]
        [--speedup 10] [--no-correction] [--log DIR]   # --log: an existing flight's log
    python scripts/receiver_clock_figures.py --synthetic --offset-s 600 --drift-ppm 100
        # the estimator alone: 20 seeds of 600 heartbeats at 1 Hz, network delays 0.5 ms +
        # exponential(mean --delay-ms), no flight

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.mission.run import SitlPorts, run_sitl

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def measure(log_dir: Path, offset_s: float, drift_ppm: float) -> dict[str, Any]:
    log = read_flight_log(log_dir)
    truth = read_truth_file(log_dir).records
    start = float(truth[0]["start_unix"])
    clocks = list(log.of_type("receiver_clock"))
    if not clocks:
        (res,) = list(log.of_type("result"))
        return {"log": str(log_dir), "exit_code": res.get("exit_code"),
                "end_reason": res.get("end_reason"),
                "localised": sorted(res.get("localised") or {}),
                "receiver_clock_records": 0, "rejects": res.get("rejects")}
    # the true receiver offset at a record's mission time m: offset + ppm * 1e-6 * (m - start)
    err = np.array([r["offset_s"] - (offset_s + drift_ppm * 1e-6 * (r["t"] - start))
                    for r in clocks])
    drift_err = np.array([r["drift_ppm"] - drift_ppm for r in clocks if r["samples"] >= 20])
    sent = {float(r["t_sent"]): float(r["t"]) for r in truth
            if r["type"] in ("pulse", "clutter") and r.get("t_sent") is not None}
    used = [d for d in log.of_type("detection") if d["used"] and d.get("t_pulse_rx") is not None]
    pulse_err = np.array([d["t_pulse"] - sent[d["t_pulse_rx"]] for d in used
                          if d["t_pulse_rx"] in sent])
    (res,) = list(log.of_type("result"))

    def q(a: np.ndarray, p: float) -> float | None:
        return round(float(np.quantile(np.abs(a), p)), 4) if len(a) else None

    return {
        "log": str(log_dir), "offset_s": offset_s, "drift_ppm": drift_ppm,
        "exit_code": res.get("exit_code"), "end_reason": res.get("end_reason"),
        "localised": sorted(res.get("localised") or {}),
        "receiver_clock_records": len(clocks),
        "jumps": sum(r["kind"] == "jump" for r in clocks),
        "first_offset_s": clocks[0]["offset_s"] if clocks else None,
        "offset_error_s": {"median_abs": q(err, 0.5), "p95_abs": q(err, 0.95),
                           "max_abs": q(err, 1.0),
                           "mean": round(float(err.mean()), 4) if len(err) else None},
        "drift_error_ppm": {"median_abs": q(drift_err, 0.5), "p95_abs": q(drift_err, 0.95),
                            "last": round(float(drift_err[-1]), 1) if len(drift_err) else None},
        "pulse_time_error_s": {"n": len(pulse_err), "median_abs": q(pulse_err, 0.5),
                               "p95_abs": q(pulse_err, 0.95), "max_abs": q(pulse_err, 1.0)},
        "detections_used": len(used),
        "time_skew_rejects": (res.get("rejects") or {}).get("time_skew", 0),
    }


def synthetic(offset_s: float, drift_ppm: float, delay_ms: float, seeds: int = 20
              ) -> dict[str, Any]:
    """The estimator on fake heartbeats (a real vehicle's clock, a quiet network)."""
    from mexgen_gcs.io.rxclock import ReceiverClock

    m0 = 1.7e9
    off_err, drift_err, t_err = [], [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        clock = ReceiverClock()
        for i in range(600):
            r = m0 + i + offset_s + drift_ppm * 1e-6 * i
            clock.observe(r, m0 + i + 0.0005 + float(rng.exponential(delay_ms * 1e-3)))
            if i >= 60:  # after the first minute
                off_err.append(clock.offset_s - (offset_s + drift_ppm * 1e-6 * i))
                drift_err.append(clock.drift_ppm - drift_ppm)
                t_pulse = m0 + i - 0.3  # a pulse heard 0.3 s before this heartbeat
                r_pulse = t_pulse + offset_s + drift_ppm * 1e-6 * (i - 0.3)
                t_err.append(clock.to_mission(r_pulse) - t_pulse)
    a, b, c = np.abs(off_err), np.abs(drift_err), np.abs(t_err)
    return {"synthetic": True, "offset_s": offset_s, "drift_ppm": drift_ppm,
            "delay_ms_mean": delay_ms + 0.5, "seeds": seeds,
            "offset_error_s": {"median_abs": round(float(np.median(a)), 5),
                               "p95_abs": round(float(np.quantile(a, 0.95)), 5),
                               "mean": round(float(np.mean(off_err)), 5)},
            "drift_error_ppm": {"median_abs": round(float(np.median(b)), 2),
                                "p95_abs": round(float(np.quantile(b, 0.95)), 2)},
            "pulse_time_error_s": {"median_abs": round(float(np.median(c)), 5),
                                   "p95_abs": round(float(np.quantile(c, 0.95)), 5)}}


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--offset-s", type=float, default=600.0)
    p.add_argument("--drift-ppm", type=float, default=100.0)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--speedup", type=float, default=10.0)
    p.add_argument("--log", type=Path, default=None)
    p.add_argument("--synthetic", action="store_true")
    p.add_argument("--no-correction", action="store_true",
                   help="fly with receiver.clock_correction: false (times used as sent)")
    p.add_argument("--delay-ms", type=float, default=5.0)
    a = p.parse_args()
    if a.synthetic:
        print(json.dumps(synthetic(a.offset_s, a.drift_ppm, a.delay_ms)))
        return 0
    if a.log is None:
        faults = [{"kind": "clock_offset", "at_s": 0.0, "offset_s": a.offset_s},
                  {"kind": "clock_drift", "at_s": 0.0, "ppm": a.drift_ppm}]
        out = Path(tempfile.mkdtemp(prefix="rxclock-"))
        result = run_sitl(MISSIONS / "demo.yaml", seed=a.seed, speedup=a.speedup,
                          ports=SitlPorts.free(), log_dir=out,
                          overrides={"sim.faults": faults,
                                     "receiver.clock_correction": not a.no_correction})
        log_dir = Path(result.log_dir or out)
    else:
        log_dir = a.log
    print(json.dumps(measure(log_dir, a.offset_s, a.drift_ppm)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
