"""The planner's inner loop: roll every action forward over the look-ahead and sum the
discounted information gain (paper section 4, "Path planning", steps 1-4).

Frame: local ENU metres about home (x east, y north, z up; tags on the ground at z = 0);
receiver yaw = the action's compass heading (0 = north, clockwise).

Arrays are float32 with shapes (T, A, R, N'): tags x actions x rollouts x particles, where R is
the generator's number of rollouts (MC-M: M, otherwise 1) and N' is N padded to a multiple of
16 (the samplers' block size) with zero-weight copies of particle 0, which never influence a
result. The only Python loops are over look-ahead steps (and tags for the motion model).

Large arrays live in a :class:`~mexgen_gcs.core.workspace.Workspace` that a
:class:`~mexgen_gcs.core.planner.Planner` keeps between plans (that module says why). The
noiseless-power grid (:mod:`core.power_grid`) is evaluated in place for up to ``GRID_CHUNK``
values at a time, so its size in memory is bounded as well.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.generators import BeliefView, MeasurementGenerator
from mexgen_gcs.core.likelihood import (
    DetectionTable,
    bayes_update,
    likelihood_coefficients,
    log_likelihood,
)
from mexgen_gcs.core.motion import ModeArray, MotionModel
from mexgen_gcs.core.power_grid import power_grid
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reward import renyi_gain
from mexgen_gcs.core.workspace import Workspace

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

PAD = 16
"""The particle axis is padded to a multiple of this."""
GRID_CHUNK = 1 << 16
"""Most power-grid values (steps x tags x actions x particles) evaluated at once."""


class PlanningBelief(Protocol):
    """What the planner reads of a tag's planning belief (N equal-weight particles)."""

    @property
    def tag_id(self) -> str: ...
    @property
    def states(self) -> FloatArray: ...
    @property
    def modes(self) -> ModeArray: ...
    @property
    def motion(self) -> MotionModel: ...


def rollout_gains(
    beliefs: Sequence[PlanningBelief],
    paths: FloatArray,
    alt_m: float,
    headings_rad: FloatArray,
    radio: RadioModel,
    table: DetectionTable,
    generator: MeasurementGenerator,
    step_s: float,
    discount: float,
    alpha: float,
    rng: np.random.Generator,
    timing: dict[str, float],
    workspace: Workspace | None = None,
) -> FloatArray:
    """Expected discounted information gain of each action for each tag, (T, A) float64.

    beliefs: T tags with the same particle count N; paths: (H, A, 2) vehicle east/north at
    the H look-ahead steps; headings_rad: (A,). Adds wall times to ``timing`` (predict,
    measure, update, reward). Cost O(H T A R N) array work.
    """
    ws = workspace if workspace is not None else Workspace()
    clock = time.perf_counter
    n_tags, n = len(beliefs), int(beliefs[0].states.shape[0])
    n_pad = -(-n // PAD) * PAD
    steps, n_act = paths.shape[0], paths.shape[1]
    n_roll = generator.rollouts

    # 1. predict: tag motion does not depend on the action, so every step is propagated once
    #    for all actions and rollouts.
    t0 = clock()
    xy = ws.get("xy", (steps, n_tags, 1, 1, n_pad, 2))
    for i, b in enumerate(beliefs):
        state, mode = b.states, b.modes
        for k in range(steps):
            state, mode = b.motion.propagate(state, mode, step_s, rng)
            xy[k, i, 0, 0, :n] = state[:, :2]
    xy[..., n:, :] = xy[..., :1, :]
    offset, exponent = _radio_draws(beliefs, n, n_pad, radio)
    t1 = clock()

    rx = np.empty((steps, 1, n_act, 1, 3), dtype=np.float32)  # receiver pose per step, action
    rx[..., :2] = paths[:, None, :, None, :]
    rx[..., 2] = alt_m
    yaw = headings_rad.astype(np.float32)[None, :, None]  # (1, A, 1) against rows (T, A, R)
    yaw_grid = yaw[..., None]  # (1, A, 1, 1) against particles (T, A, 1, N')
    # The noiseless power of every particle from every action's pose (and what the update
    # derives from it) is evaluated for a chunk of steps at a time, into workspace buffers.
    chunk = max(1, GRID_CHUNK // (n_tags * n_act * n_pad))
    grid_shape = (min(chunk, steps), n_tags, n_act, 1, n_pad)
    power = ws.get("power", grid_shape)
    log_pd = ws.get("log_pd", grid_shape)
    # MC rollouts share each action's grid: their likelihoods are one matrix product each
    coef = ws.get("coef", (grid_shape[0], n_tags, n_act, 2, n_pad)) if n_roll > 1 else None
    grid_scratch = [ws.get(f"grid{j}", grid_shape) for j in range(3)]
    lut_scratch = (ws.get("lut_f", grid_shape), ws.get("lut_i", grid_shape, np.int32))
    timing["predict"] += t1 - t0

    shape = (n_tags, n_act, n_roll, n_pad)
    log_w = ws.get("log_w", shape)  # max-shifted: normalised = log_w - log_total
    log_w[..., :n] = 0.0
    log_w[..., n:] = -np.inf
    log_total: FloatArray | float = math.log(n)
    w = ws.get("w", shape)  # exp(log_w)
    w[..., :n] = 1.0
    w[..., n:] = 0.0
    log_w_next = ws.get("log_w_next", shape)
    scratch = ws.get("scratch", shape)
    value = np.zeros(shape[:-1])
    measure_s = update_s = reward_s = 0.0
    for k in range(steps):
        t2 = clock()
        j = k % chunk
        if j == 0:
            ks = slice(k, k + chunk)
            c = len(range(steps)[ks])
            power_grid(radio, xy[ks], rx[ks, ..., None, :], yaw_grid, power[:c],
                       [g[:c] for g in grid_scratch], offset, exponent)
            table.log_pd(power[:c], out=log_pd[:c], scratch=(lut_scratch[0][:c],
                                                              lut_scratch[1][:c]))
            if coef is not None:
                likelihood_coefficients(power[:c, ..., 0, :], log_pd[:c, ..., 0, :],
                                        radio.noise_var, out=coef[:c])
            t_grid = clock()
            update_s += t_grid - t2
            t2 = t_grid
        rx_k = rx[k]
        view = BeliefView(
            weights=w,
            positions_m=xy[k],
            power_db=power[j],
            log_pd=log_pd[j],
            mean_power=lambda p, rx_k=rx_k: _mean_power(radio, p, rx_k, yaw, offset, exponent),
            detection_probability=radio.detection_probability,
            noise_std_db=radio.noise_std_db,
            scratch=ws,
        )
        # 2. measure
        meas = generator.generate(view, rng)
        t3 = clock()
        # 3. update: log_w_next <- posterior log-weights, w <- posterior weights
        log_likelihood(meas.z_db, meas.detected, power[j], log_pd[j], table, radio.noise_var,
                       out=log_w_next, coef=None if coef is None else coef[j])
        post = bayes_update(log_w, log_w_next, out_weights=w)
        t4 = clock()
        # 4. reward
        value += discount**k * renyi_gain(log_w_next, log_w, alpha, scratch,
                                          post.log_total, log_total)
        log_w, log_w_next, log_total = log_w_next, log_w, post.log_total
        t5 = clock()
        measure_s += t3 - t2
        update_s += t4 - t3
        reward_s += t5 - t4
    timing["measure"] += measure_s
    timing["update"] += update_s
    timing["reward"] += reward_s
    return value.mean(axis=2)


def _radio_draws(beliefs: Sequence[PlanningBelief], n: int, n_pad: int, radio: RadioModel
                 ) -> tuple[Float32Array | None, Float32Array | None]:
    """Per-particle offsets and exponents of the beliefs as (T, 1, 1, N') float32 grids
    (None when no belief carries them)."""
    offs = [getattr(b, "offset_db", None) for b in beliefs]
    exps = [getattr(b, "exponent", None) for b in beliefs]
    out: list[Float32Array | None] = []
    for vals, default in ((offs, 0.0), (exps, radio.path_loss_exponent)):
        if all(v is None for v in vals):
            out.append(None)
            continue
        grid = np.full((len(beliefs), 1, 1, n_pad), default, dtype=np.float32)
        for i, v in enumerate(vals):
            if v is not None:
                grid[i, 0, 0, :n] = v
                grid[i, 0, 0, n:] = v[0]
        out.append(grid)
    return out[0], out[1]


def _mean_power(radio: RadioModel, pos: FloatArray, rx: FloatArray, yaw: FloatArray,
                offset: Float32Array | None, exponent: Float32Array | None) -> FloatArray:
    """PIM's noiseless power at mean positions (T, A, R, 2) with the mean radio unknowns."""
    if offset is None and exponent is None:
        return radio.power_db(pos, rx, yaw)
    log_term, gain = radio.geometry(pos, rx, yaw)
    n = radio.path_loss_exponent if exponent is None else exponent.mean(axis=-1)
    b = 0.0 if offset is None else offset.mean(axis=-1)
    return radio.p0_db + b + n * log_term + gain
