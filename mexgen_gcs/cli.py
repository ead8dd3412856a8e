"""The `mexgen-gcs` command line: every subcommand's arguments are defined here, in one place.

`check` is implemented here; the others are looked up lazily from the modules that implement
them (`module:function`, called as ``handler(args) -> int``), so that `check` works without
the flight stack. Exit codes (a contract): 0 success, 1 mission failed or aborted, 2 bad input.
No frames here.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Callable, Sequence

from mexgen_gcs import __version__
from mexgen_gcs.core.generators import METHODS
from mexgen_gcs.errors import ConfigError, MexgenError

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2

DEFAULT_CONNECT = "udpin://0.0.0.0:14540"
#: experiment choices, spelled here so ``--help`` imports nothing heavy; tests/test_cli_choices.py
#: checks them against experiments.scenario and core.reality, where they are defined
EXPERIMENT_MODELS = ("static", "rw", "cv", "cv-ift", "cv-ift-mismatch")
REALITIES = ("matched", "tx-power", "path-loss", "antenna", "shadowing", "fading", "terrain",
             "compass", "field")
ESTIMATORS = ("classic", "robust")

#: subcommand -> "module:function" of its handler.
HANDLERS: dict[str, str] = {
    "sitl": "mexgen_gcs.ui.commands:cmd_sitl",
    "fly": "mexgen_gcs.ui.commands:cmd_fly",
    "analyze": "mexgen_gcs.analysis.cli:cmd_analyze",
    "replay": "mexgen_gcs.analysis.cli:cmd_replay",
    "experiment": "mexgen_gcs.experiments.cli:cmd_experiment",
    "bench": "mexgen_gcs.bench.cli:cmd_bench",
    "receive": "mexgen_gcs.receiver.cli:cmd_receive",
}


def build_parser() -> argparse.ArgumentParser:
    """The whole command line."""
    parser = argparse.ArgumentParser(
        prog="mexgen-gcs",
        description="Ground control for finding VHF radio-tagged objects with a multirotor.",
        epilog="Exit codes: 0 success, 1 mission failed or aborted, 2 bad input.",
    )
    parser.add_argument("--version", action="version", version=f"mexgen-gcs {__version__}")
    parser.add_argument("--log-level", default="warning",
                        choices=("debug", "info", "warning", "error"),
                        help="logging level on stderr (default: warning)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("check", help="validate a mission file and print what it would fly; "
                       "with --connect, also the vehicle's safety parameters and fence")
    p.add_argument("mission", metavar="MISSION.yaml")
    p.add_argument("--connect", default=None, metavar="URL",
                   help="also read the vehicle's PX4 safety parameters and geofence over MAVLink "
                        "(MAVSDK URL, e.g. udpin://0.0.0.0:14540) and refuse an unsafe set "
                        "(exit 2)")
    _add_accept_option(p)
    p.add_argument("--connect-timeout", type=_positive_float, default=30.0, metavar="S",
                   help="seconds to wait for the vehicle (default 30)")

    p = sub.add_parser("export-plan", help="write the mission's area (or its geofence) as a "
                       "QGroundControl .plan, KML or GeoJSON file")
    p.add_argument("mission", metavar="MISSION.yaml")
    p.add_argument("-o", "--out", action="append", required=True, metavar="FILE",
                   help="output file; its suffix picks the format: .plan (QGroundControl: "
                        "geofence inclusion polygon and planned home), .kml, .geojson; "
                        "repeat for several")
    p.add_argument("--fence", action="store_true",
                   help="write the geofence the GCS uploads (the area and home pushed out by "
                        "safety.geofence_margin_m) instead of the area")

    p = sub.add_parser("sitl", help="start the simulator and the GCS together and fly the mission")
    p.add_argument("mission", metavar="MISSION.yaml")
    _add_flight_options(p)
    p.add_argument("--speedup", type=_positive_float, default=1.0, metavar="K",
                   help="simulated time runs K times faster than wall time (default: 1)")
    p.add_argument("--mavlink-port", type=_nonnegative_int, default=14540, metavar="PORT",
                   help="UDP port for MAVLink on loopback (default 14540; 0 = any free port)")
    p.add_argument("--radio-port", type=_nonnegative_int, default=14600, metavar="PORT",
                   help="UDP port for radio datagrams on loopback (default 14600; 0 = any free)")
    p.add_argument("--receiver", choices=("sim", "iq"), default="sim",
                   help="sim: the simulator sends detections; iq: it serves IQ samples over "
                        "rtl_tcp and the IQ receiver (docs/receiver.md) runs in the GCS "
                        "(default sim)")

    p = sub.add_parser("fly", help="fly a real vehicle (or any simulator) through MAVSDK")
    p.add_argument("mission", metavar="MISSION.yaml")
    _add_flight_options(p)
    p.add_argument("--connect", default=DEFAULT_CONNECT, metavar="URL",
                   help=f"MAVSDK connection URL (default: {DEFAULT_CONNECT})")
    p.add_argument("--radio", default=None, metavar="udp://HOST:PORT",
                   help="where detections arrive (default: the mission's receiver.listen)")
    p.add_argument("--iq-source", default=None, metavar="URL",
                   help="also run the IQ receiver in this process on this source "
                        "(rtltcp://HOST:PORT, rtlsdr://0, soapy://ARGS, file:...; see "
                        "`receive`), sending to the radio port")
    p.add_argument("--iq-gain", type=float, default=29.7, metavar="DB",
                   help="with --iq-source: fixed tuner gain (default 29.7)")
    p.add_argument("--iq-cal-offset", type=float, default=0.0, metavar="DB",
                   help="with --iq-source: calibration offset, dBm = dBFS - gain + offset")
    p.add_argument("--iq-ppm", type=float, default=0.0, metavar="PPM",
                   help="with --iq-source: crystal correction")

    p = sub.add_parser("analyze", help="post-flight report and plots from flight logs "
                       "(several logs: a comparison)")
    p.add_argument("log", nargs="+", metavar="LOG",
                   help="flight log directory or its flight.jsonl; several for a comparison")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="where to write the report (default: LOG/report; several logs: "
                        "comparison/ beside the first)")
    p.add_argument("--truth", default=None, metavar="truth.jsonl",
                   help="simulator ground truth for errors (default: truth.jsonl beside LOG)")
    p.add_argument("--calibrate", default=None, metavar="TAG",
                   help="fit P0, n and noise to TAG's detections (or 'all' pooled) and print "
                        "a mission-file radio: block")
    p.add_argument("--tag-position", default=None, metavar="LAT,LON",
                   help="surveyed position of the --calibrate tag (default: the ground truth "
                        "if known, else the estimate)")
    p.add_argument("--export", action="store_true",
                   help="also write flight.geojson, tags.csv and path.csv for GIS tools")

    p = sub.add_parser("replay", help="re-run the filters on a flight log and compare planner "
                       "choices, in the terminal UI or as a table")
    p.add_argument("log", metavar="LOG", help="flight log directory or its flight.jsonl")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="the method to compare with the recorded one (default: pim for a "
                        "mexgen flight, else mexgen)")
    p.add_argument("--headless", action="store_true",
                   help="print the comparison as a table instead of the terminal UI")
    p.add_argument("--seed", type=_nonnegative_int, default=None, metavar="N",
                   help="seed of the replay's random draws (default: the flight's seed)")
    p.add_argument("--speedup", type=_positive_float, default=1.0, metavar="K",
                   help="replay K times faster than the flight (default: 1)")

    p = sub.add_parser("experiment", help="batch Monte Carlo runs reproducing the paper")
    p.add_argument("scenario", choices=("follow", "localise"))
    p.add_argument("--model", choices=EXPERIMENT_MODELS, default="rw",
                   help="the objects' motion: static tags, or the paper's four models")
    p.add_argument("--methods", default="pim,mc8,mexgen", metavar="M1,M2",
                   help="comma-separated: pim, mc8 (MC-M with M=8), mexgen (MexGen-512), "
                   "oracle<R> / oraclestar<R> (know the truth; orbit each tag at R m / fly passes "
                   "over it out to R m: the floor)")
    p.add_argument("--starts", type=_positive_int, default=50, metavar="N",
                   help="unique initial states")
    p.add_argument("--reps", type=_positive_int, default=30, metavar="N",
                   help="Monte Carlo repetitions per initial state")
    p.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                   help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="submit the runs to this Dask distributed scheduler instead")
    p.add_argument("--seed", type=_nonnegative_int, default=0, metavar="S")
    p.add_argument("--preset", choices=("paper", "field"), default="paper",
                   help="paper: the paper's sensor (omnidirectional, every pulse heard) and "
                   "planner; field: the mission defaults (3 dB antenna, -60 dB sensitivity)")
    p.add_argument("--reality", choices=REALITIES, default="matched",
                   help="how the radio world differs from the mission's model "
                   "(docs/results/localisation.md); default: matched")
    p.add_argument("--estimator", choices=ESTIMATORS, default="classic",
                   help="classic: trusts the radio model (the paper's); robust: estimates each "
                   "tag's power offset and path-loss exponent and the antenna's front-to-back "
                   "ratio, shadowing, outliers")
    p.add_argument("--finish", action="store_true",
                   help="the mission's stall and budget rules: every tag reported in bounded "
                   "time (reached, stalled, budget), the run ends when all are "
                   "(docs/mission-finish.md)")
    p.add_argument("--min-alt", type=_positive_float, default=None, metavar="M",
                   help="altitude actions: every heading also scored at M m (the mission's "
                   "flight.min_alt_m; the search flies at 50 m); default: hold 50 m")
    p.add_argument("--quick", action="store_true",
                   help="short horizons for a smoke run (minutes, not hours)")
    p.add_argument("--out", required=True, metavar="DIR")

    p = sub.add_parser("receive", help="listen for the mission's tags with a radio (RTL-SDR, "
                       "rtl_tcp, SoapySDR) or a recording and send detections to the GCS")
    p.add_argument("mission", metavar="MISSION.yaml")
    p.add_argument("--source", required=True, metavar="URL",
                   help="rtltcp://HOST:PORT, rtlsdr://INDEX, soapy://ARGS, "
                        "file:NAME.sigmf-meta or file:NAME.cu8?rate=HZ&centre=HZ")
    p.add_argument("--to", default=None, metavar="udp://HOST:PORT",
                   help="where to send detections (default: 127.0.0.1 at the port of the "
                        "mission's receiver.listen)")
    p.add_argument("--record", default=None, metavar="NAME.sigmf-data",
                   help="record the samples and the pulses (SigMF)")
    p.add_argument("--gain", type=float, default=29.7, metavar="DB",
                   help="fixed tuner gain, dB (the nearest the device has; AGC is off; "
                        "default 29.7)")
    p.add_argument("--cal-offset", type=float, default=0.0, metavar="DB",
                   help="calibration offset: dBm = dBFS - gain + offset (docs/receiver.md)")
    p.add_argument("--ppm", type=float, default=0.0, help="crystal correction, ppm")
    p.add_argument("--pfa", type=_probability, default=1e-3, metavar="P",
                   help="false alarms per tag and second (default 1e-3)")
    p.add_argument("--channel-width", type=_positive_float, default=3000.0, metavar="HZ",
                   help="each tag's channel, Hz: its frequency uncertainty (default 3000)")
    p.add_argument("--rate", type=_positive_float, default=None, metavar="HZ",
                   help="sample rate (default: the smallest that covers the tags)")
    p.add_argument("--duration", type=_positive_float, default=None, metavar="S",
                   help="stop after S seconds of samples")
    p.add_argument("--realtime", action="store_true",
                   help="replay a file at its own pace, timed from now (to feed a live GCS)")

    p = sub.add_parser("bench", help="benchmarks: filter or planner (median/min/max), "
                                     "experiment (runs per hour, the full Table II projected), "
                                     "or receiver (real-time factor at 2.4 Msps, 4 tags)")
    p.add_argument("what", choices=("filter", "planner", "experiment", "receiver"))
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--iterations", type=_positive_int, default=None, metavar="N",
                   help="filter, planner: timed calls")
    p.add_argument("--starts", type=_positive_int, default=None, metavar="N",
                   help="experiment: runs per model and method (default 2)")
    return parser


def _add_accept_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--accept-unsafe-params", type=_param_names, default=frozenset(),
                   metavar="NAME[,NAME]",
                   help="PX4 parameters whose unsafe value is accepted knowingly (a warning "
                        "instead of a refusal); adds to the mission's safety.accept_px4_params")


def _param_names(text: str) -> frozenset[str]:
    from mexgen_gcs.config.schema import PX4_SAFETY_PARAMS

    names = frozenset(n.strip() for n in text.split(",") if n.strip())
    bad = sorted(names - set(PX4_SAFETY_PARAMS))
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected names from {', '.join(PX4_SAFETY_PARAMS)}; "
                                         f"found {text!r}")
    return names


def _add_flight_options(p: argparse.ArgumentParser) -> None:
    _add_accept_option(p)
    p.add_argument("--headless", action="store_true",
                   help="no terminal UI; progress goes to stderr")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="override planner.method of the mission")
    p.add_argument("--seed", type=_nonnegative_int, default=None, metavar="N",
                   help="seed of the GCS's random draws (and of the simulated world for sitl)")
    p.add_argument("--log-dir", default="flights", metavar="D",
                   help="flight logs go to a new directory under D (default: flights)")
    p.add_argument("--time-scale", type=_positive_float, default=None, metavar="K",
                   help="the vehicle's clock runs K times the wall clock (default: measured "
                        "from the vehicle's SYSTEM_TIME; PX4 SITL at speed factor K runs "
                        "about 0.96 K)")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, found {text!r}") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, found {text!r}")
    return value


def _probability(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, found {text!r}") from None
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"expected 0 < P < 1, found {text!r}")
    return value


def _positive_int(text: str) -> int:
    value = _nonnegative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError("expected a whole number >= 1, found 0")
    return value


def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, found {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, found {text!r}")
    return value


def _methods(text: str) -> tuple[str, ...]:
    names = tuple(m.strip() for m in text.split(",") if m.strip())
    bad = [m for m in names if m not in METHODS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"expected methods from {', '.join(METHODS)}, found {text!r}")
    return names


def cmd_check(args: argparse.Namespace) -> int:
    """Validate a mission; print what it would fly and any warnings."""
    from mexgen_gcs.config import describe, load_mission, mission_warnings

    mission = load_mission(args.mission)
    print(describe(mission))
    warnings = mission_warnings(mission)
    if warnings:
        print(f"Warnings ({len(warnings)}):")
        for text in warnings:
            print(f"  - {text}")
    else:
        print("No warnings.")
    print(f"{args.mission}: OK")
    if args.connect is None:
        return EXIT_OK
    # the vehicle's side lives with the MAVSDK adapter, looked up by name like the handlers
    module = importlib.import_module("mexgen_gcs.io.px4_check")
    code = int(module.check_vehicle(mission, args.connect, args.accept_unsafe_params,
                                    args.connect_timeout))
    if code == EXIT_BAD_INPUT:
        print(f"{args.mission}: refused: the vehicle's parameters are unsafe for this mission "
              "(see above)", file=sys.stderr)
    return code


def cmd_export_plan(args: argparse.Namespace) -> int:
    """Write the mission's area (or fence) in the formats the output suffixes name."""
    from mexgen_gcs.config import load_mission
    from mexgen_gcs.config.area_files import AreaFileError, write_area_file

    mission = load_mission(args.mission)
    polygon = mission.area_polygon_deg(fence=args.fence)
    home = (mission.home.lat_deg, mission.home.lon_deg, mission.home.alt_m or 0.0)
    what = "geofence" if args.fence else "area"
    for out in args.out:
        try:
            kind = write_area_file(out, polygon, home, f"{mission.name} {what}")
        except AreaFileError as exc:
            raise ConfigError(str(exc)) from None
        except OSError as exc:
            raise ConfigError(f"{out}: cannot write: {exc.strerror}") from None
        print(f"{out}: {what} of {mission.name!r} ({len(polygon)} vertices) as {kind}")
    return EXIT_OK


def resolve_handler(command: str) -> tuple[Callable[[argparse.Namespace], int] | None, str]:
    """(handler, "") for a subcommand, or (None, why) if this build does not have it.

    A missing handler module or a missing third-party library means "not in this build"; a
    missing mexgen_gcs module imported by an existing handler module is a bug and is raised.
    """
    if command == "check":
        return cmd_check, ""
    if command == "export-plan":
        return cmd_export_plan, ""
    module_name, _, func_name = HANDLERS[command].partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        missing = exc.name or ""
        ours = missing == "mexgen_gcs" or missing.startswith("mexgen_gcs.")
        if ours and not (module_name == missing or module_name.startswith(missing + ".")):
            raise
        return None, f"no module {missing}"
    handler = getattr(module, func_name, None)
    if not callable(handler):
        return None, f"{module_name} has no {func_name}"
    return handler, ""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error (argparse exits 2)
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    handler, why = resolve_handler(args.command)
    if handler is None:
        print(f"mexgen-gcs {args.command}: not available in this build ({why})",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        return int(handler(args))
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_BAD_INPUT
    except MexgenError as exc:
        print(f"mexgen-gcs {args.command}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print(f"mexgen-gcs {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
