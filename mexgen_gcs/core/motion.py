"""Tag motion models: RW, CV, CTRA (both directions) and the CV-IFT interacting multiple model.

Frame: local ENU metres about home. A tag state is ``(..., 4) float64`` ``[x, y, vx, vy]``
(east m, north m, east m/s, north m/s) plus an integer mode ``(...,) int8`` that only the
IMM uses (single-mode models keep it at 0). Turn rates follow the ENU convention: positive =
counter-clockwise (a left turn seen from above).

Every model has one verb, ``propagate(state, mode, dt_s, rng) -> (state, mode)``, used both to
sample truth trajectories (simulation) and to predict particles (filter); it never mutates its
inputs. ``initial(n, xy, rng)`` draws velocities and modes for new particles or truth objects.
All operations are vectorised over the leading axes; cost O(number of states).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import fractional_matrix_power

FloatArray = NDArray[np.float64]
ModeArray = NDArray[np.int8]

MotionName = Literal["static", "rw", "cv", "ctra", "cv-ift", "cv-mismatch"]

#: The paper's CV-IFT mode transition matrix, rows = from {CV, CTRA+, CTRA-}, per 1 s.
_DEFAULT_TURN_RATE_RAD_S = 0.2181661564992912  # 12.5 deg/s, mid of the paper's 10-15

PAPER_TRANSITION = ((0.975, 0.0125, 0.0125), (0.225, 0.775, 0.0), (0.225, 0.0, 0.775))


class MotionModel(Protocol):
    """The motion-model role: propagate states and draw initial velocities/modes."""

    @property
    def n_modes(self) -> int: ...

    @property
    def speed_max_m_s(self) -> float: ...

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]: ...

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]: ...


def _initial_velocity(
    xy: FloatArray, speed_min: float, speed_max: float, rng: np.random.Generator
) -> FloatArray:
    """States (n, 4) at positions xy (n, 2) with uniform heading and speed in [min, max]."""
    n = xy.shape[0]
    heading = rng.uniform(0.0, 2.0 * math.pi, n)
    speed = rng.uniform(speed_min, speed_max, n)
    state = np.empty((n, 4))
    state[:, :2] = xy
    state[:, 2] = speed * np.cos(heading)
    state[:, 3] = speed * np.sin(heading)
    return state


def _single_mode_initial(
    xy: FloatArray, speed_min: float, speed_max: float, rng: np.random.Generator
) -> tuple[FloatArray, ModeArray]:
    state = _initial_velocity(xy, speed_min, speed_max, rng)
    return state, np.zeros(xy.shape[0], np.int8)


@dataclass(frozen=True, slots=True)
class RandomWalk:
    """Position random walk: x' = x + w, w ~ N(0, std^2 dt) per axis; velocity is zero.

    ``std_m_per_sqrt_s = 0`` is a stationary tag.
    """

    std_m_per_sqrt_s: float = 1.0
    n_modes: int = 1
    speed_max_m_s: float = 0.0

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        out = state.copy()
        out[..., 2:] = 0.0
        if self.std_m_per_sqrt_s > 0.0:
            out[..., :2] += rng.normal(
                0.0, self.std_m_per_sqrt_s * math.sqrt(dt_s), size=out[..., :2].shape
            )
        return out, mode

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        state = np.zeros((xy.shape[0], 4))
        state[:, :2] = xy
        return state, np.zeros(xy.shape[0], np.int8)


def _turn_step(
    state: FloatArray, omega: FloatArray | float, dt_s: float
) -> FloatArray:
    """Exact constant-turn step: velocity rotated by omega*dt, position integrated along the arc.

    omega (rad/s, CCW positive) broadcasts against state[..., 0]; omega = 0 is CV.
    """
    omega = np.asarray(omega, dtype=np.float64)
    wt = omega * dt_s
    s, c = np.sin(wt), np.cos(wt)
    small = np.abs(omega) < 1e-9
    safe = np.where(small, 1.0, omega)
    a = np.where(small, dt_s, s / safe)  # integral of cos(w t) dt
    b = np.where(small, 0.5 * omega * dt_s * dt_s, (1.0 - c) / safe)  # integral of sin(w t) dt
    vx, vy = state[..., 2], state[..., 3]
    out = np.empty(np.broadcast_shapes(state.shape, (*np.shape(omega), 4)))
    out[..., 0] = state[..., 0] + a * vx - b * vy
    out[..., 1] = state[..., 1] + b * vx + a * vy
    out[..., 2] = c * vx - s * vy
    out[..., 3] = s * vx + c * vy
    return out


def _add_accel_noise(
    state: FloatArray, accel_std: float, dt_s: float, rng: np.random.Generator
) -> None:
    """Discrete white-noise acceleration, piecewise constant over dt, in place, per axis."""
    if accel_std <= 0.0:
        return
    acc = rng.normal(0.0, accel_std, size=state[..., :2].shape)
    state[..., :2] += 0.5 * dt_s * dt_s * acc
    state[..., 2:] += dt_s * acc


@dataclass(frozen=True, slots=True)
class ConstantVelocity:
    """Nearly constant velocity with white-noise acceleration (std per axis, m/s^2)."""

    accel_std_m_s2: float = 0.1
    speed_min_m_s: float = 0.0
    speed_max_m_s: float = 6.0
    n_modes: int = 1

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        out = state.copy()
        out[..., :2] += dt_s * state[..., 2:]
        _add_accel_noise(out, self.accel_std_m_s2, dt_s, rng)
        return out, mode

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        return _single_mode_initial(xy, self.speed_min_m_s, self.speed_max_m_s, rng)


@dataclass(frozen=True, slots=True)
class ConstantTurnRate:
    """Constant turn rate with (noise) acceleration, CTRA. ``turn_rate_rad_s`` may be an array
    broadcasting against the state's leading axes (one rate per truth object), sign = direction.
    """

    turn_rate_rad_s: float | FloatArray = _DEFAULT_TURN_RATE_RAD_S
    accel_std_m_s2: float = 0.1
    speed_min_m_s: float = 0.0
    speed_max_m_s: float = 6.0
    n_modes: int = 1

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        out = _turn_step(state, self.turn_rate_rad_s, dt_s)
        _add_accel_noise(out, self.accel_std_m_s2, dt_s, rng)
        return out, mode

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        return _single_mode_initial(xy, self.speed_min_m_s, self.speed_max_m_s, rng)


@lru_cache(maxsize=64)
def _transition_for(matrix: tuple[tuple[float, ...], ...], steps: float) -> FloatArray:
    """Cumulative transition rows for ``steps`` switch periods (fractional allowed), (K, K)."""
    p = np.asarray(matrix, dtype=np.float64)
    if steps != 1.0:
        p = np.real(fractional_matrix_power(p, steps))
        p = np.clip(p, 0.0, None)
        p /= p.sum(axis=1, keepdims=True)
    cum = np.cumsum(p, axis=1)
    cum[:, -1] = 1.0
    return cum


@lru_cache(maxsize=64)
def _turn_tables(turn_rate_rad_s: float, dt_s: float) -> tuple[FloatArray, ...]:
    """(a, b, c, s) of the exact constant-turn step for modes {CV, +w, -w}, (3,) each."""
    omega = np.array([0.0, turn_rate_rad_s, -turn_rate_rad_s])
    wt = omega * dt_s
    s, c = np.sin(wt), np.cos(wt)
    small = np.abs(omega) < 1e-9
    safe = np.where(small, 1.0, omega)
    a = np.where(small, dt_s, s / safe)
    b = np.where(small, 0.5 * omega * dt_s * dt_s, (1.0 - c) / safe)
    return a, b, c, s


@dataclass(frozen=True, slots=True)
class CvIft:
    """CV with infrequent turns: an IMM of modes {0: CV, 1: CTRA left, 2: CTRA right}.

    Modes switch every ``switch_period_s`` with the row-stochastic ``transition`` matrix (the
    paper's by default); a propagate over dt uses the matrix power dt / switch_period_s.
    Within a mode the tag moves by the exact constant-turn step with turn rate
    ``[0, +w, -w][mode]``, plus white-noise acceleration.
    """

    turn_rate_rad_s: float | FloatArray = _DEFAULT_TURN_RATE_RAD_S
    accel_std_m_s2: float = 0.05
    transition: tuple[tuple[float, ...], ...] = PAPER_TRANSITION
    switch_period_s: float = 1.0
    speed_min_m_s: float = 0.0
    speed_max_m_s: float = 6.0
    n_modes: int = 3
    _signs: FloatArray = field(
        default_factory=lambda: np.array([0.0, 1.0, -1.0]), repr=False, compare=False
    )

    def stationary_distribution(self) -> FloatArray:
        """The mode occupancy the chain converges to, (K,)."""
        p = np.asarray(self.transition, dtype=np.float64)
        vals, vecs = np.linalg.eig(p.T)
        v = np.real(vecs[:, np.argmin(np.abs(vals - 1.0))])
        return v / v.sum()

    def switch(self, mode: ModeArray, dt_s: float, rng: np.random.Generator) -> ModeArray:
        """Markov mode switches over dt_s, vectorised with one uniform draw per state."""
        cum = _transition_for(self.transition, dt_s / self.switch_period_s)
        u = rng.random(mode.shape)
        rows = cum[mode, :-1]  # (..., K - 1); u < cum[:, -1] = 1 always
        return (u[..., None] >= rows).sum(axis=-1, dtype=np.int8)

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        new_mode = self.switch(mode, dt_s, rng)
        if np.ndim(self.turn_rate_rad_s) == 0:
            # one turn rate: the step's coefficients per mode, (K,) each, gathered by mode
            a, b, c, s = (t[new_mode] for t in _turn_tables(float(self.turn_rate_rad_s), dt_s))
            vx, vy = state[..., 2], state[..., 3]
            out = np.empty(state.shape)
            out[..., 0] = state[..., 0] + a * vx - b * vy
            out[..., 1] = state[..., 1] + b * vx + a * vy
            out[..., 2] = c * vx - s * vy
            out[..., 3] = s * vx + c * vy
        else:
            omega = self._signs[new_mode] * self.turn_rate_rad_s
            out = _turn_step(state, omega, dt_s)
        _add_accel_noise(out, self.accel_std_m_s2, dt_s, rng)
        return out, new_mode

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        state = _initial_velocity(xy, self.speed_min_m_s, self.speed_max_m_s, rng)
        pi = self.stationary_distribution()
        mode = np.asarray(rng.choice(len(pi), size=xy.shape[0], p=pi), dtype=np.int8)
        return state, mode


def make_motion_model(
    name: MotionName,
    *,
    rw_std_m_per_sqrt_s: float = 1.0,
    accel_std_m_s2: float = 0.1,
    mismatch_accel_std_m_s2: float = 1.0,
    turn_rate_deg_s: float = 12.5,
    speed_min_m_s: float = 0.0,
    speed_max_m_s: float = 6.0,
) -> MotionModel:
    """Build a model by name. ``cv-mismatch`` is the paper's mismatched filter: CV with the
    inflated ``mismatch_accel_std_m_s2`` standing in for a CV-IFT truth.
    """
    if name == "static":
        return RandomWalk(std_m_per_sqrt_s=0.0)
    if name == "rw":
        return RandomWalk(std_m_per_sqrt_s=rw_std_m_per_sqrt_s)
    if name == "cv":
        return ConstantVelocity(accel_std_m_s2, speed_min_m_s, speed_max_m_s)
    if name == "cv-mismatch":
        return ConstantVelocity(mismatch_accel_std_m_s2, speed_min_m_s, speed_max_m_s)
    if name == "ctra":
        return ConstantTurnRate(
            math.radians(turn_rate_deg_s), accel_std_m_s2, speed_min_m_s, speed_max_m_s
        )
    if name == "cv-ift":
        return CvIft(
            turn_rate_rad_s=math.radians(turn_rate_deg_s),
            accel_std_m_s2=accel_std_m_s2,
            speed_min_m_s=speed_min_m_s,
            speed_max_m_s=speed_max_m_s,
        )
    raise ValueError(f"unknown motion model {name!r}; expected one of {MotionName.__args__}")


def simulate(
    model: MotionModel,
    state0: FloatArray,
    mode0: ModeArray,
    dt_s: float,
    steps: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, ModeArray]:
    """Truth trajectories: (steps + 1, *state0.shape) states and (steps + 1, *mode0.shape)
    modes, starting with state0. Cost O(steps * objects) with a loop over steps only.
    """
    states = np.empty((steps + 1, *state0.shape))
    modes = np.empty((steps + 1, *mode0.shape), np.int8)
    states[0], modes[0] = state0, mode0
    for k in range(steps):
        states[k + 1], modes[k + 1] = model.propagate(states[k], modes[k], dt_s, rng)
    return states, modes
