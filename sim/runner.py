"""The simulator process: wires the vehicle, the radios and the truth log to UDP sockets.

Frame: local ENU metres about the mission home inside; MAVLink and wire format v1 outside.

One asyncio event loop. A tick every ``TICK_S`` of wall time integrates the physics up to
the sim time that is due (physics substeps end exactly on radio and fault event times, so
pulses see the vehicle where it was), sends the datagrams, and lets the MAVLink side send
what its wall-clock schedule says. It stops on SIGINT/SIGTERM, or (unless ``keep_running``)
a little after the vehicle has landed and disarmed having flown.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import socket
import sys
import time
from typing import Any

import numpy as np

from mexgen_gcs.config import Mission
from sim import px4_modes
from sim.autopilot import Autopilot
from sim.clock import SimClock
from sim.faults import Fault, FaultSchedule
from sim.fence import Fence
from sim.iq import IqRadio, IqServer
from sim.params import ParamTable
from sim.radios import RadioSim, ReceiverPose, describe_world, reality_world
from sim.scenario import (
    SimOptions,
    airframe_limits,
    build_tags,
    faults_of,
    initial_params,
    seed_of,
)
from sim.takeover import NO_TAKEOVER, TakeoverLog, pilot_mode
from sim.truth import TruthWriter
from sim.tunnel_radio import TunnelEncoder
from sim.vehicle import MavlinkVehicle

TICK_S = 0.01
MAX_PHYSICS_DT_S = 0.05
TRUTH_VEHICLE_PERIOD_S = 1.0
EXIT_LINGER_S = 1.5

Address = tuple[str, int]


class _MavlinkProtocol(asyncio.DatagramProtocol):
    def __init__(self, sim: Simulation) -> None:
        self.sim = sim

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.sim.vehicle.handle_datagram(data, (addr[0], addr[1]))

    def error_received(self, exc: Exception) -> None:
        pass  # ICMP port unreachable from a peer that is not listening (yet): keep going


class Simulation:
    """All simulator state for one run; ``run()`` drives it until stopped."""

    def __init__(self, mission: Mission, options: SimOptions) -> None:
        self.mission = mission
        self.options = options
        self.clock = SimClock(options.speedup, rate_error=options.clock_rate_error,
                              system_time=options.system_time)
        self.frame = mission.local_frame()
        self.seed = seed_of(mission, options)
        seeds = np.random.SeedSequence(self.seed).spawn(3)
        world_rng, radio_rng, vehicle_rng = (np.random.default_rng(s) for s in seeds)
        self.truth = TruthWriter(options.truth_dir)
        self.faults = FaultSchedule(faults_of(mission, options))
        self.autopilot = Autopilot(ParamTable(initial_params(mission, options)),
                                   airframe_limits(mission),
                                   mission.sim.battery_endurance_s, self.frame.alt0_m,
                                   vehicle_rng)
        self._mav_transport: asyncio.DatagramTransport | None = None
        targets = [options.mavlink] + ([options.gcs] if options.gcs else [])
        self.takeover: TakeoverLog | None = None
        self.vehicle = MavlinkVehicle(self.autopilot, self.clock, self.frame, self._mav_sendto,
                                      targets, options.sysid, on_fence=self._fence_accepted,
                                      on_command=self._command_received)
        if options.fence_latlon_deg:
            self.vehicle.preload_fence(list(options.fence_latlon_deg))
        self.iq: IqRadio | None = None
        self.iq_server: IqServer | None = None
        if options.iq is not None:
            # its own stream of draws, so the tags, pulses and vehicle of a seed stay the same
            iq_rng = np.random.default_rng(np.random.SeedSequence(self.seed).spawn(5)[4])
            self.iq = IqRadio([float(t.freq_hz) for t in mission.tags],
                              mission.receiver.pulse_width_s, mission.radio.sensitivity_db,
                              mission.radio.noise_std_db, options.iq, iq_rng)
            self.iq_server = IqServer(self.iq, lambda: self.clock.sim_s)
        self.radio = RadioSim(build_tags(mission, world_rng), mission.radio_model(),
                              mission.receiver.pulse_period_s, self.faults, self.truth,
                              self.clock.unix_of, radio_rng,
                              world=reality_world(mission, self.seed),
                              pulse_sink=self.iq.pulse if self.iq is not None else None)
        self._radio_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._radio_sock.setblocking(False)
        self._tunnel = (TunnelEncoder(options.sysid)
                        if options.radio_format == "mavlink-tunnel" else None)
        self._next_vehicle_truth_s = 0.0
        self._stop = asyncio.Event()
        self._done_wall_s: float | None = None
        self.radio_send_errors = 0

    # -- I/O -----------------------------------------------------------------------------

    def _mav_sendto(self, data: bytes, addr: Address) -> None:
        if self._mav_transport is not None and not self._mav_transport.is_closing():
            self._mav_transport.sendto(data, addr)

    def _radio_send(self, data: bytes) -> None:
        if self._tunnel is not None:
            data = self._tunnel.encode(data)
        try:
            self._radio_sock.sendto(data, self.options.radio)
        except OSError:  # nobody listening yet, or the buffer is full: a lost datagram
            self.radio_send_errors += 1

    # -- main loop -----------------------------------------------------------------------

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            lambda: _MavlinkProtocol(self), local_addr=self.options.listen,
            family=socket.AF_INET)
        self._mav_transport = transport
        iq_text = ""
        iq_srv: asyncio.Server | None = None
        if self.iq_server is not None and self.options.iq is not None:
            server = self.iq_server
            iq_srv = await loop.create_server(lambda: server, self.options.iq.host,
                                              self.options.iq.port)
            host, port = iq_srv.sockets[0].getsockname()[:2]
            iq_text = f" iq={host}:{port}"
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self._stop.set)
        listen = transport.get_extra_info("sockname")
        self._write_header(listen)
        o = self.options
        gcs = f" gcs={o.gcs[0]}:{o.gcs[1]}" if o.gcs else ""
        print(f"sim ready mavlink={o.mavlink[0]}:{o.mavlink[1]} radio={o.radio[0]}:{o.radio[1]}"
              f" listen={listen[0]}:{listen[1]} sysid={o.sysid}{gcs}"
              f" speedup={self.clock.speedup:g} seed={self.seed}{iq_text}", flush=True)
        try:
            while not self._stop.is_set():
                self.tick()
                if self._finished():
                    break
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._stop.wait(), TICK_S)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
            self.truth.write(self.clock.unix(), "end", sim_s=round(self.clock.sim_s, 3),
                             reason="signal" if self._stop.is_set() else "landed",
                             radio=self.radio.stats, mavlink=self.vehicle.stats,
                             **({"iq": self.iq.stats} if self.iq is not None else {}),
                             **self._takeover_counts())
            self.truth.close()
            if iq_srv is not None:
                iq_srv.close()
            transport.close()
            self._radio_sock.close()
        return 0

    def _finished(self) -> bool:
        if self.options.keep_running or not self.autopilot.flight_complete:
            self._done_wall_s = None
            return False
        now = self.clock.wall_s()
        if self._done_wall_s is None:
            self._done_wall_s = now
        return now - self._done_wall_s >= EXIT_LINGER_S

    def tick(self) -> None:
        """Integrate up to the due sim time, emitting events on their exact times."""
        due = self.clock.due_s()
        wall = self.clock.wall_s()
        while self.clock.sim_s < due - 1e-9:
            now = self.clock.sim_s
            radio_next = self.radio.next_event_s() if self.options.radios else math.inf
            t_next = min(due, radio_next, self.faults.next_start_s(now),
                         self._next_vehicle_truth_s, now + MAX_PHYSICS_DT_S)
            t_next = max(t_next, now + 1e-6)
            self.autopilot.step(t_next - now, t_next, wall)
            self.clock.sim_s = t_next
            self._events(wall)
        self._events(wall)
        if self.iq_server is not None:
            self.iq_server.pump()
        self.vehicle.tick()

    def _events(self, wall: float) -> None:
        now = self.clock.sim_s
        for what, fault in self.faults.update(now, wall):
            self._apply_fault(what, fault)
        for ev in self.vehicle.take_events():
            self.truth.write(self.clock.unix(), "event", kind=ev.kind, text=ev.text)
        if now + 1e-9 >= self._next_vehicle_truth_s:
            self._vehicle_truth()
            self._next_vehicle_truth_s = math.floor(now + 1e-9) + TRUTH_VEHICLE_PERIOD_S
        if self.options.radios:
            for datagram in self.radio.advance(now, wall, self._pose()):
                self._radio_send(datagram)

    def _pose(self) -> ReceiverPose:
        s = self.autopilot.state
        if self.autopilot.gps_ok:
            lat, lon, alt = self.vehicle.telemetry.vehicle_geodetic()
            return ReceiverPose(s.east_m, s.north_m, s.up_m, s.yaw_deg, lat, lon, alt)
        return ReceiverPose(s.east_m, s.north_m, s.up_m, s.yaw_deg, None, None, None)

    def _apply_fault(self, what: str, fault: Fault) -> None:
        extra: dict[str, Any] = {}
        if fault.kind == "pilot_takeover":
            extra = self._pilot(what, fault)
        self.truth.write(self.clock.unix(), "fault", phase=what, **fault.describe(), **extra)
        print(f"sim: fault {fault.kind} {what} at sim {self.clock.sim_s:.1f} s", file=sys.stderr,
              flush=True)
        if fault.kind == "link_drop":
            self.vehicle.link_down = bool(self.faults.active("link_drop"))
        elif fault.kind == "gps_loss":
            self.autopilot.gps_ok = not self.faults.active("gps_loss")
        elif fault.kind == "battery_sag" and what == "start":
            ap = self.autopilot
            ap.battery_fraction = max(0.0, ap.battery_fraction - fault.percent / 100.0)

    def _pilot(self, what: str, fault: Fault) -> dict[str, Any]:
        """The pilot's RC mode switch; returns fields for the fault record."""
        ap = self.autopilot
        before = px4_modes.name(ap.mode)
        if what == "start":
            stats = self.vehicle.stats
            self.takeover = TakeoverLog(fault, stats["rx_commands"], stats["rx_setpoints"])
            ap.pilot_switch(pilot_mode(fault))
        else:
            ap.pilot_switch(px4_modes.LAND)
            if self.takeover is not None:
                self.takeover.landed_by_pilot = True
        return {"mode_before": before, "mode_after": px4_modes.name(ap.mode),
                **self._takeover_counts()}

    def _takeover_counts(self) -> dict[str, Any]:
        if self.takeover is None:
            return dict(NO_TAKEOVER)
        return self.takeover.counts(self.vehicle.stats)

    def _command_received(self, command: int, result: int) -> None:
        if self.takeover is None:
            return
        name = self.takeover.note_command(command)
        self.truth.write(self.clock.unix(), "event", kind="gcs_command_after_takeover",
                         text=f"{name} -> {result}", command=command, name=name, result=result,
                         mode=px4_modes.name(self.autopilot.mode))

    # -- truth -----------------------------------------------------------------------------

    def _write_header(self, listen: Any) -> None:
        m, o = self.mission, self.options
        self.truth.write(
            self.clock.unix(), "sim", mission=m.name, seed=self.seed, speedup=o.speedup,
            clock_rate=self.clock.rate, system_time=o.system_time,
            start_unix=self.clock.start_unix, wall_start_unix=time.time(), sysid=o.sysid,
            home={"lat_deg": m.home.lat_deg, "lon_deg": m.home.lon_deg, "alt_m": m.home.alt_m},
            mavlink=list(o.mavlink), radio=list(o.radio), listen=[listen[0], listen[1]],
            tags=[{"id": t.id, "freq_hz": t.freq_hz, "motion": t.motion,
                   "x_m": float(t.state[0, 0]), "y_m": float(t.state[0, 1])}
                  for t in self.radio.tags],
            faults=[f.describe() for f in self.faults.faults],
            reality=describe_world(self.radio.world), mission_text=m.source_text)

    def _vehicle_truth(self) -> None:
        ap, s = self.autopilot, self.autopilot.state
        lat, lon, alt = self.vehicle.telemetry.vehicle_geodetic()
        self.truth.write(
            self.clock.unix(), "vehicle", east_m=round(s.east_m, 3), north_m=round(s.north_m, 3),
            up_m=round(s.up_m, 3), v_east_m_s=round(s.v_east_m_s, 3),
            v_north_m_s=round(s.v_north_m_s, 3), v_up_m_s=round(s.v_up_m_s, 3),
            yaw_deg=round(s.yaw_deg, 2), lat=lat, lon=lon, alt_m=round(alt, 3),
            mode=px4_modes.name(ap.mode), armed=ap.armed, landed_state=ap.landed_state.name,
            battery=round(ap.battery_fraction, 4), gps_ok=ap.gps_ok,
            link_down=self.vehicle.link_down)

    def _fence_accepted(self, fence: Fence) -> None:
        self.truth.write(
            self.clock.unix(), "fence",
            inclusion_polygons_m=[a.vertices_m.round(2).tolist() for a in fence.inclusion_polygons],
            exclusion_polygons_m=[a.vertices_m.round(2).tolist() for a in fence.exclusion_polygons],
            inclusion_circles=[[c.east_m, c.north_m, c.radius_m] for c in fence.inclusion_circles],
            exclusion_circles=[[c.east_m, c.north_m, c.radius_m] for c in fence.exclusion_circles],
            items=len(fence.items))
