"""The planner's inner loop: roll every action forward over the look-ahead and sum the
discounted information gain (paper section 4, "Path planning", steps 1-4), with the detect/miss
outcome of every generated pulse weighed by its predicted probability.

Frame: local ENU metres about home (x east, y north, z up; tags on the ground at z = 0);
receiver yaw = the action's compass heading (0 = north, clockwise).

One look-ahead step k of one row (tag x action x rollout) with predicted weights w_i of the
particles x_i (B = the predicted belief, W = sum_i w_i), noiseless powers P_i = P(x_i, u_k),
and the generator's measurement z with its detection probability p (:mod:`core.generators`:
PIM pD at the mean state's noiseless power; MexGen the mean over its samples, exactly
sum w pD / W for the stratified sampler; MC-M its sampled outcome, 0 or 1, per rollout)::

    detected:  L+_i = pD(P_i) N(z; P_i, R)       B+ = w L+ / sum w L+
    missed:    L-_i = 1 - pD(P_i)                 B- = w L- / sum w L-
    value = sum_k discount^(k-1) r_k,  averaged over the rollouts

and r_k, B_k (the belief carried to step k + 1) by the planner's ``outcome`` rule:

- "pooled" (default): the reward of the expected outcome, as MexGen's z is the expected
  power. The Bernoulli likelihood evaluated at the expected indicator p::

      L_i = (pD(P_i) N(z; P_i, R))^p (1 - pD(P_i))^(1 - p),  B_k = w L / sum w L,
      r_k = Psi(B_k, B)

- "branches": the average over the two outcomes, and their mixture carried on::

      r_k = p Psi(B+, B) + (1 - p) Psi(B-, B),   B_k = p B+ + (1 - p) B-

  The mixture is the expected posterior over the outcome: the outcome alone carries nothing
  into it (with an uninformative z, p B+ + (1 - p) B- = w pD / W + w (1 - pD) / W = B when p =
  sum w pD / W, the martingale property of Bayes' rule), while the information of z is kept
  in proportion to the chance that there is a power to measure. Carrying both branches
  instead would double the rows every step (2^H); carrying one would assume its outcome.

Both are exactly today's single branch when p is 0 or 1 (pD = 1 everywhere, the paper's
sensor; or MC's sampled outcome), and Psi is the Renyi divergence (:mod:`core.reward`).

Why "pooled" is the default (issue 12). Before, the outcome was collapsed to the majority
(MexGen's samples, PIM's pD >= 0.5) and the update carried ``log pD`` as if the detection
were certain; near the edge of detection that term separated the particles more than the
signal strength and the planner flew away from far tags. "branches" takes the expectation
over the outcome exactly, but z is still the expected power, at which the signal-strength
information vanishes to first order (a likelihood centred on the predictive mean is flat
there; its gain is of order (sigma_P^2 / R)^2 against the true expected gain's sigma_P^2 /
R, sigma_P the belief's spread of powers). The enumerated detect/miss outcome keeps its
first-order information, so with MexGen or PIM it outweighed the signal strength ~100-fold
at 1.5-2 km and the planner still preferred the edge (measured: 0.06 of the best reward
towards a tag 1.7 km away, 0.45 even over a 180 s look-ahead, where MC-512 prefers towards).
Pooled, both parts are taken at their expectation and enter at the same (second) order; with
MC both are sampled (first order, unbiased). Pooled costs one table lookup and two passes per
step; "branches" a lookup, two dot products, five passes and a log.

"branches" in the linear domain: 1 - pD >= 1 - pd_max, so the missed weights cannot underflow,
and ``Psi(B-, B) = log(sum w m^a / (S^a W^(1-a))) / (a - 1)`` with m = 1 - pD, S = sum w m
needs two dot products against tabulated m and m^a; the mixture is formed linearly and its log
taken once. A miss that no particle can explain (pd_max = 1: every 1 - pD = 0) gets weight 0.

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
from functools import partial
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.generators import BeliefView, MeasurementGenerator
from mexgen_gcs.core.likelihood import (
    DetectionTable,
    bayes_update,
    likelihood_coefficients,
    log_likelihood,
    pooled_log_likelihood,
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
    pooled: bool = True,
) -> FloatArray:
    """Expected discounted information gain of each action for each tag, (T, A) float64.

    beliefs: T tags with the same particle count N; paths: (H, A, 2) vehicle east/north at
    the H look-ahead steps, ``step_s`` apart; headings_rad: (A,). ``pooled``: the outcome
    rule, "pooled" if True else "branches" (module docstring). Adds wall times to ``timing``
    (predict, measure, update, reward). Cost O(H T A R N) array work.
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
    lut_scratch = (ws.get("lut_f", grid_shape), ws.get("lut_i", grid_shape, np.intp))
    timing["predict"] += t1 - t0

    shape = (n_tags, n_act, n_roll, n_pad)
    log_w = ws.get("log_w", shape)  # max-shifted: normalised = log_w - log_total
    log_w[..., :n] = 0.0
    log_w[..., n:] = -np.inf
    log_total: FloatArray = np.full(shape[:-1], math.log(n))
    w = ws.get("w", shape)  # exp(log_w)
    w[..., :n] = 1.0
    w[..., n:] = 0.0
    log_w_next = ws.get("log_w_next", shape)
    w_next = ws.get("w_next", shape)
    scratch = ws.get("scratch", shape)
    miss_grid = (ws.get("miss", grid_shape[1:]), ws.get("miss_pow", grid_shape[1:]))
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
            # the table index stays in lut_scratch[1] for this chunk's miss lookups
            idx = table.index(power[:c], (lut_scratch[0][:c], lut_scratch[1][:c]),
                              bounded=True)
            table.take_log_pd(idx, out=log_pd[:c])
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
            mean_power=partial(_mean_power, radio, rx=rx_k, yaw=yaw, offset=offset,
                               exponent=exponent),
            detection_probability=radio.detection_probability,  # type: ignore[arg-type]
            noise_std_db=radio.noise_std_db,
            scratch=ws,
        )
        # 2. measure
        meas = generator.generate(view, rng)
        t3 = clock()
        # 3. update: log_w_next <- the log-likelihood of the generated outcome
        p_det = meas.p_detect
        q: Float32Array | None = None  # weight of the missed branch ("branches")
        if not _uncertain(p_det):
            # every pulse detected (p = 1), or MC's sampled outcomes (0 or 1): one branch
            log_likelihood(meas.z_db, p_det > 0.0, power[j], log_pd[j], table,
                           radio.noise_var, out=log_w_next,
                           coef=None if coef is None else coef[j])
        elif pooled:  # the likelihood of the expected outcome (pD N)^p (1 - pD)^(1 - p)
            gap = table.take_log_miss_gap(lut_scratch[1][j], out=miss_grid[0])
            pooled_log_likelihood(meas.z_db, p_det, power[j], log_pd[j], gap,
                                  radio.noise_var, log_w_next, scratch)
        else:  # "branches": the detected branch first, where detection is possible
            detected = p_det > 0.0
            log_likelihood(meas.z_db, detected, power[j], log_pd[j], table,
                           radio.noise_var, out=log_w_next)
            q = np.where(detected, np.float32(1.0) - p_det, np.float32(0.0))
            if not q.any():
                q = None
        # log_w_next <- posterior log-weights; the linear ones go to w, unless the missed
        # branch still needs the prior's (then to w_next)
        post = bayes_update(log_w, log_w_next, out_weights=w if q is None else w_next)
        t4 = clock()
        # 4. reward of that branch
        gain = renyi_gain(log_w_next, log_w, alpha, scratch, post.log_total, log_total)
        t5 = clock()
        log_total_next = post.log_total
        if q is not None:
            # the missed branch (see the module docstring); the carried belief -> w_next
            idx = lut_scratch[1][j]
            miss = table.take_miss(idx, out=miss_grid[0])
            miss_pow = table.take_miss_pow(idx, alpha, out=miss_grid[1])
            gain, log_total_next = _mix_missed_branch(
                q.astype(np.float64), gain, w, w_next, log_w_next, log_total,
                post.log_total, miss, miss_pow, alpha)
            w, w_next = w_next, w
        t6 = clock()
        value += discount**k * gain
        log_w, log_w_next, log_total = log_w_next, log_w, log_total_next
        t7 = clock()
        measure_s += t3 - t2
        update_s += (t4 - t3) + (t6 - t5)
        reward_s += (t5 - t4) + (t7 - t6)
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


def _mean_power(radio: RadioModel, pos: NDArray[np.floating], rx: NDArray[np.floating],
                yaw: NDArray[np.floating], offset: Float32Array | None,
                exponent: Float32Array | None) -> NDArray[np.floating]:
    """PIM's noiseless power at mean positions (T, A, R, 2) with the mean radio unknowns."""
    pos64, rx64 = np.asarray(pos, np.float64), np.asarray(rx, np.float64)
    yaw64 = np.asarray(yaw, np.float64)
    if offset is None and exponent is None:
        return radio.power_db(pos64, rx64, yaw64)
    log_term, gain = radio.geometry(pos64, rx64, yaw64)
    n = radio.path_loss_exponent if exponent is None else exponent.mean(axis=-1)
    b = 0.0 if offset is None else offset.mean(axis=-1)
    return radio.p0_db + b + n * log_term + gain


def _uncertain(p_detect: Float32Array) -> bool:
    """Whether any row's outcome is uncertain (0 < p < 1)."""
    return bool(np.any((p_detect > 0.0) & (p_detect < 1.0)))


def _mix_missed_branch(
    q: FloatArray,
    gain_det: FloatArray,
    w: Float32Array,
    w_det: Float32Array,
    log_w_det: Float32Array,
    log_total: FloatArray,
    log_total_det: FloatArray,
    miss: Float32Array,
    miss_pow: Float32Array,
    alpha: float,
) -> tuple[FloatArray, FloatArray]:
    """Add the missed branch with weight q = 1 - p (0 where the outcome is certain), in place.

    w: (B..., N) the predicted (prior) weights, row sums exp(log_total); w_det, log_w_det: the
    detected branch's posterior (max-shifted, row sums exp(log_total_det)); miss, miss_pow:
    1 - pD and (1 - pD)^alpha of every particle, (B'..., N) broadcasting to the rows. Returns
    the expected gain per row and the log row totals of the carried belief, which replaces
    w_det (linear) and log_w_det (log) with entries <= 1 (<= 0). Rows with q = 0 keep the
    detected branch. O(B N): two dot products, four passes and one log.
    """
    # missed-branch sums over the particles, in the linear domain: 1 - pD >= 1 - pd_max, so
    # nothing underflows unless pd_max = 1 (then those particles cannot be missed at all)
    s_miss = np.vecdot(w, miss, dtype=np.float32).astype(np.float64)
    a_miss = np.vecdot(w, miss_pow, dtype=np.float32).astype(np.float64)
    # a miss no particle can explain (every 1 - pD = 0) is impossible: weight 0
    q = np.where(s_miss > 0.0, q, 0.0)
    s_safe = np.where(q > 0.0, s_miss, 1.0)
    a_safe = np.where(q > 0.0, a_miss, 1.0)
    # Renyi(missed, prior) = log(sum w m^a / (S^a W^(1 - a))) / (a - 1)
    gain_miss = (np.log(a_safe) - alpha * np.log(s_safe) - (1.0 - alpha) * log_total) / (
        alpha - 1.0)
    gain_miss = np.where(q > 0.0, np.maximum(gain_miss, 0.0), 0.0)
    gain = (1.0 - q) * gain_det + q * gain_miss
    # carried belief: (1 - q) w_det / S_det + q w m / S_miss, scaled so its entries are <= 1
    c_det = (1.0 - q) * np.exp(-log_total_det)
    c_miss = q / s_safe
    scale = c_det + c_miss
    f_det = (c_det / scale).astype(np.float32)[..., None]
    f_miss = (c_miss / scale).astype(np.float32)[..., None]
    mixed = np.multiply(w, miss, out=log_w_det)  # log_w_det is free: reuse it as scratch
    mixed *= f_miss
    w_det *= f_det
    w_det += mixed
    with np.errstate(divide="ignore"):  # weights that underflowed to 0: -inf
        np.log(w_det, out=log_w_det)
    return gain, -np.log(scale)
