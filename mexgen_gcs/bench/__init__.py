"""Benchmarks (`mexgen-gcs bench filter|planner [--json]`): measured, never asserted in tests."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable
from typing import Any


def pin_single_thread() -> None:
    """Keep BLAS/OpenMP to one thread so figures are per core and repeatable."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def time_calls(fn: Callable[[], object], iterations: int, warmup: int = 3) -> dict[str, float]:
    """Median, min and max wall time of fn() in milliseconds after `warmup` untimed calls."""
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(iterations):
        t0 = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - t0) * 1e3)
    return {
        "median_ms": statistics.median(samples),
        "min_ms": min(samples),
        "max_ms": max(samples),
        "iterations": iterations,
    }


def emit(result: dict[str, Any], as_json: bool, table: Callable[[dict[str, Any]], str]) -> None:
    print(json.dumps(result, indent=2) if as_json else table(result))


def cmd_bench(args: argparse.Namespace) -> int:
    """Entry point of `mexgen-gcs bench`: dispatch to the named benchmark."""
    pin_single_thread()
    what = getattr(args, "what", None) or getattr(args, "target", None) or "planner"
    argv = ["--json"] if getattr(args, "json", False) else []
    iterations = getattr(args, "iterations", None)
    if iterations:
        argv += ["--iterations", str(iterations)]
    if what == "filter":
        from mexgen_gcs.bench import filter as bench_filter

        return bench_filter.main(argv)
    if what == "planner":
        from mexgen_gcs.bench import planner as bench_planner

        return int(bench_planner.main(argv) or 0)
    print(f"unknown benchmark {what!r}; expected filter or planner")
    return 2
