"""`mexgen-gcs receive MISSION.yaml --source URL`: listen for the mission's tags and send
detection datagrams to the GCS (docs/receiver.md). Exit codes: 0 the source ended or the
duration passed, 1 the source failed while running, 2 bad input (mission, source URL, a tag
out of the source's band).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mexgen_gcs.config import load_mission
from mexgen_gcs.errors import ConfigError
from mexgen_gcs.receiver.output import UdpSender
from mexgen_gcs.receiver.run import ReceiveOptions, RunSummary, run_receiver
from mexgen_gcs.receiver.sources import SourceError
from mexgen_gcs.receiver.tuning import TuningError, TuningPlan
from mexgen_gcs.receiver.urls import open_source


def options_of(args: argparse.Namespace) -> ReceiveOptions:
    return ReceiveOptions(
        gain_db=args.gain, cal_offset_db=args.cal_offset, ppm=args.ppm, pfa_per_s=args.pfa,
        channel_width_hz=args.channel_width, rate_hz=args.rate, duration_s=args.duration,
        realtime=args.realtime, record=Path(args.record) if args.record else None)


def cmd_receive(args: argparse.Namespace) -> int:
    try:
        mission = load_mission(args.mission)
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    to = args.to or f"udp://127.0.0.1:{_port(mission.receiver.listen)}"
    try:
        sender = UdpSender(to)
    except ValueError as exc:
        print(f"--to {to!r}: {exc}", file=sys.stderr)
        return 2
    try:
        source = open_source(args.source)
    except SourceError as exc:
        print(f"receive: {exc}", file=sys.stderr)
        return 2

    def ready(plan: TuningPlan) -> None:
        print(f"receive: {source.name}: {plan.describe()}; sending to {to}", file=sys.stderr)

    try:
        summary = run_receiver(mission, source, options_of(args), send=sender.send,
                               on_ready=ready)
    except TuningError as exc:
        source.close()
        print(f"receive: {exc}", file=sys.stderr)
        return 2
    except SourceError as exc:
        print(f"receive: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("receive: interrupted", file=sys.stderr)
        return 0
    finally:
        sender.close()
    print(summary_text(summary))
    return 0


def summary_text(s: RunSummary) -> str:
    rate = s.plan.rate_hz
    lines = [f"receive: {s.samples / rate:.1f} s of samples, {len(s.pulses)} pulses, "
             f"{s.dropped_samples} samples dropped, {s.clipped_frames} clipped frames, "
             f"{s.cw_rejected} CW and {s.width_rejected} width rejections"]
    for ch in s.plan.channels:
        mine = [p for p in s.pulses if p.tag == ch.id]
        if mine:
            best = max(p.rssi_dbm for p in mine)
            lines.append(f"  {ch.id}: {len(mine)} pulses, strongest {best:.1f} dBm")
        else:
            lines.append(f"  {ch.id}: nothing heard")
    if s.damage:
        lines.append(f"  warning: {s.damage}")
    return "\n".join(lines)


def _port(listen: str) -> int:
    from mexgen_gcs.config.urls import parse_udp_url

    return parse_udp_url(listen).port
