"""The command-line handlers of `mexgen-gcs sitl` and `mexgen-gcs fly`: load the mission, fly
it (`mission.run`) with the terminal UI attached when stdout is a terminal and ``--headless``
is not given, print the summary. They live in the UI layer because they choose the UI; the
mission layer never imports it. No frames here.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import sys
import time

from mexgen_gcs.config import Mission, load_mission
from mexgen_gcs.errors import ConfigError, MexgenError
from mexgen_gcs.io.clock import VehicleClock
from mexgen_gcs.mission.controller import MissionResult
from mexgen_gcs.mission.iq_receiver import IqReceiverSpec
from mexgen_gcs.mission.run import (
    DEFAULT_MAVLINK_PORT,
    DEFAULT_RADIO_PORT,
    MissionRunner,
    SitlPorts,
    apply_overrides,
    fly_mission,
    free_udp_port,
    make_log_dir,
    run_sitl,
    summary_text,
)
from mexgen_gcs.receiver.run import ReceiveOptions
from mexgen_gcs.receiver.sources import SourceError
from mexgen_gcs.receiver.urls import check_url


def _ui_runner(args: argparse.Namespace) -> MissionRunner | None:
    """The terminal UI's runner when it should and can be shown, else None (headless; a
    note on stderr if the UI cannot be loaded)."""
    if getattr(args, "headless", False) or not sys.stdout.isatty():
        return None
    try:
        from mexgen_gcs.ui.app import run_with_ui
    except ImportError as exc:
        print(f"terminal UI unavailable ({exc}); flying headless", file=sys.stderr)
        return None
    return run_with_ui


def _setup_logging() -> None:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")


def _accept_params(mission: Mission, args: argparse.Namespace) -> Mission:
    """--accept-unsafe-params added to safety.accept_px4_params (so the log says so too)."""
    extra = getattr(args, "accept_unsafe_params", None)
    if not extra:
        return mission
    names = sorted(set(mission.safety.accept_px4_params) | set(extra))
    return apply_overrides(mission, {"safety.accept_px4_params": names})


def cmd_sitl(args: argparse.Namespace) -> int:
    _setup_logging()
    try:
        mission = load_mission(args.mission)
        overrides = {"sim.seed": args.seed} if getattr(args, "seed", None) is not None else None
        mission = _accept_params(apply_overrides(mission, overrides), args)
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    runner = _ui_runner(args)
    ports = SitlPorts(getattr(args, "mavlink_port", DEFAULT_MAVLINK_PORT) or free_udp_port(),
                      getattr(args, "radio_port", DEFAULT_RADIO_PORT) or free_udp_port())
    try:
        result = run_sitl(mission, seed=args.seed if args.seed is not None else 1, ports=ports,
                          speedup=float(getattr(args, "speedup", 1.0) or 1.0),
                          method=getattr(args, "method", None),
                          log_dir=getattr(args, "log_dir", None) or "flights", runner=runner,
                          time_scale=getattr(args, "time_scale", None),
                          receiver=getattr(args, "receiver", None) or "sim")
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    except MexgenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print_summary(result)
    return result.exit_code


def print_summary(result: MissionResult) -> None:
    """The summary on stdout; a dead terminal (SSH gone) loses it, nothing else (the log has
    it all), and stdout is pointed at /dev/null so the interpreter's last flush cannot fail."""
    try:
        print(summary_text(result), flush=True)
    except (OSError, ValueError):
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        except (OSError, ValueError):
            pass


def cmd_fly(args: argparse.Namespace) -> int:
    _setup_logging()
    try:
        mission = load_mission(args.mission)
        if getattr(args, "method", None):
            mission = apply_overrides(mission, {"planner.method": args.method})
        mission = _accept_params(mission, args)
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    seed = args.seed if getattr(args, "seed", None) is not None else int(time.time())
    out = make_log_dir(getattr(args, "log_dir", None) or "flights", mission,
                        mission.planner.method, seed)
    runner = _ui_runner(args)
    radio = getattr(args, "radio", None) or mission.receiver.listen
    clock = VehicleClock(fixed_rate=getattr(args, "time_scale", None))
    iq = None
    if getattr(args, "iq_source", None):
        try:
            check_url(args.iq_source)
        except SourceError as exc:
            print(f"--iq-source: {exc}", file=sys.stderr)
            return 2
        host = radio.removeprefix("udp://").rpartition(":")
        send_to = f"udp://127.0.0.1:{host[2]}" if host[0] in ("0.0.0.0", "") else radio
        iq = IqReceiverSpec(args.iq_source, ReceiveOptions(
            gain_db=args.iq_gain, cal_offset_db=args.iq_cal_offset, ppm=args.iq_ppm))
        radio_send = send_to
    else:
        radio_send = radio
    try:
        result = asyncio.run(fly_mission(
            mission, connect_url=args.connect, radio_url=radio, clock=clock, log_dir=out,
            method=mission.planner.method, seed=seed, runner=runner, iq=iq,
            iq_send_url=radio_send))
    except MexgenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print_summary(result)
    return result.exit_code
