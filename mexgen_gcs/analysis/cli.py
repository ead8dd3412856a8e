"""`mexgen-gcs analyze` and `mexgen-gcs replay`.

Frame: positions given on the command line are WGS84 (``--tag-position LAT,LON``) and are
converted to each flight's local ENU frame about its home. Exit codes: 0 done, 1 the analysis
could not be done (e.g. too few detections to calibrate), 2 bad input (a file that is not a
flight log of a version this program reads, an unknown tag, a bad option).

Options are read with defaults (``getattr``), so the handlers work with any parser that
defines at least ``log`` (one path or a list of paths).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib
import inspect
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from mexgen_gcs.errors import ConfigError, EstimationError, LogFormatError

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


def _err(command: str, text: str) -> None:
    print(f"mexgen-gcs {command}: {text}", file=sys.stderr)


def _logs(args: argparse.Namespace) -> list[str]:
    value = getattr(args, "logs", None) or getattr(args, "log", None)
    if value is None:
        return []
    if isinstance(value, str | Path):
        return [str(value)]
    return [str(v) for v in value]


def parse_lat_lon(text: str) -> tuple[float, float]:
    """'LAT,LON' in degrees -> (lat, lon); ValueError naming the problem."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2:
        raise ValueError(f"expected LAT,LON in degrees, found {text!r}")
    try:
        lat, lon = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"expected LAT,LON in degrees, found {text!r}") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ValueError(f"{text!r} is not a latitude in [-90, 90] and longitude in [-180, 180]")
    return lat, lon


def cmd_analyze(args: argparse.Namespace) -> int:
    """Report (one log) or comparison (several logs); optional calibration and exports."""
    from mexgen_gcs.analysis.flightdata import load_flight
    from mexgen_gcs.analysis.truth import find_truth, load_truth

    logs = _logs(args)
    if not logs:
        _err("analyze", "no flight log given")
        return EXIT_BAD_INPUT
    truth_arg = getattr(args, "truth", None)
    if truth_arg and len(logs) > 1:
        _err("analyze", "--truth goes with one log; with several, each log's own truth.jsonl "
             "is used")
        return EXIT_BAD_INPUT
    calibrate_tag = getattr(args, "calibrate", None)
    tag_position = getattr(args, "tag_position", None)
    if tag_position and not calibrate_tag:
        _err("analyze", "--tag-position is the known position for --calibrate TAG")
        return EXIT_BAD_INPUT
    given_lat_lon = None
    if tag_position:
        try:
            given_lat_lon = parse_lat_lon(str(tag_position))
        except ValueError as exc:
            _err("analyze", f"--tag-position: {exc}")
            return EXIT_BAD_INPUT
        if calibrate_tag == "all":
            _err("analyze", "--tag-position is one tag's position: name the tag with "
                 "--calibrate TAG, not all")
            return EXIT_BAD_INPUT
    t0 = time.perf_counter()
    try:
        flights = [load_flight(p) for p in logs]
        truths = []
        for f in flights:
            path = Path(truth_arg) if truth_arg else find_truth(f.log_dir)
            truths.append(load_truth(path) if path is not None else None)
    except (LogFormatError, ConfigError) as exc:
        _err("analyze", str(exc))
        return EXIT_BAD_INPUT
    for f, truth in zip(flights, truths, strict=True):
        _notes(f, truth)
    out_arg = getattr(args, "out", None)
    if len(flights) == 1:
        code = _analyze_one(flights[0], truths[0], Path(out_arg) if out_arg else None,
                            bool(getattr(args, "export", False)))
    else:
        code = _analyze_many(flights, truths, Path(out_arg) if out_arg else None,
                             bool(getattr(args, "export", False)))
    if code == EXIT_OK and calibrate_tag:
        code = _calibrate(flights, truths, str(calibrate_tag), given_lat_lon)
    print(f"analysed {len(flights)} log{'s' if len(flights) > 1 else ''} in "
          f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return code


def _notes(flight: Any, truth: Any = None) -> None:
    """What was skipped while reading, on stderr."""
    if flight.torn_last_line:
        print(f"note: {flight.path} ends with a torn line (a crash while writing); skipped it",
              file=sys.stderr)
    if flight.damage:
        print(f"note: {flight.path}: {flight.damage.describe()}", file=sys.stderr)
    if truth is not None and truth.damage:
        print(f"note: {truth.path}: {truth.damage.describe()}", file=sys.stderr)


def _analyze_one(flight: Any, truth: Any, out: Path | None, export: bool) -> int:
    from mexgen_gcs.analysis.export import write_exports
    from mexgen_gcs.analysis.report import write_report

    out_dir = out if out is not None else flight.log_dir / "report"
    report = write_report(flight, out_dir, truth)
    tot = report.summary.totals
    print(f"{flight.mission.name} ({tot.method}): {tot.end_reason}, {tot.duration_s:.0f} s, "
          f"{tot.distance_flown_m / 1000:.2f} km flown, {tot.tags_localised}/{tot.tags_total} "
          f"tags localised")
    for t in report.summary.tags:
        when = "not localised" if t.localised_after_s is None else (
            f"localised after {t.localised_after_s:.1f} s")
        err = f", error {t.error_at_localisation_m:.1f} m" if (
            t.error_at_localisation_m is not None) else ""
        print(f"  {t.tag_id}: {when}{err}, {t.detections} detections")
    print(f"report: {report.markdown}")
    print(f"        {report.html}")
    if export:
        ex = write_exports(flight, report.summary, out_dir)
        print(f"exports: {ex.geojson}, {ex.tags_csv}, {ex.path_csv}")
    return EXIT_OK


def _analyze_many(flights: list[Any], truths: list[Any], out: Path | None,
                  export: bool) -> int:
    from mexgen_gcs.analysis.compare import unique_labels, write_comparison
    from mexgen_gcs.analysis.export import write_exports
    from mexgen_gcs.analysis.summary import summarise

    summaries = [summarise(f, t) for f, t in zip(flights, truths, strict=True)]
    out_dir = out if out is not None else flights[0].log_dir.parent / "comparison"
    comp = write_comparison(flights, summaries, truths, out_dir)
    print(f"compared {len(flights)} flights ({', '.join(comp.methods)}): {comp.markdown}")
    print(f"        {comp.html}")
    if export:
        for f, s, label in zip(flights, summaries, unique_labels(flights), strict=True):
            ex = write_exports(f, s, out_dir / label)
            print(f"exports: {ex.geojson}, {ex.tags_csv}, {ex.path_csv}")
    return EXIT_OK


def _calibrate(flights: list[Any], truths: list[Any], tag: str,
               given_lat_lon: tuple[float, float] | None) -> int:
    from mexgen_gcs.analysis.calibration import calibrate_flights

    known = set().union(*(f.tag_ids for f in flights))
    if tag != "all" and tag not in known:
        _err("analyze", f"--calibrate: no tag {tag!r} in the mission (tags: "
             f"{', '.join(sorted(known))}, or all)")
        return EXIT_BAD_INPUT
    tags = tuple(sorted(known)) if tag == "all" else (tag,)
    entries = []
    for f, truth in zip(flights, truths, strict=True):
        given = None
        if given_lat_lon is not None:
            e, n, _ = f.frame.to_enu(given_lat_lon[0], given_lat_lon[1], f.frame.alt0_m)
            given = (float(e), float(n))
        entries.append((f, truth, given))
    if given_lat_lon is not None:
        source = "given"
    elif all(t is not None and all(x in t.tags for x in tags if x in f.tag_ids)
             for f, t in zip(flights, truths, strict=True)):
        source = "truth"
    else:
        source = "estimate"
    try:
        fit = calibrate_flights(entries, tags, source)
    except EstimationError as exc:
        _err("analyze", f"cannot calibrate: {exc}")
        return EXIT_FAILED
    radio = flights[0].mission.radio
    print(f"path-loss fit for {', '.join(tags)} against {source} positions: P0 "
          f"{fit.p0_db:.2f} dB (mission {radio.p0_db:g}), n {fit.path_loss_exponent:.3f} "
          f"(mission {radio.path_loss_exponent:g}), noise {fit.noise_std_db:.2f} dB (mission "
          f"{radio.noise_std_db:g})", file=sys.stderr)
    print(fit.radio_block(radio.model_dump()), end="")
    if len(tags) == 1:
        print(fit.tag_block(tags[0], flights[0].mission.tag(tags[0]).freq_hz), end="")
    return EXIT_OK


def _find_ui_replay() -> tuple[Callable[..., Any] | None, str]:
    """The terminal UI's run_replay(snapshots, speedup=...), or (None, why not)."""
    for name in ("mexgen_gcs.ui", "mexgen_gcs.ui.replay", "mexgen_gcs.ui.app"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        fn = getattr(module, "run_replay", None)
        if callable(fn):
            return fn, ""
    return None, "the terminal UI has no run_replay in this build"


def cmd_replay(args: argparse.Namespace) -> int:
    """Re-run the filters on a log and compare planner choices; UI or a table."""
    from mexgen_gcs.analysis.flightdata import load_flight
    from mexgen_gcs.analysis.replay import METHODS, default_other_method, replay, replay_table

    logs = _logs(args)
    if len(logs) != 1:
        _err("replay", "give exactly one flight log")
        return EXIT_BAD_INPUT
    method = getattr(args, "method", None)
    if method is not None and method not in METHODS:
        _err("replay", f"--method: expected one of {', '.join(METHODS)}, found {method!r}")
        return EXIT_BAD_INPUT
    try:
        flight = load_flight(logs[0])
    except (LogFormatError, ConfigError) as exc:
        _err("replay", str(exc))
        return EXIT_BAD_INPUT
    _notes(flight)
    method = method or default_other_method(flight.method)
    headless = bool(getattr(args, "headless", False)) or not sys.stdout.isatty()
    run_ui = None
    if not headless:
        run_ui, why = _find_ui_replay()
        if run_ui is None:
            print(f"note: {why}; printing the replay as a table", file=sys.stderr)
    n = len(flight.plans)
    print(f"replaying {logs[0]}: {n} plans, recorded {flight.method} against {method}",
          file=sys.stderr)
    t0 = time.perf_counter()
    steps = replay(flight, method, seed=getattr(args, "seed", None))
    print(f"replayed in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    if run_ui is None:
        print(replay_table(steps, method))
        return EXIT_OK
    return _run_ui(run_ui, flight, steps, float(getattr(args, "speedup", 1.0) or 1.0))


def _run_ui(run_ui: Callable[..., Any], flight: Any, steps: Sequence[Any],
            speedup: float) -> int:
    from mexgen_gcs.analysis.snapshots import build_snapshots
    from mexgen_gcs.analysis.truth import find_truth, load_truth

    truth_path = find_truth(flight.log_dir)
    try:
        truth = load_truth(truth_path) if truth_path is not None else None
    except LogFormatError as exc:
        print(f"note: no ground truth shown: {exc}", file=sys.stderr)
        truth = None
    if truth is not None and truth.damage:
        print(f"note: {truth.path}: {truth.damage.describe()}", file=sys.stderr)
    snaps = build_snapshots(flight, steps, truth)
    out = run_ui(snaps, speedup=speedup)
    if inspect.isawaitable(out):
        out = asyncio.run(_await(out))
    return int(out) if isinstance(out, int) else EXIT_OK


async def _await(awaitable: Any) -> Any:
    return await awaitable
