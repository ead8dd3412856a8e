"""``python -m sim MISSION.yaml [options]``: run the simulator until stopped or landed.

``--radios-only --vehicle URL``: no simulated vehicle; the radios ride on a real autopilot's
(or another simulator's) MAVLink telemetry (``sim.rider``). ``--no-radios``: the vehicle only.

Exit codes: 0 after a clean stop (SIGINT/SIGTERM, or landed and disarmed after flying),
2 for bad input (mission file or flags), with a message on stderr naming the problem.
Prints one line ``sim ready mavlink=... radio=... listen=...`` on stdout once it is up.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Sequence
from pathlib import Path

from mexgen_gcs.config import Mission, load_mission
from mexgen_gcs.config.area_files import AreaFileError, read_area_file
from mexgen_gcs.errors import ConfigError
from sim.clock import SYSTEM_TIME_SOURCES
from sim.faults import KINDS, parse_fault_flag
from sim.iq import IqOptions
from sim.params import parse_param_flag
from sim.rider import RadioRider, RiderOptions
from sim.runner import Simulation
from sim.scenario import Address, SimOptions, faults_of
from sim.tunnel_radio import RADIO_FORMATS
from sim.vehicle_link import VehicleEndpoint, parse_vehicle_url


def parse_address(text: str) -> Address:
    """``HOST:PORT`` or ``udp://HOST:PORT`` (IPv4 or a host name)."""
    rest = text.removeprefix("udp://")
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, e.g. 127.0.0.1:14540; got {text!r}")
    return host, int(port)


def _fault(text: str) -> object:
    try:
        return parse_fault_flag(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 < value <= 200.0:
        raise argparse.ArgumentTypeError(f"expected 0 < value <= 200, got {value}")
    return value


def _rate_error(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not -0.5 <= value <= 0.5:
        raise argparse.ArgumentTypeError(f"expected -0.5 <= E <= 0.5, got {value}")
    return value


def _vehicle(text: str) -> VehicleEndpoint:
    try:
        return parse_vehicle_url(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _param(text: str) -> tuple[str, float]:
    try:
        return parse_param_flag(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _cw(text: str) -> tuple[float, float]:
    try:
        offset, dbm = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected OFFSET_HZ,DBM, e.g. 1000,-70; got {text!r}") \
            from None
    return offset, dbm


def _sysid(text: str) -> int:
    if not text.isdigit() or not 1 <= int(text) <= 255:
        raise argparse.ArgumentTypeError(f"expected a system id 1..255, got {text!r}")
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sim",
        description="Simulated PX4 multirotor (MAVLink/UDP) and VHF radio receiver "
                    "(detection wire format v1/UDP) for a mission file.")
    p.add_argument("mission", type=Path, help="mission file (YAML)")
    p.add_argument("--seed", type=int, default=None, help="world seed (default: sim.seed)")
    p.add_argument("--speedup", type=_positive, default=1.0,
                   help="sim time runs K times faster than the wall clock, 0 < K <= 200 "
                        "(default 1; up to 50 is reliable with MAVSDK, see sim/README.md)")
    p.add_argument("--clock-rate-error", type=_rate_error, default=0.0, metavar="E",
                   help="sim time runs at K*(1+E) instead of K, -0.5 <= E <= 0.5 (default 0; "
                        "PX4 SIH at speed factor 4 runs about -0.02)")
    p.add_argument("--system-time", choices=SYSTEM_TIME_SOURCES, default="sim",
                   help="SYSTEM_TIME.time_unix_usec: sim = sim time as unix (a real "
                        "aircraft's GPS clock), host = the host's wall clock while time_boot_ms "
                        "is sim time (PX4 SITL); default sim")
    p.add_argument("--mavlink", type=parse_address, default=("127.0.0.1", 14540),
                   metavar="HOST:PORT", help="send MAVLink here (default 127.0.0.1:14540)")
    p.add_argument("--gcs", type=parse_address, default=None, metavar="HOST:PORT",
                   help="also send MAVLink here, e.g. a GCS on 127.0.0.1:14550")
    p.add_argument("--radio", type=parse_address, default=("127.0.0.1", 14600),
                   metavar="HOST:PORT", help="send detection datagrams here "
                   "(default 127.0.0.1:14600)")
    p.add_argument("--listen", type=parse_address, default=("0.0.0.0", 0), metavar="HOST:PORT",
                   help="bind the MAVLink socket here (default 0.0.0.0:0, any free port)")
    p.add_argument("--truth-dir", type=Path, default=None,
                   help="write truth.jsonl into this directory (default: no truth file)")
    p.add_argument("--sysid", type=_sysid, default=1, help="MAVLink system id (default 1)")
    p.add_argument("--fault", type=_fault, action="append", default=[], metavar="SPEC",
                   help="add a fault, KIND,at_s=S[,field=value]; kinds: "
                        + ", ".join(f"{k}({', '.join(v)})" for k, v in KINDS.items()))
    p.add_argument("--param", type=_param, action="append", default=[], metavar="NAME=VALUE",
                   help="set a PX4 parameter before the start, e.g. NAV_DLL_ACT=0 (repeatable; "
                        "the defaults are PX4 SITL's)")
    p.add_argument("--fence", type=Path, default=None, metavar="FILE",
                   help="start with this inclusion fence on board, as if the pilot's station had "
                        "uploaded it (a .plan, .kml or .geojson polygon, as area.from reads)")
    p.add_argument("--keep-running", action="store_true",
                   help="do not exit after landing and disarming")
    p.add_argument("--radio-format", choices=RADIO_FORMATS, default="wire-v1",
                   help="what the receiver sends: wire-v1 JSON datagrams (default) or "
                   "mavlink-tunnel (TagTracker's MAVLink TUNNEL PulseInfo_t)")
    p.add_argument("--no-radios", action="store_true",
                   help="simulate the vehicle only, no tags and no datagrams (e.g. when "
                        "radios ride on it from another process with --radios-only)")
    g = p.add_argument_group("the radio as IQ samples (an rtl_tcp server)")
    g.add_argument("--iq-server", type=parse_address, default=None, metavar="HOST:PORT",
                   help="serve the radio as 8-bit IQ over the rtl_tcp protocol here (port 0: "
                        "any free port, printed as iq=HOST:PORT in the ready line) instead of "
                        "sending detection datagrams; a receiver (mexgen-gcs receive --source "
                        "rtltcp://HOST:PORT --cal-offset 24.6) detects the pulses")
    g.add_argument("--iq-cw", type=_cw, default=None, metavar="OFFSET_HZ,DBM",
                   help="add a CW interferer OFFSET_HZ from the first tag at DBM")
    g = p.add_argument_group("radios riding on any MAVLink vehicle")
    g.add_argument("--radios-only", action="store_true",
                   help="no simulated vehicle: run tags, pulses and detections on the clock and "
                        "pose of the vehicle at --vehicle (vehicle flags and faults are ignored)")
    g.add_argument("--vehicle", type=_vehicle, default=None, metavar="URL",
                   help="the vehicle's telemetry: udpin:HOST:PORT (listen, e.g. PX4's GCS link "
                        "udpin:0.0.0.0:14550) or udpout:HOST:PORT (talk first, e.g. PX4 "
                        "instance i's GCS link udpout:127.0.0.1:18570+i)")
    g.add_argument("--vehicle-sysid", type=_sysid, default=None,
                   help="the vehicle's MAVLink system id (default: the first autopilot heard)")
    return p


def _radios_only(mission: Mission, args: argparse.Namespace) -> int:
    options = RiderOptions(
        vehicle=args.vehicle, radio=args.radio, vehicle_sysid=args.vehicle_sysid,
        seed=args.seed, truth_dir=args.truth_dir, keep_running=args.keep_running)
    try:
        rider = RadioRider(mission, options, faults_of(mission, SimOptions(
            extra_faults=tuple(args.fault))))
        return asyncio.run(rider.run())
    except (OSError, ValueError) as exc:
        print(f"sim: cannot start: {exc}", file=sys.stderr)
        return 2


def _iq_options(args: argparse.Namespace) -> IqOptions | None:
    if args.iq_server is None:
        return None
    cw = args.iq_cw
    return IqOptions(host=args.iq_server[0], port=args.iq_server[1],
                     cw_offset_hz=cw[0] if cw else None, cw_dbm=cw[1] if cw else -70.0)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.radios_only != (args.vehicle is not None):
        parser.error("--radios-only and --vehicle URL go together")
    if args.radios_only and args.no_radios:
        parser.error("--radios-only and --no-radios exclude each other")
    if args.radios_only and args.radio_format != "wire-v1":
        parser.error("--radio-format mavlink-tunnel is not available with --radios-only")
    try:
        mission = load_mission(args.mission)
    except ConfigError as exc:
        print(f"sim: {exc}", file=sys.stderr)
        return 2
    if args.radios_only:
        return _radios_only(mission, args)
    fence: tuple[tuple[float, float], ...] = ()
    if args.fence is not None:
        try:
            fence = tuple(read_area_file(args.fence, mission.home.lat_deg, mission.home.lon_deg))
        except AreaFileError as exc:
            print(f"sim: --fence: {exc}", file=sys.stderr)
            return 2
    options = SimOptions(
        speedup=args.speedup, clock_rate_error=args.clock_rate_error,
        system_time=args.system_time, seed=args.seed, mavlink=args.mavlink, gcs=args.gcs,
        radio=args.radio, listen=args.listen, truth_dir=args.truth_dir, sysid=args.sysid,
        extra_faults=tuple(args.fault), keep_running=args.keep_running,
        radios=not args.no_radios, params=tuple(args.param), fence_latlon_deg=fence,
        radio_format=args.radio_format, iq=_iq_options(args))
    try:
        sim = Simulation(mission, options)
    except (OSError, ValueError) as exc:
        print(f"sim: cannot start: {exc}", file=sys.stderr)
        return 2
    try:
        return asyncio.run(sim.run())
    except OSError as exc:  # e.g. the listen address is taken
        print(f"sim: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
