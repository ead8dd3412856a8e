"""Simulated VHF tags and the receiver on the vehicle, speaking detection wire format v1.

Frame: local ENU metres about home (x east, y north, z up); tags are on the ground (z = 0),
the receiver is at the vehicle's position; yaw is a compass heading (0 north, clockwise).

Truth: each tag's state follows its core motion model, stepped every ``truth_step_s`` (1 s)
of sim time; between steps the position is extrapolated with the state's velocity. Each tag
pulses every ``pulse_period_s`` with its own random phase. For a pulse the receiver gets the
noiseless power ``RadioModel.power_db`` from the vehicle's pose, detects it per
``RadioModel.detect`` and reports ``RadioModel.measure``; detected pulses become detection
datagrams carrying the receiver pose (lat/lon/alt_m AMSL/yaw_deg). Clutter: each pulse period,
each tag channel gets Poisson(``clutter_rate``) spurious detections, uniform in dB over the
model's clutter range, plus the ``clutter`` fault's extra rate. Heartbeats listing every tag
go out every second of sim time and at least once a wall second.
Reality: with a ``sim.reality`` profile other than ``matched`` the receiver's power comes from
one world drawn from that profile (:mod:`mexgen_gcs.core.reality`: transmit offsets, the
exponent, an antenna pattern, shadowing, per-pulse fading, tag heights, a compass bias), not
from the mission's model; the truth header records the drawn world.
Faults: radio_silence (nothing sent), detection_dropout, clutter, clock_offset, clock_drift
(the receiver's clock off or running fast/slow), gps_loss (no pose in the datagrams). The truth
log records every pulse with its true power.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from mexgen_gcs.core.motion import MotionModel
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reality import TrueRadio, profile
from mexgen_gcs.io.wire import RSSI_RANGE_DB, encode_detection, encode_heartbeat
from sim.faults import FaultSchedule
from sim.truth import TruthWriter


@dataclass
class TagTruth:
    """One simulated tag: its model and current truth state [x, y, vx, vy] (ENU)."""

    id: str
    freq_hz: int
    model: MotionModel
    state: np.ndarray
    mode: np.ndarray
    motion: str = "static"


@dataclass(frozen=True, slots=True)
class ReceiverPose:
    """The receiver at a pulse: ENU position, compass yaw, and WGS84 if the GPS has a fix."""

    east_m: float
    north_m: float
    up_m: float
    yaw_deg: float
    lat_deg: float | None
    lon_deg: float | None
    alt_m: float | None


class RadioSim:
    """Produces the receiver's datagrams as sim time advances. I/O is done by the caller."""

    def __init__(
        self,
        tags: list[TagTruth],
        radio: RadioModel,
        pulse_period_s: float,
        faults: FaultSchedule,
        truth: TruthWriter,
        unix_of: Callable[[float], float],
        rng: np.random.Generator,
        truth_step_s: float = 1.0,
        world: TrueRadio | None = None,
        pulse_sink: Callable[[int, float, float], None] | None = None,
    ) -> None:
        if not tags or not pulse_period_s > 0.0:
            raise ValueError("need at least one tag and pulse_period_s > 0")
        self.tags = tags
        self.radio = radio
        self.world = world
        self.pulse_sink = pulse_sink
        self.period_s = pulse_period_s
        self.faults = faults
        self.truth = truth
        self.unix_of = unix_of
        rngs = rng.spawn(4)
        self._rng_motion, self._rng_detect, self._rng_clutter, phase_rng = rngs
        self._next_pulse = phase_rng.uniform(0.0, pulse_period_s, len(tags))
        self._truth_step_s = truth_step_s
        self._state_t = 0.0  # sim time of the tags' current truth state
        self._next_truth = 0.0  # next tag truth record (the step after it is applied)
        self._next_heartbeat_s = 0.0
        self._last_heartbeat_wall = -math.inf
        self._next_fault_clutter = math.inf
        self.listening = [t.id for t in tags]
        self.stats = {"pulses": 0, "detections_sent": 0, "clutter_sent": 0, "heartbeats": 0}

    # -- scheduling -----------------------------------------------------------------------

    def next_event_s(self) -> float:
        return min(float(self._next_pulse.min()), self._next_truth, self._next_heartbeat_s,
                   self._next_fault_clutter)

    def advance(self, now_s: float, wall_s: float, pose: ReceiverPose) -> list[bytes]:
        """Process everything due at or before ``now_s``; returns datagrams to send."""
        out: list[bytes] = []
        self._update_fault_clutter(now_s)
        while self._next_truth <= now_s + 1e-9:
            self._truth_tick(self._next_truth)
        for i in np.argsort(self._next_pulse):
            while self._next_pulse[i] <= now_s + 1e-9:
                t = float(self._next_pulse[i])
                self._next_pulse[i] += self.period_s
                out.extend(self._pulse(int(i), t, pose))
        while self._next_fault_clutter <= now_s + 1e-9:
            t = self._next_fault_clutter
            out.extend(self._clutter(int(self._rng_clutter.integers(len(self.tags))), t, pose,
                                     "fault"))
            self._draw_fault_clutter(t)
        if now_s + 1e-9 >= self._next_heartbeat_s or wall_s - self._last_heartbeat_wall >= 1.0:
            self._next_heartbeat_s = math.floor(now_s + 1e-9) + 1.0
            self._last_heartbeat_wall = wall_s
            if not self._silent() and self.pulse_sink is None:
                out.append(encode_heartbeat(self._t_sent(now_s), self.listening))
                self.stats["heartbeats"] += 1
        return out

    # -- truth -----------------------------------------------------------------------------

    def _truth_tick(self, t: float) -> None:
        """Step the tags' truth state to t and record it."""
        if t > self._state_t:
            dt = t - self._state_t
            for tag in self.tags:
                tag.state, tag.mode = tag.model.propagate(tag.state, tag.mode, dt,
                                                          self._rng_motion)
            self._state_t = t
        for tag in self.tags:
            x, y, vx, vy = (float(v) for v in tag.state[0])
            self.truth.write(self.unix_of(t), "tag", tag=tag.id, motion=tag.motion,
                             x_m=round(x, 3), y_m=round(y, 3), vx_m_s=round(vx, 3),
                             vy_m_s=round(vy, 3), mode=int(tag.mode[0]))
        self._next_truth = t + self._truth_step_s

    def _position(self, tag: TagTruth, t: float) -> np.ndarray:
        """[x, y, vx, vy] at sim time t >= _state_t, extrapolated with the velocity."""
        s = tag.state[0].copy()
        s[:2] += (t - self._state_t) * s[2:]
        return s

    # -- pulses ------------------------------------------------------------------------------

    def _silent(self) -> bool:
        return bool(self.faults.active("radio_silence"))

    def _t_sent(self, t: float) -> float:
        """The receiver's clock at sim time t: the vehicle's, plus the clock faults."""
        return (self.unix_of(t) + sum(f.offset_s for f in self.faults.active("clock_offset"))
                + sum(f.ppm * 1e-6 * (t - f.at_s) for f in self.faults.active("clock_drift")))

    def _pulse(self, i: int, t: float, pose: ReceiverPose) -> list[bytes]:
        if self.pulse_sink is not None:
            self._iq_pulse(i, t, pose)
            return []
        tag = self.tags[i]
        xy = self._position(tag, t)[:2]
        rx = np.array([pose.east_m, pose.north_m, pose.up_m])
        yaw = math.radians(pose.yaw_deg)
        tag_z = 0.0
        if self.world is None:
            power = float(self.radio.power_db(xy, rx, yaw))
            detected = bool(self.radio.detect(np.array(power), self._rng_detect))
            rssi = (float(self.radio.measure(np.array(power), self._rng_detect)) if detected
                    else None)
        else:
            tag_z = float(self.world.tag_height_m[i])
            p, d, r = self.world.pulse(np.array(i), xy, rx, yaw, self._rng_detect)
            power, detected = float(p), bool(d)
            rssi = float(r) if detected else None
        dropped = detected and any(
            self._rng_detect.random() < f.probability
            for f in self.faults.active("detection_dropout"))
        send = detected and not dropped and not self._silent()
        t_sent = self._t_sent(t)
        self.stats["pulses"] += 1
        self._truth_pulse(t, tag, xy, tag_z, pose, power, detected=detected, rssi_db=rssi,
                          dropped=dropped, sent=send, t_sent=t_sent if send else None)
        out: list[bytes] = []
        if send:
            assert rssi is not None
            out.append(self._datagram(tag, t_sent, rssi, pose))
            self.stats["detections_sent"] += 1
        n_clutter = int(self._rng_clutter.poisson(self.radio.clutter_rate))
        for _ in range(n_clutter):
            out.extend(self._clutter(i, t, pose, "model"))
        return out

    def _iq_pulse(self, i: int, t: float, pose: ReceiverPose) -> None:
        """IQ mode: the pulse's noiseless power goes to the IQ stream (``sim.iq``), whose
        receiver decides what is heard; the truth records the pulse (``detected`` unknown)."""
        tag = self.tags[i]
        xy = self._position(tag, t)[:2]
        rx = np.array([pose.east_m, pose.north_m, pose.up_m])
        yaw = math.radians(pose.yaw_deg)
        if self.world is None:
            power = float(self.radio.power_db(xy, rx, yaw))
        else:
            p, _, _ = self.world.pulse(np.array(i), xy, rx, yaw, self._rng_detect)
            power = float(p)
        silent = self._silent()
        if not silent:
            assert self.pulse_sink is not None
            self.pulse_sink(i, t, power)
        self.stats["pulses"] += 1
        self._truth_pulse(t, tag, xy, 0.0, pose, power, detected=None, rssi_db=None,
                          dropped=False, sent=not silent, t_sent=None)

    def _truth_pulse(self, t: float, tag: Any, xy: Any, tag_z: float, pose: ReceiverPose,
                     power: float, **outcome: Any) -> None:
        """The truth file's record of one pulse: where tag and receiver were, its power, and
        what became of it (``outcome``: detected, rssi_db, dropped, sent, t_sent)."""
        rx = np.array([pose.east_m, pose.north_m, pose.up_m])
        self.truth.write(
            self.unix_of(t), "pulse", tag=tag.id, freq_hz=tag.freq_hz,
            x_m=round(float(xy[0]), 3), y_m=round(float(xy[1]), 3),
            rx_enu_m=[round(pose.east_m, 3), round(pose.north_m, 3), round(pose.up_m, 3)],
            rx_yaw_deg=round(pose.yaw_deg, 3),
            distance_m=round(float(np.linalg.norm(rx - np.array([xy[0], xy[1], tag_z]))), 3),
            power_db=power, **outcome)

    def _clutter(self, i: int, t: float, pose: ReceiverPose, source: str) -> list[bytes]:
        tag = self.tags[i]
        rssi = float(self._rng_clutter.uniform(self.radio.clutter_min_db,
                                               self.radio.clutter_max_db))
        send = not self._silent()
        t_sent = self._t_sent(t)
        self.truth.write(self.unix_of(t), "clutter", tag=tag.id, freq_hz=tag.freq_hz,
                         rssi_db=rssi, source=source, sent=send,
                         t_sent=t_sent if send else None)
        if not send:
            return []
        self.stats["clutter_sent"] += 1
        return [self._datagram(tag, t_sent, rssi, pose)]

    @staticmethod
    def _datagram(tag: TagTruth, t_sent: float, rssi: float, pose: ReceiverPose) -> bytes:
        # A real receiver saturates: keep extreme model settings inside the wire format's range.
        rssi = min(max(rssi, RSSI_RANGE_DB[0]), RSSI_RANGE_DB[1])
        if pose.lat_deg is None or pose.lon_deg is None:
            return encode_detection(t_sent, rssi, tag=tag.id, freq_hz=tag.freq_hz)
        return encode_detection(t_sent, rssi, tag=tag.id, freq_hz=tag.freq_hz,
                                lat=pose.lat_deg, lon=pose.lon_deg, alt_m=pose.alt_m,
                                yaw_deg=pose.yaw_deg)

    # -- fault clutter (a Poisson process in sim time) ------------------------------------------

    def _fault_rate(self) -> float:
        return sum(f.rate_per_s for f in self.faults.active("clutter"))

    def _update_fault_clutter(self, now_s: float) -> None:
        rate = self._fault_rate()
        if rate <= 0.0:
            self._next_fault_clutter = math.inf
        elif math.isinf(self._next_fault_clutter):
            self._draw_fault_clutter(now_s)

    def _draw_fault_clutter(self, after_s: float) -> None:
        rate = self._fault_rate()
        self._next_fault_clutter = (after_s + float(self._rng_clutter.exponential(1.0 / rate))
                                    if rate > 0.0 else math.inf)


def reality_world(mission: Any, seed: int) -> TrueRadio | None:
    """The radio world of ``sim.reality`` (None for matched), drawn from its own child of the
    simulator's seed so the tags, pulses and noise of a seed stay what they were."""
    name = mission.sim.reality
    if name == "matched":
        return None
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    return profile(name).realise(mission.radio_model(), len(mission.tags), rng)


def describe_world(world: TrueRadio | None) -> dict[str, Any] | None:
    """The drawn world for the truth header (None for matched)."""
    if world is None:
        return None
    return {"profile": world.profile.name, "tx_offset_db": world.tx_offset_db.tolist(),
            "tag_height_m": world.tag_height_m.tolist(),
            "path_loss_exponent": world.path_loss_exponent,
            "compass_bias_deg": math.degrees(world.compass_bias_rad),
            "antenna": world.profile.describe()["antenna"],
            "shadowing_std_db": world.shadowing.std_db, "rician_k_db": world.profile.rician_k_db}
