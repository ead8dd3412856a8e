"""`mexgen-gcs bench filter|planner|experiment|receiver`: dispatch to the named benchmark."""

from __future__ import annotations

import argparse

from mexgen_gcs.bench.timing import pin_single_thread


def cmd_bench(args: argparse.Namespace) -> int:
    """Entry point of `mexgen-gcs bench`: dispatch to the named benchmark."""
    pin_single_thread()
    what = getattr(args, "what", None) or getattr(args, "target", None) or "planner"
    argv = ["--json"] if getattr(args, "json", False) else []
    if what == "experiment":
        from mexgen_gcs.bench import experiment as bench_experiment

        starts = getattr(args, "starts", None)
        return bench_experiment.main(argv + (["--starts", str(starts)] if starts else []))
    if what == "receiver":
        from mexgen_gcs.bench import receiver as bench_receiver

        return bench_receiver.main(argv)
    iterations = getattr(args, "iterations", None)
    if iterations:
        argv += ["--iterations", str(iterations)]
    if what == "filter":
        from mexgen_gcs.bench import filter as bench_filter

        return bench_filter.main(argv)
    if what == "planner":
        from mexgen_gcs.bench import planner as bench_planner

        return int(bench_planner.main(argv) or 0)
    print(f"unknown benchmark {what!r}; expected filter, planner, experiment or receiver")
    return 2
