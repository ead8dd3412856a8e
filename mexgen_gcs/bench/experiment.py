"""`mexgen-gcs bench experiment`: what the paper's whole Table II costs on this machine.

A fixed small batch of localisation runs (paper preset, seed 0, starts 0..S-1, repetition 0)
per model and method, run one after another in this process on one thread, so the figures
are per core: runs per hour, simulated seconds per CPU second, the CPU split by stage
(filter: detections and pulses; planner: belief sampling and planning; world: truth, radios,
vehicle and bookkeeping) and the projected wall time of the full table, 4 models x 3 methods x
50 starts x 30 repetitions = 18,000 runs, on N cores.

The projection takes each (model, method) cell's mean CPU per run from the batch, so it
assumes the batch's mix of early successes and full-length failures (a failed run lasts the
whole 1000 s) is the cell's; with a few starts per cell that is the projection's main
uncertainty, which is why the per-cell spread is printed too. No frames here.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from mexgen_gcs.bench.timing import emit, pin_single_thread
from mexgen_gcs.experiments.runner import RunSpec, run_one
from mexgen_gcs.experiments.scenario import scenario

TABLE_MODELS = ("rw", "cv", "cv-ift", "cv-ift-mismatch")
TABLE_METHODS = ("pim", "mc8", "mexgen")
TABLE_STARTS, TABLE_REPS = 50, 30
"""The paper's Table II: every model and method, 50 starts x 30 repetitions each."""
STAGES = ("filter", "planner", "world")


def run(starts: int = 2, models: Sequence[str] = TABLE_MODELS,
        methods: Sequence[str] = TABLE_METHODS, seed: int = 0, cores: Sequence[int] = (1, 2),
        quick: bool = False) -> dict[str, Any]:
    """Time the batch; ``quick`` uses the smoke scenario (short horizons) for tests."""
    cells: list[dict[str, Any]] = []
    for model in models:
        sc = scenario("localise", model, quick=quick, preset="paper")  # type: ignore[arg-type]
        for method in methods:
            cpu: list[float] = []
            sim_s = 0.0
            stages = dict.fromkeys(STAGES, 0.0)
            for start in range(starts):
                result = run_one(RunSpec(sc, method, seed, start, 0))
                cpu.append(sum(result.stages_s.values()))  # the run's CPU, unrounded
                sim_s += float(result.row["sim_s"])
                for k in STAGES:
                    stages[k] += result.stages_s.get(k, 0.0)
            total = sum(cpu)
            cells.append({
                "model": model, "method": method, "runs": len(cpu), "cpu_s": total,
                "cpu_per_run_s": total / len(cpu),
                "cpu_per_run_range_s": [min(cpu), max(cpu)],
                "runs_per_hour_per_core": 3600.0 * len(cpu) / total,
                "sim_s_per_cpu_s": sim_s / total,
                "stage_share": {k: v / total for k, v in stages.items()}})
    runs = sum(c["runs"] for c in cells)
    cpu_total = sum(c["cpu_s"] for c in cells)
    table_runs = len(models) * len(methods) * TABLE_STARTS * TABLE_REPS
    table_cpu_s = sum(c["cpu_per_run_s"] for c in cells) * TABLE_STARTS * TABLE_REPS
    stage_total = {k: sum(c["stage_share"][k] * c["cpu_s"] for c in cells) / cpu_total
                   for k in STAGES}
    return {
        "what": (f"localisation runs, paper preset, seed {seed}, {starts} start(s) x 1 rep per "
                 f"model and method, one thread{' (quick scenario)' if quick else ''}"),
        "cells": cells,
        "runs": runs,
        "runs_per_hour_per_core": 3600.0 * runs / cpu_total,
        "stage_share": stage_total,
        "table": {"runs": table_runs, "cpu_h": table_cpu_s / 3600.0,
                  "wall_h_on_cores": {str(n): table_cpu_s / 3600.0 / n for n in cores}},
    }


def _table(result: dict[str, Any]) -> str:
    lines = [result["what"],
             "model            method  runs  CPU/run s (min-max)   runs/h/core  sim s/CPU s"
             "  filter planner world"]
    for c in result["cells"]:
        lo, hi = c["cpu_per_run_range_s"]
        sh = c["stage_share"]
        lines.append(
            f"{c['model']:<16} {c['method']:<7} {c['runs']:>4}  {c['cpu_per_run_s']:7.2f} "
            f"({lo:5.2f}-{hi:6.2f})  {c['runs_per_hour_per_core']:11.0f}  "
            f"{c['sim_s_per_cpu_s']:11.0f}  {sh['filter']:6.0%} {sh['planner']:7.0%} "
            f"{sh['world']:5.0%}")
    sh = result["stage_share"]
    table = result["table"]
    walls = ", ".join(f"{h:.2f} h on {n} core{'s' if n != '1' else ''}"
                      for n, h in table["wall_h_on_cores"].items())
    lines += [
        f"all: {result['runs']} runs, {result['runs_per_hour_per_core']:.0f} runs/h/core; "
        f"CPU: filter {sh['filter']:.0%}, planner {sh['planner']:.0%}, world {sh['world']:.0%}",
        f"full table ({table['runs']} runs): {table['cpu_h']:.2f} CPU h = {walls}"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    pin_single_thread()
    p = argparse.ArgumentParser(prog="mexgen-gcs bench experiment")
    p.add_argument("--json", action="store_true")
    p.add_argument("--starts", type=int, default=2, help="runs per model and method")
    a = p.parse_args(argv)
    emit(run(starts=max(a.starts, 1)), a.json, _table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
