"""Tag motion models: RW, CV, CTRA (both directions) and the CV-IFT interacting multiple model.

Frame: local ENU metres about home. A tag state is ``(..., 4) float64`` ``[x, y, vx, vy]``
(east m, north m, east m/s, north m/s) plus an integer mode ``(...,) int8`` that only the
IMM uses (single-mode models keep it at 0). Turn rates follow the ENU convention: positive =
counter-clockwise (a left turn seen from above).

Every model has one verb, ``propagate(state, mode, dt_s, rng) -> (state, mode)``, used both to
sample truth trajectories (simulation) and to predict particles (filter); it never mutates its
inputs. ``initial(n, xy, rng)`` draws velocities and modes for new particles or truth objects.
All operations are vectorised over the leading axes; cost O(number of states). Each
``propagate`` is one compiled pass over the states (:mod:`core.jit`) that draws its noise from
the caller's generator in the order numpy would (per state: mode switch uniforms for all
states first, then the two accelerations of each state in turn).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import fractional_matrix_power

from mexgen_gcs.core.jit import inline, kernel

FloatArray = NDArray[np.float64]
ModeArray = NDArray[np.int8]

MotionName = Literal["static", "rw", "cv", "ctra", "cv-ift", "cv-mismatch"]

#: The paper's CV-IFT mode transition matrix, rows = from {CV, CTRA+, CTRA-}, per 1 s.
_DEFAULT_TURN_RATE_RAD_S = 0.2181661564992912  # 12.5 deg/s, mid of the paper's 10-15

PAPER_TRANSITION = ((0.975, 0.0125, 0.0125), (0.225, 0.775, 0.0), (0.225, 0.0, 0.775))
_NO_TURN = np.zeros(1)


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
    moving_dims: int = 2
    """State columns the model moves: east, north (the velocity columns stay zero)."""

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        flat = _rows(state)
        out = _random_walk_step(flat, self.std_m_per_sqrt_s * math.sqrt(dt_s),
                                self.std_m_per_sqrt_s > 0.0, rng)
        return out.reshape(state.shape), mode

    def initial(
        self, xy: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        state = np.zeros((xy.shape[0], 4))
        state[:, :2] = xy
        return state, np.zeros(xy.shape[0], np.int8)


def _rows(state: FloatArray) -> FloatArray:
    """States (..., 4) as contiguous rows (n, 4) for a kernel."""
    return np.ascontiguousarray(state, dtype=np.float64).reshape(-1, 4)


@inline
def _turn_coefficients(omega: float, dt_s: float) -> tuple[float, float, float, float]:
    """(a, b, c, s) of the exact constant-turn step over dt_s at turn rate omega (rad/s, CCW
    positive; 0 is CV): ``a`` = integral of cos(w t) dt, ``b`` = integral of sin(w t) dt,
    ``c``, ``s`` = cos, sin of omega dt."""
    wt = omega * dt_s
    s, c = math.sin(wt), math.cos(wt)
    if abs(omega) < 1e-9:
        return dt_s, 0.5 * omega * dt_s * dt_s, c, s
    return s / omega, (1.0 - c) / omega, c, s


@inline
def _turn_and_accelerate(state: FloatArray, out: FloatArray, i: int, a: float, b: float,
                         c: float, s: float, accel_std: float, dt_s: float,
                         rng: np.random.Generator) -> None:
    """Row i of out: the exact constant-turn step of row i of state (velocity rotated by
    omega dt, position integrated along the arc), plus discrete white-noise acceleration,
    piecewise constant over dt, N(0, accel_std^2) per axis (drawn east, then north)."""
    vx, vy = state[i, 2], state[i, 3]
    out[i, 0] = state[i, 0] + a * vx - b * vy
    out[i, 1] = state[i, 1] + b * vx + a * vy
    out[i, 2] = c * vx - s * vy
    out[i, 3] = s * vx + c * vy
    if accel_std > 0.0:
        for k in range(2):
            acc = accel_std * rng.standard_normal()
            out[i, k] += 0.5 * dt_s * dt_s * acc
            out[i, 2 + k] += dt_s * acc


@kernel
def _random_walk_step(state: FloatArray, std: float, draw: bool, rng: np.random.Generator
                      ) -> FloatArray:
    """Rows (n, 4): position + N(0, std^2) per axis (if ``draw``), velocity zero."""
    out = np.empty_like(state)
    for i in range(state.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = state[i, 0], state[i, 1], 0.0, 0.0
        if draw:
            out[i, 0] += std * rng.standard_normal()
            out[i, 1] += std * rng.standard_normal()
    return out


@kernel
def _turn_step(state: FloatArray, omega: FloatArray, accel_std: float, dt_s: float,
               rng: np.random.Generator) -> FloatArray:
    """Rows (n, 4) propagated by constant turn rate ``omega`` (1,) for every row, or (n,)
    one per row, plus the acceleration noise."""
    n = state.shape[0]
    out = np.empty_like(state)
    a, b, c, s = _turn_coefficients(omega[0], dt_s)
    for i in range(n):
        if omega.shape[0] > 1:
            a, b, c, s = _turn_coefficients(omega[i], dt_s)
        _turn_and_accelerate(state, out, i, a, b, c, s, accel_std, dt_s, rng)
    return out


@inline
def _next_mode(u: float, cum_row: FloatArray) -> int:
    """The mode a uniform u selects from one row of cumulative transition probabilities."""
    k = 0
    for j in range(cum_row.shape[0] - 1):  # u < cum[-1] = 1 always
        if u >= cum_row[j]:
            k += 1
    return k


@kernel
def _switch_modes(mode: ModeArray, cum: FloatArray, rng: np.random.Generator) -> ModeArray:
    """Markov mode switches (n,) with cumulative transition rows ``cum`` (K, K)."""
    out = np.empty_like(mode)
    for i in range(mode.shape[0]):
        out[i] = _next_mode(rng.random(), cum[mode[i]])
    return out


@kernel
def _imm_step(state: FloatArray, mode: ModeArray, cum: FloatArray, signs: FloatArray,
              rate: FloatArray, accel_std: float, dt_s: float, rng: np.random.Generator
              ) -> tuple[FloatArray, ModeArray]:
    """Rows (n, 4) and modes (n,) of the IMM: switch modes (cumulative rows ``cum`` (K, K)),
    then the constant-turn step at ``signs[mode] * rate`` (rate (1,) or (n,)), plus noise."""
    n = state.shape[0]
    new_mode = _switch_modes(mode, cum, rng)
    out = np.empty_like(state)
    k_modes = signs.shape[0]
    table = np.empty((k_modes, 4))  # coefficients per mode for a shared turn rate
    for k in range(k_modes):
        table[k, 0], table[k, 1], table[k, 2], table[k, 3] = _turn_coefficients(
            signs[k] * rate[0], dt_s)
    for i in range(n):
        m = new_mode[i]
        if rate.shape[0] > 1:
            a, b, c, s = _turn_coefficients(signs[m] * rate[i], dt_s)
        else:
            a, b, c, s = table[m, 0], table[m, 1], table[m, 2], table[m, 3]
        _turn_and_accelerate(state, out, i, a, b, c, s, accel_std, dt_s, rng)
    return out, new_mode


def _per_row(value: float | FloatArray, lead: tuple[int, ...]) -> FloatArray:
    """A scalar as (1,), or an array broadcast to the states' leading shape, flattened."""
    if np.ndim(value) == 0:
        return np.array([float(value)])
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, np.float64), lead)).reshape(-1)


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
        out = _turn_step(_rows(state), _NO_TURN, self.accel_std_m_s2, dt_s, rng)
        return out.reshape(state.shape), mode

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
        lead = np.broadcast_shapes(state.shape[:-1], np.shape(self.turn_rate_rad_s))
        flat = _rows(np.broadcast_to(state, (*lead, 4)))
        out = _turn_step(flat, _per_row(self.turn_rate_rad_s, lead), self.accel_std_m_s2, dt_s,
                         rng)
        return out.reshape((*lead, 4)), mode

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
        flat = np.ascontiguousarray(mode, dtype=np.int8).reshape(-1)
        return _switch_modes(flat, cum, rng).reshape(np.shape(mode))

    def propagate(
        self, state: FloatArray, mode: ModeArray, dt_s: float, rng: np.random.Generator
    ) -> tuple[FloatArray, ModeArray]:
        lead = np.broadcast_shapes(state.shape[:-1], np.shape(mode),
                                   np.shape(self.turn_rate_rad_s))
        flat = _rows(np.broadcast_to(state, (*lead, 4)))
        modes = np.ascontiguousarray(np.broadcast_to(mode, lead), dtype=np.int8).reshape(-1)
        cum = _transition_for(self.transition, dt_s / self.switch_period_s)
        out, new_mode = _imm_step(flat, modes, cum, self._signs,
                                  _per_row(self.turn_rate_rad_s, lead), self.accel_std_m_s2,
                                  dt_s, rng)
        return out.reshape((*lead, 4)), new_mode.reshape(lead)

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


def predict_positions(model: MotionModel, state: FloatArray, mode: ModeArray, dt_s: float,
                      steps: int, rng: np.random.Generator) -> FloatArray:
    """Positions (steps, n, 2) after each of ``steps`` propagations of the n states (n, 4) by
    ``dt_s``: the planner's look-ahead. The same draws in the same order as calling
    ``propagate`` ``steps`` times, but one compiled call for the models of this module (numba
    spends ~5 us unboxing a Generator on every call: 20 calls a plan were 5 % of a batch's
    CPU). Other models are propagated step by step."""
    rows = _rows(state)
    if isinstance(model, RandomWalk):
        return _random_walk_path(rows, model.std_m_per_sqrt_s * math.sqrt(dt_s),
                                 model.std_m_per_sqrt_s > 0.0, steps, rng)
    if isinstance(model, ConstantVelocity):
        return _turn_path(rows, _NO_TURN, model.accel_std_m_s2, dt_s, steps, rng)
    if isinstance(model, ConstantTurnRate) and np.ndim(model.turn_rate_rad_s) == 0:
        return _turn_path(rows, np.array([float(model.turn_rate_rad_s)]), model.accel_std_m_s2,
                          dt_s, steps, rng)
    if isinstance(model, CvIft) and np.ndim(model.turn_rate_rad_s) == 0:
        cum = _transition_for(model.transition, dt_s / model.switch_period_s)
        modes = np.ascontiguousarray(mode, dtype=np.int8).reshape(-1)
        return _imm_path(rows, modes, cum, model._signs,
                         np.array([float(model.turn_rate_rad_s)]), model.accel_std_m_s2, dt_s,
                         steps, rng)
    out = np.empty((steps, rows.shape[0], 2))
    for k in range(steps):
        state, mode = model.propagate(state, mode, dt_s, rng)
        out[k] = _rows(state)[:, :2]
    return out


@kernel
def _random_walk_path(state: FloatArray, std: float, draw: bool, steps: int,
                      rng: np.random.Generator) -> FloatArray:
    """:func:`predict_positions` of :class:`RandomWalk` (draws as ``_random_walk_step``)."""
    n = state.shape[0]
    out = np.empty((steps, n, 2))
    x = state[:, 0].copy()
    y = state[:, 1].copy()
    for k in range(steps):
        for i in range(n):
            if draw:
                x[i] += std * rng.standard_normal()
                y[i] += std * rng.standard_normal()
            out[k, i, 0] = x[i]
            out[k, i, 1] = y[i]
    return out


@kernel
def _turn_path(state: FloatArray, omega: FloatArray, accel_std: float, dt_s: float, steps: int,
               rng: np.random.Generator) -> FloatArray:
    """:func:`predict_positions` at one turn rate ``omega`` (1,) (0: CV), as ``_turn_step``."""
    n = state.shape[0]
    out = np.empty((steps, n, 2))
    a, b, c, s = _turn_coefficients(omega[0], dt_s)
    cur = state.copy()
    nxt = np.empty_like(state)
    for k in range(steps):
        for i in range(n):
            _turn_and_accelerate(cur, nxt, i, a, b, c, s, accel_std, dt_s, rng)
            out[k, i, 0] = nxt[i, 0]
            out[k, i, 1] = nxt[i, 1]
        cur, nxt = nxt, cur
    return out


@kernel
def _imm_path(state: FloatArray, mode: ModeArray, cum: FloatArray, signs: FloatArray,
              rate: FloatArray, accel_std: float, dt_s: float, steps: int,
              rng: np.random.Generator) -> FloatArray:
    """:func:`predict_positions` of the IMM at one turn rate ``rate`` (1,), as ``_imm_step``."""
    n = state.shape[0]
    out = np.empty((steps, n, 2))
    k_modes = signs.shape[0]
    table = np.empty((k_modes, 4))
    for j in range(k_modes):
        table[j, 0], table[j, 1], table[j, 2], table[j, 3] = _turn_coefficients(
            signs[j] * rate[0], dt_s)
    cur = state.copy()
    nxt = np.empty_like(state)
    modes = mode.copy()
    for k in range(steps):
        modes = _switch_modes(modes, cum, rng)
        for i in range(n):
            m = modes[i]
            _turn_and_accelerate(cur, nxt, i, table[m, 0], table[m, 1], table[m, 2],
                                 table[m, 3], accel_std, dt_s, rng)
            out[k, i, 0] = nxt[i, 0]
            out[k, i, 1] = nxt[i, 1]
        cur, nxt = nxt, cur
    return out


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
