"""Compiled kernels of the particle Bernoulli filter's update: power, likelihood, weights.

Frame: local ENU metres about home (x east, y north, z up; tags on the ground at z = 0);
powers in dB; headings are compass headings in radians (0 = north, clockwise), as in
:mod:`core.radio`. Particle states are ``(N, 4)`` ``[x, y, vx, vy]``; log-weights ``(N,)``.

The model's equations are written once, as scalar helpers inlined into the kernels (the
equations themselves are documented in :mod:`core.radio`, :mod:`core.radio_belief` and
:mod:`core.bernoulli`):

- :func:`geometry`: the exponent's regressor ``l = -10 log10(max(d, d_min) / d0)`` and the
  antenna gain ``g`` of :meth:`RadioModel.geometry`;
- :func:`detection`: ``pD = pd_max Phi((m - s) / w)`` and ``1 - pD``, each to full relative
  precision in its small tail (one ``erfc`` per particle);
- :func:`inlier_density` and :func:`likelihood`: the outlier-mixture density of a detected
  power and the Bernoulli likelihood ``L = 1 - pD + pD sum_z g(z) / kappa``;
- :func:`miss_moments`: what a missed pulse says about the power a particle's Gaussian over
  (b, n) explains (a moment-matched probit step);
- :func:`correlated_miss`: a miss given the earlier misses that share its shadowing.

``L >= 1 - pd_max >= 1e-12`` always, so it is computed as a probability (no log-sum-exp) and
only its log enters the log-weights; no particle's weight ever underflows to a NaN.

The kernels loop over particles once per update with no per-step array temporaries: the
classic filter's whole update (:func:`classic_update`) and the robust filter's
(:func:`robust_update`: marginal and prewhitened predictions, likelihood, one weighted
Kalman step per detection, or a probit step for a miss) each end by updating and
normalising the log-weights in place.
Cost O(N (1 + m) + N J) for m shadowing neighbours and J detections.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import LANES, exp64, inline, kernel, log64, max_lanes
from mexgen_gcs.core.radio import RadioModel, distance2_and_gain

FloatArray = NDArray[np.float64]
LevelArray = NDArray[np.int8]

_SQRT1_2 = math.sqrt(0.5)
_MINUS_10_OVER_LN10 = -10.0 / math.log(10.0)
CERTAIN_X = 12.0
"""Standard scores above which detection is certain in float64: log Phi(12) = -2e-33 and
Phi(-12) = 2e-33, negligible beside the miss floor 1 - pd_max >= 1e-12."""
_MIN_KAPPA = 1e-300


class RadioParams(NamedTuple):
    """The radio model and the estimator's outlier model as the kernels take them."""

    p0_db: float
    d0_m: float
    path_loss_exponent: float
    min_distance2_m2: float
    front_back_db: float
    sensitivity_db: float
    detection_spread2_db2: float
    pd_max: float
    miss_floor: float
    """1 - pd_max, kept >= 1e-12 (a pulse is never certainly detected)."""
    inv_kappa: float
    """1 / the clutter intensity per dB."""
    inlier: float
    """1 - eps, eps the outlier probability of a detected power."""
    outlier_density: float
    """eps / clutter range, per dB."""
    noise_var: float


def radio_params(radio: RadioModel, outlier_prob: float = 0.0) -> RadioParams:
    """The kernels' view of ``radio`` with outlier probability ``outlier_prob`` (eps)."""
    pd_max = min(radio.pd_max, 1.0 - 1e-12)
    width = radio.clutter_max_db - radio.clutter_min_db
    return RadioParams(
        p0_db=radio.p0_db, d0_m=radio.d0_m, path_loss_exponent=radio.path_loss_exponent,
        min_distance2_m2=radio.min_distance_m**2, front_back_db=radio.front_back_db,
        sensitivity_db=radio.sensitivity_db,
        detection_spread2_db2=radio.detection_spread_db**2, pd_max=radio.pd_max,
        miss_floor=1.0 - pd_max, inv_kappa=1.0 / max(radio.clutter_density, _MIN_KAPPA),
        inlier=1.0 - outlier_prob, outlier_density=outlier_prob / width,
        noise_var=radio.noise_var,
    )


# -- scalar model equations (inlined) ---------------------------------------------------------

@inline
def geometry(px: float, py: float, rx: float, ry: float, rz: float, sin_yaw: float,
             cos_yaw: float, p: RadioParams) -> tuple[float, float]:
    """(l, g) of a tag at (px, py, 0) seen from (rx, ry, rz) with heading yaw: the exponent's
    regressor ``-10 log10(max(d, d_min) / d0)`` and the antenna gain, dB."""
    half_fb = 0.5 * p.front_back_db
    d2, gain = distance2_and_gain(px - rx, py - ry, rz * rz, p.min_distance2_m2,
                                  half_fb * sin_yaw, half_fb * cos_yaw, half_fb)
    return 0.5 * _MINUS_10_OVER_LN10 * log64(d2 / (p.d0_m * p.d0_m)), gain


@inline
def detection(mean_db: float, var_db2: float, p: RadioParams) -> tuple[float, float]:
    """(pD, 1 - pD) of a predicted power N(mean_db, var_db2): pD = pd_max Phi(x) with
    x = (mean - sensitivity) / sqrt(spread^2 + var), each to full relative precision in
    both tails (one erfc). 1 - pD >= 1 - pd_max >= 1e-12: a pulse is never certain."""
    x = (mean_db - p.sensitivity_db) / np.sqrt(p.detection_spread2_db2 + var_db2)
    if x >= CERTAIN_X:
        return p.pd_max, p.miss_floor
    if x >= 0.0:
        q = 0.5 * math.erfc(x * _SQRT1_2)  # Phi(-x)
        # 1 - pd_max Phi(x) = (1 - pd_max) + pd_max Phi(-x): no cancellation
        return p.pd_max * (1.0 - q), p.miss_floor + p.pd_max * q
    pd = p.pd_max * 0.5 * math.erfc(-x * _SQRT1_2)
    return pd, 1.0 - pd


@inline
def miss_moments(mean_db: float, q_db2: float, rest_db2: float, miss: float, p: RadioParams
                 ) -> tuple[float, float]:
    """A missed pulse as evidence about a Gaussian part of the predicted power: the received
    power is u + r, u ~ N(mean_db, q_db2) the part a particle's Gaussian over (b, n) explains
    and r ~ N(0, rest_db2) the rest (shadowing, model error), and the pulse was missed with
    probability ``miss`` = (1 - pd_max) + pd_max Phi(-(mean - s) / sqrt(w^2 + rest + q)).
    The moment-matched posterior of u is a mixture of the prior (the pulse lost anyway,
    weight a = (1 - pd_max) / miss) and the prior times the probit Phi(-(u - s) / sqrt(w^2 +
    rest)) (the power below the threshold). Returns (shift of u's mean / q, change of its
    variance / q^2): what the Kalman form needs, with no division by a small q.
    Misses are most pulses where detection is uncertain: without this each miss would be
    scored against the same prior of (b, n) and a weak tag read as far
    (docs/results/localisation.md)."""
    d2 = p.detection_spread2_db2 + rest_db2 + q_db2
    d = np.sqrt(d2)
    x = (mean_db - p.sensitivity_db) / d
    if x <= -CERTAIN_X or q_db2 <= 0.0:
        return 0.0, 0.0  # the pulse could not have been detected, or nothing is unknown
    if x < 25.0:
        lam = exp64(-0.5 * x * x) / (math.sqrt(2.0 * math.pi) * 0.5 * math.erfc(x * _SQRT1_2))
    else:
        lam = x + 1.0 / x  # phi(x) / Phi(-x), asymptotically
    a = min(p.miss_floor / miss, 1.0)
    b = 1.0 - a
    # the probit part: shift -q lam / d, variance q - q^2 lam (lam - x) / d^2; then the mixture
    # (whose variance exceeds q when a pulse that should have been heard was lost: bimodal)
    return -b * lam / d, b * lam * (a * lam - (lam - x)) / d2


_FLAT_X = 8.5
"""Beyond this many sigma Phi is 1 or 0 in float64 (Phi(-8.5) = 1e-17): a(s) is flat."""
_GH_X, _GH_W = np.polynomial.hermite.hermgauss(16)
GH_NODES = np.sqrt(2.0) * _GH_X
"""Gauss-Hermite nodes and weights for E over s ~ N(0, 1): s = sqrt(2) x, w / sqrt(pi)."""
GH_WEIGHTS = _GH_W / math.sqrt(math.pi)
_GH_CUM = np.cumsum(GH_WEIGHTS)
"""The weight of the nodes up to and including each (the nodes ascend)."""
_MISS_RTOL = 1e-4
"""A correlated miss whose bound is within this share of the marginal one is the marginal."""
_PHI_H = 1.0 / 32.0
_PHI_X = np.arange(-_FLAT_X, _FLAT_X + 0.5 * _PHI_H, _PHI_H)
_PHI_TAB = np.array([0.5 * math.erfc(x * _SQRT1_2) for x in _PHI_X])
_PHI_DTAB = -np.exp(-0.5 * _PHI_X**2) / math.sqrt(2.0 * math.pi) * _PHI_H
"""Phi(-x) on a grid of 1/32 over +-8.5 and its slope per cell, for cubic Hermite
interpolation (:func:`phi_upper`): within 1.4e-9 of erfc, four times cheaper."""


@inline
def phi_upper(x: float) -> float:
    """Phi(-x) by cubic Hermite interpolation of a table (absolute error < 1.4e-9; beyond
    +-8.5 the value at +-8.5, 1 and 1e-17): the quadrature's nodes, where an erfc each cost
    four times as much. Clamped, not branched, so that a loop over nodes vectorises."""
    u = min(max((x + _FLAT_X) * (1.0 / _PHI_H), 0.0), _PHI_TAB.shape[0] - 1.0000001)
    i = int(u)
    t = u - i
    t2 = t * t
    t3 = t2 * t
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * _PHI_TAB[i] + (t3 - 2.0 * t2 + t) * _PHI_DTAB[i]
            + (3.0 * t2 - 2.0 * t3) * _PHI_TAB[i + 1] + (t3 - t2) * _PHI_DTAB[i + 1])


@inline
def correlated_miss(pred_db: float, vp_db2: float, shadow_db2: float, k: float, miss: float,
                    p: RadioParams) -> float:
    """P(miss | k earlier misses that share its shadowing): E[a(s)^(k+1)] / E[a(s)^k] over
    the shadowing s ~ N(0, shadow_db2), a(s) = 1 - pd_max Phi((pred + s - sens) /
    sqrt(spread^2 + vp - shadow)) the miss probability given s (Gauss-Hermite, 16 nodes).

    k = 0 is the marginal miss 1 - pD. As k grows, a particle whose power is near the
    threshold is no longer punished by every miss in one shadowed patch: the first misses
    say the patch is weak, and the next ones repeat it. A particle that should have heard
    the pulse whatever the shadowing still pays 1 - pd_max for each (those losses are
    independent). k is a count weighted by correlation, so this treats the earlier misses as
    if at this pulse's shadowing and geometry: an approximation of the censored Gaussian
    field, measured in docs/results/localisation.md.

    The answer is a mean of the nodes' a under weights tilted towards large a, so it lies
    between the untilted mean and the largest a. ``miss`` (the marginal 1 - pD) is returned
    where that bound says they agree within 1e-4 (the pulse inaudible, or audible, whatever
    the shadowing: most particles, most pulses)."""
    tau = np.sqrt(p.detection_spread2_db2 + max(vp_db2 - shadow_db2, 0.0))
    sd = np.sqrt(shadow_db2)
    nq = GH_NODES.shape[0]
    x0 = (pred_db - p.sensitivity_db) / tau
    step = sd / tau
    # a(s) falls as s grows and the nodes ascend: the first node's a is the largest
    a_top = p.miss_floor + p.pd_max * phi_upper(x0 + step * GH_NODES[0])
    if a_top <= miss * (1.0 + _MISS_RTOL):
        return miss  # inaudible (or flat) whatever the shadowing
    # audible but for a deep fade: the nodes S where a exceeds the floor f by more than the
    # tolerance are the first few, of weight W; tilted by at most (a_top / f)^k they lift
    # the mean above f (1 + tol) by at most W (a_top / f)^k (a_top - f)
    f = p.miss_floor
    q = 1
    while q < nq and p.pd_max * phi_upper(x0 + step * GH_NODES[q]) > _MISS_RTOL * f:
        q += 1
    if q < nq and (math.log(_GH_CUM[q - 1]) + k * math.log(a_top / f) + math.log(a_top - f)
                   <= math.log(_MISS_RTOL * miss)):
        return miss
    log_a0 = math.log(a_top)
    num = 0.0
    den = 0.0
    for q in range(nq):
        a = p.miss_floor + p.pd_max * phi_upper(x0 + step * GH_NODES[q])
        ak = exp64(k * (log64(a) - log_a0))  # a^k / a_top^k <= 1: no overflow
        num += GH_WEIGHTS[q] * ak * a
        den += GH_WEIGHTS[q] * ak
    return min(max(num / den, p.miss_floor), 1.0)


@inline
def inlier_density(e_db: float, s_db2: float, p: RadioParams) -> float:
    """(1 - eps) N(e; 0, s): the inlier part of the density of a detected power with
    innovation ``e_db`` and innovation variance ``s_db2`` (0 beyond 37 sigma: no subnormals)."""
    return p.inlier * exp64(-0.5 * e_db * e_db / s_db2) / np.sqrt(2.0 * math.pi * s_db2)


@inline
def likelihood(pd: float, miss: float, g_det: FloatArray, share: FloatArray, p: RadioParams
               ) -> float:
    """L = 1 - pD + sum_z (g_det(z) + pD eps U(clutter range)) / kappa from ``g_det`` (J,),
    each detection's joint density of being detected and reading its power as the tag's
    inlier (pD (1 - eps) N(z) in the classic model, pD(z) (1 - eps) N(z) in the robust one);
    ``share`` (J,) receives each detection's probability of being this particle's inlier,
    g_det(z) / (kappa L). L >= 1e-12."""
    nz = g_det.shape[0]
    total = miss
    for j in range(nz):
        g_det[j] *= p.inv_kappa
        total += g_det[j] + pd * p.outlier_density * p.inv_kappa
    for j in range(nz):
        share[j] = g_det[j] / total
    return total


@inline
def _reweight_levels(log_w: FloatArray, lik: FloatArray, s1: FloatArray, s2: FloatArray
                     ) -> float:
    """Bayes' rule on normalised log-weights in place, ``log_w <- log_w + log lik - log
    total`` (lik (N,) > 0 is overwritten), unless the total is not finite (then log_w is left
    as it was). Returns the log total, the log of the weighted mean likelihood; ``s1``, ``s2``
    (L,) receive sum w and sum w^2 (w scaled by a common factor) of each roughness level
    (particle slot i belongs to level i % L): the effective sample size of a level is
    s1^2 / s2."""
    n = log_w.shape[0]
    n_levels = s1.shape[0]
    for i in range(n):
        lik[i] = log_w[i] + log64(lik[i])
    hi = max_lanes(lik, np.empty(LANES))
    s1[:] = 0.0
    s2[:] = 0.0
    if not math.isfinite(hi):
        return -math.inf
    if n_levels == 1:  # one sum each, which LLVM vectorises
        t1 = 0.0
        t2 = 0.0
        for i in range(n):
            e = exp64(lik[i] - hi)  # 0 below e^-708: nothing beside a sum >= 1
            t1 += e
            t2 += e * e
        s1[0] = t1
        s2[0] = t2
    else:
        for i in range(n):
            e = exp64(lik[i] - hi)
            s1[i % n_levels] += e
            s2[i % n_levels] += e * e
    total = hi + math.log(np.sum(s1))
    if not math.isfinite(total):
        return -math.inf
    for i in range(n):
        log_w[i] = lik[i] - total
    return total


@inline
def geometry_and_shape(px: float, py: float, rx: float, ry: float, rz: float, sin_yaw: float,
                       cos_yaw: float, p: RadioParams) -> tuple[float, float, float]:
    """(l, g, a): :func:`geometry` and the shape of the mission's pattern ``a = (cos(dpsi) -
    1) cos(elev)`` (dpsi the tag's bearing from the nose, elev its depression angle), the
    regressor of an unknown change ``c`` of half the front-to-back ratio; ``g = (fb / 2) a``.
    One square root each, as :func:`geometry`."""
    d2, shape = distance2_and_gain(px - rx, py - ry, rz * rz, p.min_distance2_m2, sin_yaw,
                                   cos_yaw, 1.0)
    return (0.5 * _MINUS_10_OVER_LN10 * log64(d2 / (p.d0_m * p.d0_m)),
            0.5 * p.front_back_db * shape, shape)


@inline
def dot(a: FloatArray, b: FloatArray) -> float:
    acc = 0.0
    for k in range(a.shape[0]):
        acc += a[k] * b[k]
    return acc


@inline
def unpack_gaussian(mean: FloatArray, cov: FloatArray, i: int, mu: FloatArray,
                    sig: FloatArray) -> None:
    """Particle i's theta mean into ``mu`` (K,) and its packed covariance (upper triangle
    column by column, :func:`core.radio_belief.packed_index`) into ``sig`` (K, K)."""
    kk = mu.shape[0]
    for b in range(kk):
        mu[b] = mean[i, b]
        for a in range(b + 1):
            v = cov[i, b * (b + 1) // 2 + a]
            sig[a, b] = v
            sig[b, a] = v


@inline
def pack_gaussian(mu: FloatArray, sig: FloatArray, i: int, mean: FloatArray, cov: FloatArray
                  ) -> None:
    """The inverse of :func:`unpack_gaussian`."""
    kk = mu.shape[0]
    for b in range(kk):
        mean[i, b] = mu[b]
        for a in range(b + 1):
            cov[i, b * (b + 1) // 2 + a] = sig[a, b]


@inline
def project(sig: FloatArray, h: FloatArray, sh: FloatArray) -> float:
    """``sh <- Sigma h'``; returns ``h Sigma h'`` (>= 0: rounding never makes it negative)."""
    kk = h.shape[0]
    q = 0.0
    for a in range(kk):
        acc = 0.0
        for b in range(kk):
            acc += sig[a, b] * h[b]
        sh[a] = acc
        q += h[a] * acc
    return max(q, 0.0)


@inline
def narrow(sig: FloatArray, sh: FloatArray, f: float) -> None:
    """``Sigma <- Sigma - f (Sigma h')(Sigma h')'``, variances kept >= 0 (rounding)."""
    kk = sh.shape[0]
    for a in range(kk):
        for b in range(kk):
            sig[a, b] -= f * sh[a] * sh[b]
        sig[a, a] = max(sig[a, a], 0.0)


@kernel
def classic_update(states: FloatArray, rx_xyz: FloatArray, rx_yaw_rad: float, z_db: FloatArray,
                   log_w: FloatArray, p: RadioParams) -> tuple[float, float]:
    """The classic filter's whole update (the radio model trusted exactly): each particle's
    power from the receiver pose, its likelihood L for the detections z_db (J,), and the
    log-weights (N,) updated in place by Bayes' rule and normalised. Returns (log of the
    weighted mean likelihood, effective sample size 1 / sum w^2); if that log is not finite
    (every particle impossible), ``log_w`` is left unchanged and the ESS is NaN."""
    n = states.shape[0]
    nz = z_db.shape[0]
    sin_yaw, cos_yaw = math.sin(rx_yaw_rad), math.cos(rx_yaw_rad)
    rx, ry, rz = rx_xyz[0], rx_xyz[1], rx_xyz[2]
    lik = np.empty(n)
    power = np.empty(n)
    # positions copied out of the (N, 4) rows first: with a stride of 4 LLVM does not
    # vectorise the geometry below (3x slower)
    px = np.empty(n)
    py = np.empty(n)
    for i in range(n):
        px[i] = states[i, 0]
        py[i] = states[i, 1]
    for i in range(n):
        log_term, gain = geometry(px[i], py[i], rx, ry, rz, sin_yaw, cos_yaw, p)
        power[i] = p.p0_db + gain + p.path_loss_exponent * log_term
    weakest = -max_lanes(-power, np.empty(LANES))
    spread = math.sqrt(p.detection_spread2_db2)
    if nz <= 1 and (weakest - p.sensitivity_db) / spread >= CERTAIN_X:
        # every particle certainly detectable (detection() would return the constants) and
        # at most one power: a loop without branches or calls, which LLVM vectorises
        lik[:] = p.miss_floor
        if nz == 1:
            z = z_db[0]
            c = p.pd_max * p.inv_kappa * p.inlier / math.sqrt(2.0 * math.pi * p.noise_var)
            k = -0.5 / p.noise_var
            floor = p.miss_floor + p.pd_max * p.outlier_density * p.inv_kappa
            for i in range(n):
                e = z - power[i]
                lik[i] = floor + c * exp64(k * e * e)
    else:
        g_in = np.empty(nz)
        share = np.empty(nz)
        for i in range(n):
            pd, miss = detection(power[i], 0.0, p)
            for j in range(nz):
                g_in[j] = pd * inlier_density(z_db[j] - power[i], p.noise_var, p)
            lik[i] = likelihood(pd, miss, g_in, share, p)
    s1 = np.empty(1)
    s2 = np.empty(1)
    total = _reweight_levels(log_w, lik, s1, s2)
    return total, s1[0] * s1[0] / s2[0] if math.isfinite(total) else math.nan


@kernel
def robust_update(states: FloatArray, mean: FloatArray, cov: FloatArray, level: LevelArray,
                  rx_xyz: FloatArray, rx_yaw_rad: float, nb_poses: FloatArray, nb_z_db: FloatArray,
                  beta: FloatArray, r2: FloatArray, shadow_left: FloatArray, misses_k: float,
                  z_db: FloatArray, log_w: FloatArray, p: RadioParams
                  ) -> tuple[float, FloatArray, FloatArray, FloatArray]:
    """The robust filter's whole update (:mod:`core.radio_belief`), in place.

    Each particle's power predicted from its Gaussian over theta (offset b, exponent n, and
    with an unknown front-to-back ratio its change c) (``mean`` (N, K), ``cov`` (N, K (K + 1)
    / 2) packed, :func:`core.radio_belief.packed_index`), prewhitened against the m neighbour cells
    ``nb_poses`` (m, 4) ``[x, y, z, yaw]`` with mean powers ``nb_z_db`` (m,) by its level's
    ``beta`` (L, m), with variance ``r2`` (L,) (shadowing, receiver noise and model error);
    pD of that prediction less the receiver noise, and for each detection pD given its
    power. Then L for the detections z_db (J,), one weighted, moment-matched
    Kalman step of the Gaussian per detection (in order, each predicted afresh) or, for a
    missed pulse (J = 0), the narrowing probit step of :func:`miss_moments`, and the
    log-weights updated as by :func:`classic_update`. A miss is scored given ``misses_k``
    earlier misses weighted by their shadowing correlation with it (:func:`correlated_miss`,
    over each level's shadowing left after the neighbours, ``shadow_left`` (L,)), and its
    probit step is divided by 1 + misses_k. Returns (log of the weighted mean
    likelihood, (J,) prior-weighted inlier probability of each detection, (L,) sum w and
    (L,) sum w^2 of each level's new weights, w scaled by a common factor)."""
    n = states.shape[0]
    nz = z_db.shape[0]
    n_levels, m = beta.shape
    sin_yaw, cos_yaw = math.sin(rx_yaw_rad), math.cos(rx_yaw_rad)
    rx, ry, rz = rx_xyz[0], rx_xyz[1], rx_xyz[2]
    nb_sin = np.sin(nb_poses[:, 3])
    nb_cos = np.cos(nb_poses[:, 3])
    z_shift = np.zeros(n_levels)  # sum_k beta_k z_k: the prewhitening of z, per level
    beta_sum = np.zeros(n_levels)
    conditioned = np.zeros(n_levels, np.bool_)  # any beta_k != 0 (else no neighbour terms)
    for lev in range(n_levels):
        for k in range(m):
            z_shift[lev] += beta[lev, k] * nb_z_db[k]
            beta_sum[lev] += beta[lev, k]
            conditioned[lev] |= beta[lev, k] != 0.0
    lik = np.empty(n)
    g_in = np.empty(nz)
    share = np.empty(nz)
    mass = np.zeros(nz)
    kk = mean.shape[1]  # the unknowns: (b, n), or (b, n, c) with an unknown front-back ratio
    pattern = kk > 2
    h = np.empty(kk)  # the prewhitened regressors H~ (c~ is base)
    mu = np.empty(kk)
    sig = np.empty((kk, kk))
    sh = np.empty(kk)  # Sigma H~'
    for i in range(n):
        lev = level[i]
        px, py = states[i, 0], states[i, 1]
        l0, g0, a0 = geometry_and_shape(px, py, rx, ry, rz, sin_yaw, cos_yaw, p)
        h[0] = 1.0 - beta_sum[lev]
        h[1] = l0
        if pattern:
            h[2] = a0
        base = p.p0_db * (1.0 - beta_sum[lev]) + g0
        for k in range(m if conditioned[lev] else 0):
            bk = beta[lev, k]
            lk, gk, ak = geometry_and_shape(px, py, nb_poses[k, 0], nb_poses[k, 1],
                                            nb_poses[k, 2], nb_sin[k], nb_cos[k], p)
            h[1] -= bk * lk
            base -= bk * gk
            if pattern:
                h[2] -= bk * ak
        unpack_gaussian(mean, cov, i, mu, sig)
        # conditional prediction of the power given the neighbours: mean, variance s of the
        # reported power and vp of the received power (s less the receiver noise)
        q = project(sig, h, sh)
        pred = z_shift[lev] + base + dot(h, mu)
        s = q + r2[lev]
        vp = max(s - p.noise_var, 0.0)
        pd, miss = detection(pred, vp, p)
        miss_lik = miss
        if nz == 0 and misses_k > 0.0 and shadow_left[lev] > 0.0:
            miss_lik = correlated_miss(pred, vp, shadow_left[lev], misses_k, miss, p)
        for j in range(nz):
            # a detected power is both a draw of the received power and evidence that it was
            # above the threshold: pD given z (the power's conditional law), not pD
            e = z_db[j] - pred
            pd_z, _ = detection(pred + vp / s * e, vp * p.noise_var / s, p)
            g_in[j] = inlier_density(e, s, p) * pd_z
        lik[i] = likelihood(pd, miss_lik, g_in, share, p)
        if nz == 0:
            # a miss moves the Gaussian too: the power was (probably) below the threshold
            shift_q, dvar_q2 = miss_moments(pred, q, vp - q, miss, p)
            # misses that share this one's shadowing said mostly the same about theta
            shift_q /= 1.0 + misses_k
            dvar_q2 /= 1.0 + misses_k
            if dvar_q2 < 0.0:
                # only where the posterior narrows: where a pulse that should have been heard
                # was lost the posterior is bimodal (lost, or below the threshold), and its
                # moment-matched Gaussian would widen with every such miss and let far
                # particles live; those misses move only the weights
                for a in range(kk):
                    mu[a] += sh[a] * shift_q
                narrow(sig, sh, -dvar_q2)
        w_prior = math.exp(log_w[i]) if nz else 0.0
        for j in range(nz):
            w = min(max(share[j], 0.0), 1.0)
            mass[j] += w_prior * w
            # the Gaussians move with each detection: predict afresh
            s = project(sig, h, sh) + r2[lev]
            e = z_db[j] - z_shift[lev] - (base + dot(h, mu))
            for a in range(kk):
                mu[a] += w * e / s * sh[a]
            narrow(sig, sh, w / s - w * (1.0 - w) * e * e / (s * s))
        pack_gaussian(mu, sig, i, mean, cov)
    s1 = np.empty(n_levels)
    s2 = np.empty(n_levels)
    total = _reweight_levels(log_w, lik, s1, s2)
    return total, mass, s1, s2
