"""The simulated world of an experiment run: truth tags, the vehicle, and the radio.

Frame: local ENU metres about the area centre (x east, y north, z up); tags are on the ground
(z = 0). Headings and yaw are compass headings (0 = north, clockwise); a heading h is the
velocity direction (sin h, cos h) (east, north).

- Truth: per start, each tag's whole trajectory is drawn once with its core motion model
  (``core.motion``), sampled at every pulse: uniform position in the initial search space,
  heading uniform in [0, 360), speed uniform in the scenario's range, a turn rate uniform in
  10-15 deg/s per object (CV-IFT), the paper's IMM transition matrix. A trajectory that leaves
  the search area before ``min_inside_s`` is redrawn (rejection sampling).
- Vehicle: a point mass at a fixed altitude that follows horizontal velocity commands with
  the speed and acceleration limits (velocity moves straight towards the command at
  ``max_accel``, the model the planner's paths assume), yawing to the commanded heading.
- Radio: every pulse, each tag's noiseless power (``RadioModel.power_db``) at the receiver's
  pose, a detection draw, a noise draw and Poisson clutter. With a reality profile other than
  ``matched`` the power comes from a world drawn from it (``core.reality.TrueRadio``: tag
  offsets, exponent, antenna, shadowing, fading, tag heights, compass bias), drawn once per
  start (``reality_seed``) so every method and estimator meets the same world. The number
  of random draws per pulse does not depend on where the vehicle is, so every method sees
  the same radio noise stream for the same seeds (common random numbers).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.motion import CvIft, MotionModel, make_motion_model, simulate
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reality import TrueRadio, profile
from mexgen_gcs.errors import MexgenError
from mexgen_gcs.experiments.scenario import Scenario
from mexgen_gcs.experiments.seeds import reality_seed, truth_seed

FloatArray = NDArray[np.float64]

MAX_TRUTH_TRIES = 10_000
"""Redraws of one tag's trajectory before giving up on the containment constraint."""


@dataclass(frozen=True, slots=True, eq=False)
class Truth:
    """Truth trajectories of a start's tags at every pulse, t = k * pulse_period_s."""

    states: FloatArray
    """(K + 1, n_tags, 4) [x_east_m, y_north_m, vx_m_s, vy_m_s]."""
    modes: NDArray[np.int8]
    """(K + 1, n_tags) IMM modes (0 for single-mode models)."""
    turn_rates_deg_s: FloatArray
    """(n_tags,) the turn rate drawn per object (0 when the model has no turns)."""
    tries: int
    """Trajectories drawn in all, rejected ones included."""

    def digest(self) -> str:
        """A short fingerprint of the trajectories (paired runs share it)."""
        return hashlib.sha256(np.ascontiguousarray(self.states).tobytes()).hexdigest()[:16]


def truth_model(sc: Scenario, turn_rate_deg_s: float | FloatArray) -> MotionModel:
    """The truth motion model of the objects. ``turn_rate_deg_s`` (CV-IFT only) is a number
    or one rate per object, (n,), broadcasting against states (n, 4)."""
    lo, hi = sc.truth_speed_m_s
    model = make_motion_model(
        sc.truth_motion,  # type: ignore[arg-type]
        rw_std_m_per_sqrt_s=sc.truth_rw_std_m_per_sqrt_s, accel_std_m_s2=sc.truth_accel_std_m_s2,
        speed_min_m_s=lo, speed_max_m_s=hi)
    if isinstance(model, CvIft):
        model = replace(model, turn_rate_rad_s=np.radians(turn_rate_deg_s))
    return model


def make_truth(sc: Scenario, rng: np.random.Generator, batch: int = 8,
               max_tries: int = MAX_TRUTH_TRIES) -> Truth:
    """Draw every tag's trajectory for ``sc.steps`` pulses (see the module docstring).

    Candidates are drawn ``batch`` per tag still without a trajectory and simulated together
    (one vectorised ``simulate``); each such tag takes its first candidate that stays inside
    the search area for ``min_inside_s``. Cost O(rounds * steps) vectorised propagations.
    Raises MexgenError if the tags cannot be kept inside within ``max_tries`` draws.
    """
    steps, dt = sc.steps, sc.pulse_period_s
    n_inside = min(steps, math.ceil(sc.min_inside_s / dt))
    initial, area = sc.initial_area(), sc.area()
    states = np.empty((steps + 1, sc.n_tags, 4))
    modes = np.empty((steps + 1, sc.n_tags), np.int8)
    rates = np.zeros(sc.n_tags)
    pending = list(range(sc.n_tags))
    tries = 0
    while pending:
        if tries >= max_tries:
            raise MexgenError(
                f"could not draw a {sc.truth_motion} trajectory that stays inside the "
                f"{2 * sc.area_half_m:g} m search area for {sc.min_inside_s:g} s in "
                f"{max_tries} tries; enlarge the area or shorten min_inside_s")
        m = len(pending) * batch
        tries += m
        rate_deg_s = rng.uniform(*sc.truth_turn_rate_deg_s, size=m)
        model = truth_model(sc, rate_deg_s)
        s0, m0 = model.initial(initial.sample_uniform(m, rng), rng)
        traj, traj_modes = simulate(model, s0, m0, dt, steps, rng)
        ok = np.asarray(area.contains(traj[: n_inside + 1, :, :2]).all(axis=0)) if n_inside else (
            np.ones(m, dtype=bool))
        still: list[int] = []
        for j, tag in enumerate(pending):
            hits = np.flatnonzero(ok[j * batch:(j + 1) * batch])
            if hits.size == 0:
                still.append(tag)
                continue
            c = j * batch + int(hits[0])
            states[:, tag], modes[:, tag] = traj[:, c], traj_modes[:, c]
            rates[tag] = rate_deg_s[c] if sc.truth_motion == "cv-ift" else 0.0
        pending = still
    return Truth(states, modes, rates, tries)


@lru_cache(maxsize=16)
def truth_for(sc: Scenario, seed: int, start: int) -> Truth:
    """The truth of one start: depends on (seed, start) only, shared by every repetition and
    method. Cached per process (a pure function of its arguments)."""
    return make_truth(sc, np.random.default_rng(truth_seed(seed, start)))


class PointMass:
    """A multirotor as a point mass following velocity commands (horizontal; vertical: the
    commanded down-velocity, held).

    State in plain floats (this runs every control period). ``step`` is exact for a command
    held over dt: the velocity moves towards the (speed-limited) command at ``max_accel``
    along the straight line in velocity space, then holds it.
    """

    def __init__(self, east_m: float, north_m: float, alt_m: float, max_speed_m_s: float,
                 max_accel_m_s2: float, yaw_deg: float = 0.0) -> None:
        if not (max_speed_m_s > 0.0 and max_accel_m_s2 > 0.0):
            raise ValueError("max_speed_m_s and max_accel_m_s2 must be > 0")
        self.east_m, self.north_m, self.alt_m = east_m, north_m, alt_m
        self.v_east_m_s = 0.0
        self.v_north_m_s = 0.0
        self.yaw_deg = yaw_deg % 360.0
        self.max_speed_m_s = max_speed_m_s
        self.max_accel_m_s2 = max_accel_m_s2

    @property
    def xyz_m(self) -> FloatArray:
        return np.array([self.east_m, self.north_m, self.alt_m])

    @property
    def v_xy_m_s(self) -> FloatArray:
        return np.array([self.v_east_m_s, self.v_north_m_s])

    @property
    def yaw_rad(self) -> float:
        return math.radians(self.yaw_deg)

    def step(self, v_east_m_s: float, v_north_m_s: float, yaw_deg: float, dt_s: float,
             v_down_m_s: float = 0.0) -> None:
        """Hold the command (east, north, down m/s; compass yaw) for dt_s seconds."""
        self.alt_m -= v_down_m_s * dt_s
        speed = math.hypot(v_east_m_s, v_north_m_s)
        if speed > self.max_speed_m_s:
            v_east_m_s *= self.max_speed_m_s / speed
            v_north_m_s *= self.max_speed_m_s / speed
        de, dn = v_east_m_s - self.v_east_m_s, v_north_m_s - self.v_north_m_s
        gap = math.hypot(de, dn)
        tau = min(dt_s, gap / self.max_accel_m_s2)
        # p(dt) = p0 + v0 dt + a u (tau dt - tau^2 / 2), u = dv / |dv|
        k = self.max_accel_m_s2 * (tau * dt_s - 0.5 * tau * tau) / gap if gap > 0.0 else 0.0
        self.east_m += self.v_east_m_s * dt_s + k * de
        self.north_m += self.v_north_m_s * dt_s + k * dn
        if tau >= gap / self.max_accel_m_s2:
            self.v_east_m_s, self.v_north_m_s = v_east_m_s, v_north_m_s
        else:
            f = self.max_accel_m_s2 * tau / gap
            self.v_east_m_s += f * de
            self.v_north_m_s += f * dn
        self.yaw_deg = yaw_deg % 360.0


class RadioWorld:
    """The receiver's measurements per pulse, drawn from one generator; ``world`` (a drawn
    reality) replaces the mission's model for the power, detection and noise."""

    def __init__(self, radio: RadioModel, n_tags: int, rng: np.random.Generator,
                 world: TrueRadio | None = None) -> None:
        self.radio = radio
        self.n_tags = n_tags
        self.rng = rng
        self.world = world
        self._tags = np.arange(n_tags)

    def pulse(self, tag_xy: FloatArray, rx_xyz: FloatArray,
              rx_yaw_rad: float) -> list[list[float]]:
        """Detections (dB) per tag for one pulse: tag_xy (n_tags, 2), rx_xyz (3,).

        A fixed number of draws per call: n detection uniforms, n noise normals, n clutter
        counts and the clutter values (whose count does not depend on the pose)."""
        if self.world is None:
            power = self.radio.power_db(tag_xy, rx_xyz, rx_yaw_rad)
            detected = self.radio.detect(power, self.rng)
            z = self.radio.measure(power, self.rng)
        else:
            rx = np.broadcast_to(rx_xyz, (self.n_tags, 3))
            _, detected, z = self.world.pulse(self._tags, tag_xy, rx, rx_yaw_rad, self.rng)
        n_clutter = self.rng.poisson(self.radio.clutter_rate, self.n_tags)
        clutter = self.rng.uniform(self.radio.clutter_min_db, self.radio.clutter_max_db,
                                   int(n_clutter.sum()))
        out: list[list[float]] = [[float(z[i])] if detected[i] else [] for i in
                                  range(self.n_tags)]
        offset = 0
        for i, c in enumerate(n_clutter.tolist()):
            out[i].extend(clutter[offset:offset + c].tolist())
            offset += c
        return out


def reality_for(sc: Scenario, radio: RadioModel, seed: int, start: int) -> TrueRadio | None:
    """The start's radio world under the scenario's reality profile (None when matched: the
    mission's model itself, drawn exactly as before profiles existed)."""
    if sc.reality == "matched":
        return None
    return profile(sc.reality).realise(radio, sc.n_tags,
                                       np.random.default_rng(reality_seed(seed, start)))
