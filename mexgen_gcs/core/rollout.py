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

R is the receiver noise, or, when the tag's filter is uncertain about the radio, what a pulse
from that pose would tell it, per step, tag and action: each particle predicts with its mean
offset and exponent, and their uncertainty at the belief's mean position is noise; the pulse
is conditioned on the shadowing the filter has heard (:class:`core.radio_belief.PulseNoise`:
P_i becomes P(x_i, u) - c P(x_i, u_c), z less c times that power's mean, R becomes r^2): a
pulse where the filter has listened tells little, so the planner looks for new places
instead of circling where the power is already known.

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
result. Particle positions are stored (steps, T, 2, N'), east and north as rows, so that the
compiled loops read them contiguously. Each look-ahead step is two compiled passes
(:mod:`core.rollout_kernels`: the power grid; the update with its gain) around the generator;
the only Python loops are over look-ahead steps (and tags for the motion model).

Large arrays live in a :class:`~mexgen_gcs.core.workspace.Workspace` that a
:class:`~mexgen_gcs.core.planner.Planner` keeps between plans (that module says why).
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
from mexgen_gcs.core.likelihood import DetectionTable
from mexgen_gcs.core.motion import ModeArray, MotionModel, predict_positions
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.rollout_kernels import grid_params, grid_step, update_step
from mexgen_gcs.core.workspace import Workspace

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

PAD = 16
"""The particle axis is padded to a multiple of this."""


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
    alt_m: float | FloatArray,
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
    the H look-ahead steps, ``step_s`` apart; alt_m: the vehicle's altitude, one for every
    step and action or (H, A); headings_rad: (A,). ``pooled``: the outcome
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
    xy = ws.get("xy", (steps, n_tags, 2, n_pad))  # east, north rows: the kernels vectorise
    for i, b in enumerate(beliefs):
        path = predict_positions(b.motion, b.states, b.modes, step_s, steps, rng)  # (H, N, 2)
        xy[:, i, :, :n] = path.transpose(0, 2, 1)
    xy[..., n:] = xy[..., :1]
    offset, exponent = _radio_draws(beliefs, n, n_pad, radio)
    t1 = clock()

    rx = np.empty((steps, n_act, 3), dtype=np.float32)  # receiver pose per step, action
    rx[..., :2] = paths
    rx[..., 2] = alt_m
    yaw = headings_rad.astype(np.float32)
    yaw_rows = yaw[None, :, None]  # (1, A, 1) against rows (T, A, R)
    none = np.zeros((0, 0), np.float32)
    params = grid_params(radio.p0_db, radio.path_loss_exponent, radio.d0_m, radio.front_back_db,
                         radio.min_distance_m, table.inv_step, table.offset)
    tables = table.arrays(alpha)
    grid_shape = (n_tags, n_act, n_pad)
    power = ws.get("power", grid_shape)
    log_pd = ws.get("log_pd", grid_shape)
    index = ws.get("index", grid_shape, np.int32)
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
    log_total_next: FloatArray = np.empty(shape[:-1])
    value = np.zeros(shape[:-1])
    offset_grid = none if offset is None else offset.reshape(n_tags, n_pad)
    exponent_grid = none if exponent is None else exponent.reshape(n_tags, n_pad)
    inv_2r, nb_c, nb_xy = _pulse_noise(beliefs, paths, alt_m, radio)
    nb_power = ws.get("nb_power", grid_shape) if nb_c.size else none[None]
    measure_s = update_s = reward_s = 0.0
    for k in range(steps):
        t2 = clock()
        grid_step(xy[k], rx[k], yaw, offset_grid, exponent_grid, params, tables.log_pd,
                  nb_c[k] if nb_c.size else none, nb_xy[k] if nb_c.size else none[None],
                  power, log_pd, index, nb_power)
        t3 = clock()
        view = BeliefView(
            weights=w,
            positions_m=xy[k].transpose(0, 2, 1)[:, None, None],
            power_db=power[:, :, None, :],
            log_pd=log_pd[:, :, None, :],
            mean_power=partial(_mean_power, radio, rx=rx[k][None, :, None, :], yaw=yaw_rows,
                               offset=offset, exponent=exponent),
            detection_probability=radio.detection_probability,  # type: ignore[arg-type]
            noise_std_db=radio.noise_std_db,
            scratch=ws,
        )
        # 2. measure
        meas = generator.generate(view, rng)
        t4 = clock()
        # 3. update and 4. reward (core.rollout_kernels)
        update_step(power, log_pd, index, meas.z_db, meas.p_detect, log_w, w, log_total,
                    tables.update, inv_2r[k], nb_c[k] if nb_c.size else none, nb_power, alpha,
                    pooled, discount**k, log_w_next, w_next,
                    log_total_next, value)
        log_w, log_w_next = log_w_next, log_w
        w, w_next = w_next, w
        log_total, log_total_next = log_total_next, log_total
        t5 = clock()
        update_s += t3 - t2
        measure_s += t4 - t3
        reward_s += t5 - t4
    timing["measure"] += measure_s
    timing["update"] += update_s
    timing["reward"] += reward_s
    return value.mean(axis=2)


def _pulse_noise(beliefs: Sequence[PlanningBelief], paths: FloatArray,
                 alt_m: float | FloatArray, radio: RadioModel
                 ) -> tuple[FloatArray, Float32Array, Float32Array]:
    """Per look-ahead step, tag and action: 1 / (2 R) (H, T, A), and the shadowing
    neighbours' weight (H, T, A) and centroid (H, T, A, 2) (:class:`core.radio_belief.
    PulseNoise`; the last two empty when no tag's filter has a shadowing memory). R is the
    receiver noise, or the variance of a pulse there given the neighbours, plus the
    uncertainty of the belief's offset and exponent (``radio_cov``) at its mean position."""
    steps, n_act = paths.shape[:2]
    var = np.full((steps, len(beliefs), n_act), radio.noise_var)
    noises = [getattr(b, "noise", None) for b in beliefs]
    conditioned = any(x is not None for x in noises)
    nb_c = np.zeros((steps, len(beliefs), n_act) if conditioned else (0, 0, 0), np.float32)
    nb_xy = np.zeros((*nb_c.shape, 2), np.float32)
    for i, (b, noise) in enumerate(zip(beliefs, noises, strict=True)):
        if noise is not None:
            r2, c, centre = noise.conditioning(paths)
            var[:, i] = r2
            nb_c[:, i] = c
            nb_xy[:, i] = centre
        cov = getattr(b, "radio_cov", None)
        if cov is not None:
            alt = np.broadcast_to(np.asarray(alt_m, dtype=np.float64), paths.shape[:2])
            rx = np.concatenate([paths, alt[..., None]], axis=-1)
            log_term, _ = radio.geometry(np.asarray(b.states)[:, :2].mean(axis=0), rx, 0.0)
            var[:, i] += np.maximum(cov[0] + 2.0 * cov[1] * log_term + cov[2] * log_term**2, 0.0)
    return 0.5 / var, nb_c, nb_xy


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
