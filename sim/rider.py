"""``python -m sim MISSION --radios-only --vehicle URL``: simulated radios riding on any vehicle.

No simulated vehicle: the tags, their pulses and the receiver run on the VEHICLE's clock and
pose, taken from its MAVLink telemetry (PX4's GCS link on 14550, or the project's simulator's
``--gcs`` port). Frames: tag truth in the mission's local ENU frame about the mission home;
the receiver is at the vehicle's lat/lon mapped into that frame, at a height equal to the
vehicle's ``relative_alt`` (above ITS home); datagrams carry the vehicle's lat/lon, AMSL
``alt`` and heading, and ``t`` = the vehicle's unix time of the pulse (``sim.vehicle_link``).

Radio time ``sim_s`` = vehicle seconds since the radios started (the first pose after the clock
was anchored); pulses are processed only up to the newest pose, so every pulse is posed by
interpolation between two telemetry samples, never extrapolated. The radios send the vehicle
only SET_MESSAGE_INTERVAL(SYSTEM_TIME, 0.2 s) until SYSTEM_TIME arrives and one
REQUEST_MESSAGE(HOME_POSITION), no HEARTBEAT, so no link-loss check of the autopilot counts
them. Exit 0 after the vehicle has flown, landed and disarmed, or on SIGINT/SIGTERM.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import socket
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mexgen_gcs.config import Mission
from sim.faults import Fault, FaultSchedule
from sim.radios import RadioSim, ReceiverPose, describe_world, reality_world
from sim.scenario import Address, build_tags
from sim.truth import TruthWriter
from sim.vehicle_link import PoseSample, VehicleEndpoint, VehicleTrack

RADIO_FAULTS = {"radio_silence", "detection_dropout", "clutter", "clock_offset",
                "clock_drift"}
RIDER_SYSID = 251
RIDER_COMPID = mavlink.MAV_COMP_ID_PERIPHERAL
TICK_S = 0.01
REQUEST_EVERY_S = 1.0
#: SYSTEM_TIME asked at 5 Hz (of vehicle time on PX4): the clock fit needs a few samples.
SYSTEM_TIME_INTERVAL_US = 200_000
#: Wall seconds to wait for enough SYSTEM_TIME before anchoring the vehicle clock otherwise.
SYSTEM_TIME_WAIT_S = 8.0
EXIT_LINGER_S = 1.5


@dataclass(frozen=True)
class RiderOptions:
    vehicle: VehicleEndpoint
    radio: Address
    vehicle_sysid: int | None = None
    seed: int | None = None
    truth_dir: Path | None = None
    extra_faults: tuple[Fault, ...] = ()
    keep_running: bool = False


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, rider: RadioRider) -> None:
        self.rider = rider

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.rider.receive(data, (addr[0], addr[1]))

    def error_received(self, exc: Exception) -> None:
        pass


class _Writer:
    def __init__(self, rider: RadioRider) -> None:
        self.rider = rider

    def write(self, buf: bytes) -> None:
        self.rider.send_to_vehicle(bytes(buf))


class RadioRider:
    """All state of one radios-only run; ``run()`` drives it."""

    def __init__(self, mission: Mission, options: RiderOptions, faults: list[Fault]) -> None:
        self.mission = mission
        self.options = options
        self.frame = mission.local_frame()
        self.seed = mission.sim.seed if options.seed is None else options.seed
        # The same streams as the full simulator: the same tags and pulse phases for a seed.
        seeds = np.random.SeedSequence(self.seed).spawn(3)
        world_rng, radio_rng = (np.random.default_rng(s) for s in seeds[:2])
        self.truth = TruthWriter(options.truth_dir)
        self.ignored_faults = [f for f in faults if f.kind not in RADIO_FAULTS]
        self.faults = FaultSchedule([f for f in faults if f.kind in RADIO_FAULTS])
        self.track = VehicleTrack(options.vehicle_sysid)
        self.radio = RadioSim(build_tags(mission, world_rng), mission.radio_model(),
                              mission.receiver.pulse_period_s, self.faults, self.truth,
                              self._unix_of, radio_rng,
                              world=reality_world(mission, self.seed))
        self._boot0: float | None = None
        self._bound: tuple[str, int] = ("", 0)
        self._sim_s = 0.0
        self._next_vehicle_truth_s = 0.0
        self._transport: asyncio.DatagramTransport | None = None
        self._vehicle_addr: Address | None = (
            (options.vehicle.host, options.vehicle.port) if options.vehicle.mode == "udpout"
            else None)
        self._mav = mavlink.MAVLink(_Writer(self), srcSystem=RIDER_SYSID, srcComponent=RIDER_COMPID)
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._radio_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._radio_sock.setblocking(False)
        self._stop = asyncio.Event()
        self._wall0 = time.monotonic()
        self._first_pose_wall: float | None = None
        self._last_request_wall = -math.inf
        self._home_requested = False
        self._done_wall: float | None = None
        self.stats = {"rx_datagrams": 0, "rx_messages": 0, "rx_bad": 0, "tx_messages": 0,
                      "pose_gaps": 0, "radio_send_errors": 0}

    # -- clocks -------------------------------------------------------------------------

    def _wall_s(self) -> float:
        return time.monotonic() - self._wall0

    def _unix_of(self, sim_s: float) -> float:
        assert self._boot0 is not None
        return self.track.unix_of(self._boot0 + sim_s)

    # -- I/O -------------------------------------------------------------------------------

    def send_to_vehicle(self, data: bytes) -> None:
        if self._transport is not None and self._vehicle_addr is not None:
            self._transport.sendto(data, self._vehicle_addr)
            self.stats["tx_messages"] += 1

    def receive(self, data: bytes, addr: Address) -> None:
        self.stats["rx_datagrams"] += 1
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:  # hostile or foreign bytes
            self.stats["rx_bad"] += 1
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self.stats["rx_bad"] += 1
                continue
            self.stats["rx_messages"] += 1
            self.track.handle(msg)
            if msg.get_srcSystem() == self.track.sysid and self.options.vehicle.mode == "udpin":
                self._vehicle_addr = addr  # reply where the vehicle sends from
        if self._first_pose_wall is None and self.track.last_boot_s is not None:
            self._first_pose_wall = self._wall_s()

    def _radio_send(self, data: bytes) -> None:
        try:
            self._radio_sock.sendto(data, self.options.radio)
        except OSError:
            self.stats["radio_send_errors"] += 1

    def _requests(self) -> None:
        """Ask for SYSTEM_TIME (PX4's GCS link does not stream it) and the home position."""
        wall = self._wall_s()
        if wall - self._last_request_wall < REQUEST_EVERY_S:
            return
        self._last_request_wall = wall
        target = self.track.sysid or 0
        if self.track.system_time_samples == 0:
            self._mav.command_long_send(target, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                        mavlink.MAVLINK_MSG_ID_SYSTEM_TIME,
                                        SYSTEM_TIME_INTERVAL_US, 0, 0, 0, 0, 0)
        if self.track.home is None and self.track.sysid is not None and not self._home_requested:
            self._home_requested = True
            self._mav.command_long_send(target, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                        mavlink.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)

    # -- main loop -------------------------------------------------------------------------

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        ep = self.options.vehicle
        local = (ep.host, ep.port) if ep.mode == "udpin" else ("0.0.0.0", 0)
        transport, _ = await loop.create_datagram_endpoint(
            lambda: _Protocol(self), local_addr=local, family=socket.AF_INET)
        self._transport = transport
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self._stop.set)
        bound = transport.get_extra_info("sockname")
        self._bound = (bound[0], bound[1])
        for f in self.ignored_faults:
            print(f"sim: --radios-only ignores the vehicle fault {f.kind} (the vehicle is real)",
                  file=sys.stderr)
        r = self.options.radio
        print(f"sim ready radios-only vehicle={ep} listen={bound[0]}:{bound[1]} "
              f"radio={r[0]}:{r[1]} seed={self.seed}", flush=True)
        reason = "signal"
        try:
            while not self._stop.is_set():
                self._requests()
                self._anchor()
                self.step()
                if self._finished():
                    reason = "landed"
                    break
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._stop.wait(), TICK_S)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
            t_end = self._unix_of(self._sim_s) if self._boot0 is not None else time.time()
            self.truth.write(t_end, "end", sim_s=round(self._sim_s, 3), reason=reason,
                             radio=self.radio.stats, mavlink=self.stats,
                             vehicle_sysid=self.track.sysid, clock=self._clock_info())
            self.truth.close()
            transport.close()
            self._radio_sock.close()
        return 0

    def _clock_info(self) -> dict[str, Any]:
        return {"offset_s": self.track.offset_s, "source": self.track.offset_source,
                "rate": self.track.rate, "boot0_s": self._boot0}

    def _anchor(self) -> None:
        """Fix the vehicle clock's unix offset, then start the radios at the newest pose."""
        track = self.track
        if (track.offset_s is None and self._first_pose_wall is not None
                and self._wall_s() - self._first_pose_wall > SYSTEM_TIME_WAIT_S):
            track.anchor_now(time.time())
            if track.offset_source == "host":
                print("sim: no SYSTEM_TIME from the vehicle; its clock is anchored on this "
                      "host's", file=sys.stderr)
        if self._boot0 is not None or track.offset_s is None or track.poses.latest_s is None:
            return
        self._boot0 = track.poses.latest_s
        self._write_header()
        print(f"sim: radios on the vehicle's clock (sysid {track.sysid}, boot "
              f"{self._boot0:.3f} s = unix {self._unix_of(0.0):.3f}; boot_unix "
              f"{track.offset_s:.3f} from {track.offset_source}, rate {track.rate})",
              file=sys.stderr, flush=True)

    def step(self) -> None:
        """Run tags and pulses up to the newest pose, each pulse at its own interpolated pose."""
        if self._boot0 is None or self.track.poses.latest_s is None:
            return
        target = self.track.poses.latest_s - self._boot0
        wall = self._wall_s()
        while self._sim_s < target - 1e-9:
            now = self._sim_s
            t_next = min(target, self.radio.next_event_s(), self.faults.next_start_s(now),
                         self._next_vehicle_truth_s)
            self._sim_s = max(t_next, now + 1e-6)
            self._events(wall)
        self._events(wall)

    def _events(self, wall: float) -> None:
        now = self._sim_s
        for what, fault in self.faults.update(now, wall):
            self.truth.write(self._unix_of(now), "fault", phase=what, **fault.describe())
        pose = self._pose(now)
        if now + 1e-9 >= self._next_vehicle_truth_s:
            if pose is not None:
                self._vehicle_truth(now, pose)
            self._next_vehicle_truth_s = math.floor(now + 1e-9) + 1.0
        for datagram in self.radio.advance(now, wall, self._receiver(pose)):
            self._radio_send(datagram)

    def _pose(self, sim_s: float) -> PoseSample | None:
        assert self._boot0 is not None
        return self.track.poses.at(self._boot0 + sim_s)

    def _receiver(self, pose: PoseSample | None) -> ReceiverPose:
        if pose is None:  # a telemetry gap: the power still needs a position, the datagram not
            self.stats["pose_gaps"] += 1
            latest = self.track.poses.latest_s
            last = self.track.poses.at(latest) if latest is not None else None
            if last is None:
                return ReceiverPose(0.0, 0.0, 0.0, 0.0, None, None, None)
            e, n = self._en(last)
            return ReceiverPose(e, n, last.rel_alt_m, last.yaw_deg, None, None, None)
        e, n = self._en(pose)
        return ReceiverPose(e, n, pose.rel_alt_m, pose.yaw_deg, pose.lat_deg, pose.lon_deg,
                            pose.alt_m)

    def _en(self, pose: PoseSample) -> tuple[float, float]:
        e, n, _ = self.frame.to_enu(pose.lat_deg, pose.lon_deg, self.frame.alt0_m)
        return float(e), float(n)

    def _finished(self) -> bool:
        if self.options.keep_running or not (self.track.has_flown
                                              and self.track.landed_and_disarmed):
            self._done_wall = None
            return False
        if self._done_wall is None:
            self._done_wall = self._wall_s()
        return self._wall_s() - self._done_wall >= EXIT_LINGER_S

    # -- truth -------------------------------------------------------------------------------

    def _write_header(self) -> None:
        m, o, track = self.mission, self.options, self.track
        ep = o.vehicle
        self.truth.write(
            self._unix_of(0.0), "sim", mission=m.name, seed=self.seed, mode="radios-only",
            speedup=track.rate or 1.0, sysid=track.sysid or 0,
            mavlink=[ep.host, ep.port], listen=list(self._bound),
            vehicle=str(ep), vehicle_sysid=track.sysid, start_unix=self._unix_of(0.0),
            wall_start_unix=time.time(), clock=self._clock_info(),
            home={"lat_deg": m.home.lat_deg, "lon_deg": m.home.lon_deg, "alt_m": m.home.alt_m},
            vehicle_home=(None if track.home is None else
                          {"lat_deg": track.home[0], "lon_deg": track.home[1],
                           "alt_m": track.home[2]}),
            radio=list(o.radio), reality=describe_world(self.radio.world),
            tags=[{"id": t.id, "freq_hz": t.freq_hz, "motion": t.motion,
                   "x_m": float(t.state[0, 0]), "y_m": float(t.state[0, 1])}
                  for t in self.radio.tags],
            faults=[f.describe() for f in self.faults.faults],
            ignored_faults=[f.describe() for f in self.ignored_faults],
            mission_text=m.source_text)

    def _vehicle_truth(self, sim_s: float, pose: PoseSample) -> None:
        e, n = self._en(pose)
        track = self.track
        self.truth.write(
            self._unix_of(sim_s), "vehicle", east_m=round(e, 3), north_m=round(n, 3),
            up_m=round(pose.rel_alt_m, 3), v_east_m_s=round(pose.v_east_m_s, 3),
            v_north_m_s=round(pose.v_north_m_s, 3), v_up_m_s=round(-pose.v_down_m_s, 3),
            yaw_deg=round(pose.yaw_deg, 2), lat=pose.lat_deg, lon=pose.lon_deg,
            alt_m=round(pose.alt_m, 3), mode=track.mode, armed=track.armed,
            landed_state=track.landed_state_name,
            battery=1.0 if track.battery is None else track.battery,
            battery_known=track.battery is not None,
            gps_ok=track.gps_ok is not False, link_down=False, boot_s=round(pose.boot_s, 3))
