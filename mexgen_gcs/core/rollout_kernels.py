"""The compiled inner steps of the rollout planner (:mod:`core.rollout` has the equations).

Frame: local ENU metres (x east, y north, z up; tags on the ground at z = 0); receiver yaw
is a compass heading (0 = north, clockwise), as in :mod:`core.radio`.

Two kernels per look-ahead step, each one pass over every tag x action (x rollout) x particle
with nothing allocated:

- :func:`grid_step`: the noiseless power of every particle from every action's pose
  (:meth:`RadioModel.power_db`, in float32), its detection-table entry and ``log pD``;
- :func:`update_step`: the likelihood of the generated outcome, the Bayes update, the Renyi
  gain and its discounted sum, for the "pooled" and the "branches" outcome rules.

Before these were kernels the same arithmetic was ~40 numpy passes per step over arrays of a
few thousand values, and the cost of a plan was the cost of calling numpy, not of the
arithmetic (`mexgen-gcs bench planner`; the figures are in docs/experiments.md).

Weights are kept "max-shifted" (:mod:`core.likelihood`): a row of log-weights ``l`` with
maximum 0 stands for ``exp(l - log_total)``, ``log_total = log sum exp(l)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import LANES, exp32, inline, kernel, log32, max_lanes
from mexgen_gcs.core.radio import distance2_and_gain

Float32Array = NDArray[np.float32]
FloatArray = NDArray[np.float64]
Int32Array = NDArray[np.int32]

_F = np.float32
_INV_LN10 = 1.0 / math.log(10.0)


@inline
def _powers(x: Float32Array, y: Float32Array, ex: Any, ey: Any, dz2: Any, ks: Any, kc: Any,
            half_fb: Any, min2: Any, log10_d0: Any, p0: Any, c_slope: Any, c_const: Any,
            exponent: Float32Array, offset_db: Float32Array, t: int, out: Float32Array
            ) -> None:
    """Noiseless power (float32) of every particle (x, y) of tag t from the receiver at
    (ex, ey) with squared height dz2 and antenna terms ks, kc (float32 scalars): see
    :func:`grid_step`."""
    n = x.shape[0]
    if exponent.shape[0] > 0:  # p0 - 5 n_i (log10(d^2) - 2 log10(d0)) + gain
        for i in range(n):
            d2, gain = distance2_and_gain(x[i] - ex, y[i] - ey, dz2, min2, ks, kc, half_fb)
            l10 = log32(d2) * _F(_INV_LN10)  # log10(distance^2)
            out[i] = (l10 - _F(2.0) * log10_d0) * (_F(-5.0) * exponent[t, i]) + p0 + gain
    else:
        for i in range(n):
            d2, gain = distance2_and_gain(x[i] - ex, y[i] - ey, dz2, min2, ks, kc, half_fb)
            l10 = log32(d2) * _F(_INV_LN10)  # log10(distance^2)
            out[i] = l10 * c_slope + c_const + gain
    if offset_db.shape[0] > 0:
        for i in range(n):
            out[i] += offset_db[t, i]


@kernel
def grid_step(
    xy: Float32Array,
    rx: Float32Array,
    yaw_rad: Float32Array,
    offset_db: Float32Array,
    exponent: Float32Array,
    params: FloatArray,
    table_log_pd: Float32Array,
    nb_c: Float32Array,
    nb_xy: Float32Array,
    power: Float32Array,
    log_pd: Float32Array,
    index: Int32Array,
    nb_power: Float32Array,
) -> None:
    """Noiseless power, table entry and log pD of every particle from every pose, in place.

    xy: (T, 2, N) particle east (row 0) and north (row 1); rx: (A, 3) receiver
    east/north/up; yaw_rad: (A,); offset_db, exponent: (T, N) per-particle power offset
    (added to P0) and path-loss exponent (replacing the model's), or empty (0, 0) arrays
    for the model's; params: :func:`grid_params`; table_log_pd: the detection table's
    log pD. Writes power, log_pd, index: (T, A, N). nb_c (T, A) and nb_xy (T, A, 2), or
    empty: the shadowing neighbours' weight and centroid of each tag's pulse from each pose
    (:class:`core.radio_belief.PulseNoise`); where nb_c != 0 nb_power (T, A, N) receives the
    power from the centroid (same height and heading).
    """
    n_tags = xy.shape[0]
    p0, n_model, log10_d0, half_fb, min2 = (_F(params[0]), _F(params[1]), _F(params[2]),
                                            _F(params[3]), _F(params[4]))
    inv_step, tab_offset = _F(params[5]), _F(params[6])
    last = np.int32(table_log_pd.shape[0] - 1)
    c_const = p0 + _F(10.0) * n_model * log10_d0
    c_slope = _F(-5.0) * n_model
    for t in range(n_tags):
        x, y = xy[t, 0], xy[t, 1]
        for a in range(rx.shape[0]):
            dz2 = rx[a, 2] * rx[a, 2]
            ks, kc = half_fb * _F(math.sin(yaw_rad[a])), half_fb * _F(math.cos(yaw_rad[a]))
            pw, ix, lp = power[t, a], index[t, a], log_pd[t, a]
            # simple loops, each of which LLVM vectorises, rather than one that it does not
            # (the table lookup is a gather)
            _powers(x, y, rx[a, 0], rx[a, 1], dz2, ks, kc, half_fb, min2, log10_d0, p0,
                    c_slope, c_const, exponent, offset_db, t, pw)
            for i in range(x.shape[0]):
                ix[i] = min(max(np.int32(pw[i] * inv_step + tab_offset), np.int32(0)), last)
            for i in range(x.shape[0]):
                lp[i] = table_log_pd[ix[i]]
            if nb_c.shape[0] > 0 and nb_c[t, a] != _F(0.0):
                _powers(x, y, nb_xy[t, a, 0], nb_xy[t, a, 1], dz2, ks, kc, half_fb, min2,
                        log10_d0, p0, c_slope, c_const, exponent, offset_db, t, nb_power[t, a])


def grid_params(p0_db: float, path_loss_exponent: float, d0_m: float, front_back_db: float,
                min_distance_m: float, table_inv_step: float, table_offset: float
                ) -> FloatArray:
    """The scalar parameters :func:`grid_step` reads, in its order."""
    return np.array([p0_db, path_loss_exponent, math.log10(d0_m), 0.5 * front_back_db,
                     min_distance_m**2, table_inv_step, table_offset])


@kernel
def update_step(
    power: Float32Array,
    log_pd: Float32Array,
    index: Int32Array,
    z_db: Float32Array,
    p_detect: Float32Array,
    log_w: Float32Array,
    w: Float32Array,
    log_total: FloatArray,
    tables: Float32Array,
    inv_2r: FloatArray,
    nb_c: Float32Array,
    nb_power: Float32Array,
    alpha: float,
    pooled: bool,
    discount_k: float,
    out_log_w: Float32Array,
    out_w: Float32Array,
    out_log_total: FloatArray,
    value: FloatArray,
) -> None:
    """One look-ahead step's update and reward for every row, in place.

    power, log_pd, index: (T, A, N) from :func:`grid_step`, shared by the R rollouts of an
    action; z_db, p_detect: (T, A, R) the generated measurement and its detection
    probability; log_w, w, log_total: (T, A, R, N), (T, A, R, N), (T, A, R) the predicted
    belief (max-shifted, see the module); tables: (3, K) the detection table's log(1 - pD) -
    log pD, 1 - pD and (1 - pD)^alpha; inv_2r (T, A) = 1 / (2 R), R the noise of a pulse from
    the row's pose; nb_c (T, A) and nb_power (T, A, N) from :func:`grid_step`, or empty: where
    nb_c != 0 the likelihood is of the pulse conditioned on the shadowing neighbours, the
    particle's power less nb_c x its power from their centroid against z less nb_c x that
    power's mean under the row's predicted weights. Writes the carried belief to
    out_log_w, out_w, out_log_total and adds ``discount_k`` x the row's gain to value (T, A,
    R). ``pooled``: the outcome rule (core.rollout). A row whose outcome nothing explains
    (every likelihood -inf or NaN) keeps its prior. Entries with zero weight stay zero.
    """
    n_tags, n_act, n_roll, n = log_w.shape
    a32 = _F(alpha)
    b32 = _F(1.0 - alpha)
    lanes = np.empty(LANES, np.float32)
    for t in range(n_tags):
        for a in range(n_act):
            k32 = _F(inv_2r[t, a])
            for r in range(n_roll):
                z = _F(z_db[t, a, r])
                p = _F(p_detect[t, a, r])
                # the detected branch's likelihood is the pooled one at p_lik, and q is the
                # weight of the missed branch ("branches" only)
                if pooled or p <= _F(0.0):
                    p_lik, q = p, 0.0
                else:
                    p_lik, q = _F(1.0), 1.0 - float(p)
                c_quad = -p_lik * k32
                c_gap = _F(1.0) - p_lik
                lw, ow, e = log_w[t, a, r], out_log_w[t, a, r], out_w[t, a, r]
                pw, lp, ix = power[t, a], log_pd[t, a], index[t, a]
                c_nb = nb_c[t, a] if nb_c.shape[0] > 0 else _F(0.0)
                if c_nb != _F(0.0):  # conditioned on the neighbours: z~ - P~ = z - P - c (Q - q)
                    qn = nb_power[t, a]
                    wn = w[t, a, r]
                    sq = _F(0.0)
                    sw = _F(0.0)
                    for i in range(n):
                        sq += wn[i] * qn[i]
                        sw += wn[i]
                    z = z - c_nb * (sq / sw)
                    if c_gap != _F(0.0):
                        for i in range(n):
                            d = z - (pw[i] - c_nb * qn[i])
                            ow[i] = lp[i] + c_quad * d * d + lw[i] + c_gap * tables[0, ix[i]]
                    else:
                        for i in range(n):
                            d = z - (pw[i] - c_nb * qn[i])
                            ow[i] = lp[i] + c_quad * d * d + lw[i]
                elif c_gap != _F(0.0):
                    for i in range(n):
                        d = z - pw[i]
                        ow[i] = lp[i] + c_quad * d * d + lw[i] + c_gap * tables[0, ix[i]]
                else:
                    for i in range(n):
                        d = z - pw[i]
                        ow[i] = lp[i] + c_quad * d * d + lw[i]
                m = max_lanes(ow, lanes)
                if not math.isfinite(m):  # nothing explains it: keep the prior
                    for i in range(n):
                        ow[i] = lw[i]
                    m = _F(0.0)
                # float32 sums, as numpy's were: the lanes of a vectorised sum are partial
                # sums, so the error is ~1e-6 relative at N = 20000
                total = _F(0.0)
                mix = _F(0.0)
                for i in range(n):
                    v = ow[i] - m
                    ow[i] = v
                    ei = exp32(v)
                    e[i] = ei
                    total += ei
                    mix += exp32(a32 * v + b32 * lw[i])
                log_total_det = math.log(total)
                log_prior = log_total[t, a, r]
                if mix < _F(1e-30) or alpha > 1.0:  # underflow, or a positive exponent: exactly
                    # over the entries of nonzero posterior weight only: a zero-weight entry
                    # (the padding, an impossible particle) adds nothing, and for alpha > 1
                    # its term would be alpha (-inf) + (1 - alpha) (-inf) = -inf + inf = NaN
                    mix_max = -np.inf
                    for i in range(n):
                        if ow[i] > -np.inf:
                            mix_max = max(mix_max, alpha * ow[i] + (1.0 - alpha) * lw[i])
                    s = 0.0
                    for i in range(n):
                        if ow[i] > -np.inf:
                            s += math.exp(alpha * ow[i] + (1.0 - alpha) * lw[i] - mix_max)
                    log_mix = math.log(s) + mix_max
                else:
                    log_mix = math.log(mix)
                gain = max((log_mix - alpha * log_total_det - (1.0 - alpha) * log_prior)
                           / (alpha - 1.0), 0.0)
                log_total_next = log_total_det
                if q > 0.0:
                    s_miss = 0.0
                    a_miss = 0.0
                    wp = w[t, a, r]
                    for i in range(n):
                        j = index[t, a, i]
                        s_miss += wp[i] * tables[1, j]
                        a_miss += wp[i] * tables[2, j]
                    if s_miss > 0.0:  # else a miss no particle can explain: weight 0
                        gain_miss = max((math.log(a_miss) - alpha * math.log(s_miss)
                                         - (1.0 - alpha) * log_prior) / (alpha - 1.0), 0.0)
                        gain = (1.0 - q) * gain + q * gain_miss
                        # carried belief (1 - q) w_det / S_det + q w m / S_miss, entries <= 1
                        c_det = (1.0 - q) * math.exp(-log_total_det)
                        c_miss = q / s_miss
                        scale = c_det + c_miss
                        f_det, f_miss = _F(c_det / scale), _F(c_miss / scale)
                        for i in range(n):
                            v = e[i] * f_det + wp[i] * tables[1, index[t, a, i]] * f_miss
                            e[i] = v
                            ow[i] = math.log(v) if v > _F(0.0) else -np.inf
                        log_total_next = -math.log(scale)
                out_log_total[t, a, r] = log_total_next
                value[t, a, r] += discount_k * gain
