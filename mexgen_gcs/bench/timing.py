"""Timing helpers of the benchmarks: single-threaded BLAS, median/min/max of repeated calls."""

from __future__ import annotations

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
