"""`mexgen-gcs experiment follow|localise ...`: batch Monte Carlo runs reproducing the paper.

No frames here. ``run_experiment`` is the scripted form: it builds the (start, repetition,
method) runs, skips those already in DIR/runs.csv, executes the rest on a local process pool
or a Dask cluster, stores each as it finishes, then writes summary.md and the plots.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TextIO

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.parallel import RunFailure, execute
from mexgen_gcs.experiments.progress import Progress
from mexgen_gcs.experiments.report import write_report
from mexgen_gcs.experiments.runner import RunSpec
from mexgen_gcs.experiments.scenario import (
    METHODS,
    ORACLE_PREFIX,
    Scenario,
    oracle_orbit_m,
    scenario,
)
from mexgen_gcs.experiments.store import RunStore

EXIT_OK, EXIT_FAILED, EXIT_INTERRUPTED = 0, 1, 130


@dataclass(frozen=True, slots=True)
class ExperimentOutcome:
    out_dir: Path
    planned: int
    """Runs asked for."""
    skipped: int
    """Of those, already in runs.csv (resumed)."""
    completed: int
    """Finished and stored by this invocation."""
    failures: tuple[RunFailure, ...]
    report: tuple[Path, ...]


def parse_methods(text: str) -> tuple[str, ...]:
    names = tuple(dict.fromkeys(m.strip() for m in text.split(",") if m.strip()))
    bad = [m for m in names if m not in METHODS and not m.startswith(ORACLE_PREFIX)]
    if bad or not names:
        raise ConfigError(f"--methods {text!r}: expected a comma-separated list of "
                          f"{', '.join(METHODS)}, oracle<R>, oraclestar<R>")
    for m in names:
        oracle_orbit_m(m)  # a clear error for a bad oracle radius
    return names


def run_specs(sc: Scenario, methods: tuple[str, ...], starts: int, reps: int,
              seed: int) -> list[RunSpec]:
    """Every run, ordered start, repetition, method (so finished runs come in pairs)."""
    return [RunSpec(sc, m, seed, s, r) for s in range(starts) for r in range(reps)
            for m in methods]


def run_experiment(sc: Scenario, methods: tuple[str, ...], *, starts: int, reps: int,
                   seed: int, out_dir: str | Path, workers: int | None = None,
                   scheduler: str | None = None, stream: TextIO | None = None,
                   command: str | None = None) -> ExperimentOutcome:
    """Run (or resume) an experiment into out_dir; see the module docstring."""
    out = Path(out_dir)
    specs = run_specs(sc, methods, starts, reps, seed)
    failures: list[RunFailure] = []
    completed = 0
    with RunStore(out, sc, seed, methods) as store:
        if command:
            with open(out / "commands.log", "a", encoding="utf-8") as fh:
                fh.write(f"{datetime.now(UTC).isoformat(timespec='seconds')}  {command}\n")
        pending = store.pending(specs)
        progress = Progress(len(pending), f"{sc.kind} {sc.model}", stream or sys.stderr)
        outcomes = execute(pending, workers=workers, scheduler=scheduler)
        try:
            for outcome in outcomes:
                if isinstance(outcome, RunFailure):
                    failures.append(outcome)
                    _log_failure(out, outcome)
                else:
                    store.append(outcome)
                    completed += 1
                progress.update(failed=isinstance(outcome, RunFailure))
        finally:
            outcomes.close()  # on an interrupt: cancel and stop the workers now
            progress.close()
    report = write_report(out)
    return ExperimentOutcome(out, len(specs), len(specs) - len(pending), completed,
                             tuple(failures), tuple(report))


def _log_failure(out: Path, failure: RunFailure) -> None:
    s = failure.spec
    with open(out / "failures.log", "a", encoding="utf-8") as fh:
        fh.write(f"--- {datetime.now(UTC).isoformat(timespec='seconds')} {s.scenario.model} "
                 f"{s.method} start {s.start} rep {s.rep}\n{failure.error}\n")


def _command(args: argparse.Namespace) -> str:
    parts = ["mexgen-gcs", "experiment", args.scenario, "--model", args.model, "--preset",
             getattr(args, "preset", "paper"), "--methods", args.methods, "--starts",
             str(args.starts), "--reps", str(args.reps), "--seed", str(args.seed), "--out",
             str(args.out)]
    if args.workers:
        parts += ["--workers", str(args.workers)]
    if args.scheduler:
        parts += ["--scheduler", args.scheduler]
    for flag, default in (("reality", "matched"), ("estimator", "classic")):
        value = getattr(args, flag, default)
        if value != default:
            parts += [f"--{flag}", value]
    if getattr(args, "finish", False):
        parts.append("--finish")
    if getattr(args, "min_alt", None) is not None:
        parts += ["--min-alt", f"{args.min_alt:g}"]
    if args.quick:
        parts.append("--quick")
    return shlex.join(parts)


def cmd_experiment(args: argparse.Namespace) -> int:
    """Entry point of `mexgen-gcs experiment`. Exit 0 when every run is stored, 1 if some
    failed (see DIR/failures.log; rerun to retry them), 2 on bad input, 130 if interrupted
    (rerun the same command to resume)."""
    methods = parse_methods(args.methods)
    sc = scenario(args.scenario, args.model, quick=bool(args.quick),
                  preset=getattr(args, "preset", "paper"),
                  reality=getattr(args, "reality", "matched"),
                  estimator=getattr(args, "estimator", "classic"),
                  finish=bool(getattr(args, "finish", False)))
    min_alt = getattr(args, "min_alt", None)
    if min_alt is not None:
        if min_alt >= sc.alt_m:
            print(f"mexgen-gcs experiment: --min-alt must be below the search altitude "
                  f"{sc.alt_m:g} m (got {min_alt:g})", file=sys.stderr)
            return 2
        sc = replace(sc, min_alt_m=float(min_alt))
    try:
        result = run_experiment(sc, methods, starts=args.starts, reps=args.reps,
                                seed=args.seed, out_dir=args.out, workers=args.workers,
                                scheduler=args.scheduler, command=_command(args))
    except KeyboardInterrupt:
        print(f"\nmexgen-gcs experiment: interrupted; finished runs are in {args.out}/runs.csv."
              " Run the same command again to resume.", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"{result.completed} runs done, {result.skipped} already in {result.out_dir}/runs.csv"
          f", {len(result.failures)} failed")
    print(f"summary: {result.out_dir / 'summary.md'}")
    if result.failures:
        print(f"failed runs are listed in {result.out_dir / 'failures.log'}; run the same "
              "command again to retry them", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK
