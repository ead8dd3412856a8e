"""Particle Bernoulli filter for one tag (Ristic, Vo, Vo and Farina 2013, single sensor).

Frame: local ENU metres about home. The belief of one tag is an existence probability ``q``
and weighted particles ``states (N, 4)`` ``[x, y, vx, vy]`` with IMM modes ``(N,) int8`` and
log-weights ``(N,)`` normalised in one place (``resampling.normalise_log_weights``).

Prediction (per pulse period ``dt``)::

    q_pred = p_b (1 - q) + p_s q
    s_pred = (p_s q s_prop + p_b (1 - q) b) / q_pred

with the birth density ``b`` uniform over the search area (velocity and mode from the motion
model's ``initial``). With a fixed particle count the mixture is sampled by replacing each
particle by a birth particle with probability ``beta = p_b (1 - q) / q_pred``.

Update with the pulse period's measurement set ``Z`` (0 = missed detection, 1 = detection,
more = clutter too), ``kappa = clutter intensity per dB``::

    L(x) = 1 - pD(x) + sum_z pD(x) g(z | x) / kappa
    q_upd = q <L> / (1 - q + q <L>),    w_i <- w_i L(x_i)

computed on the log scale so that no weight underflow produces a NaN. With radio unknowns
(``FilterConfig.radio_unknowns``) each particle also carries a Gaussian over the tag's power
offset, the path-loss exponent and the shadowing (:mod:`core.radio_belief`): ``pD`` and ``g``
are then marginal over them, ``g`` is an outlier mixture, and each detection updates the
Gaussians by a Kalman step (a Rao-Blackwellised particle filter). Resampling is
systematic when the effective sample size drops below a fraction of N, followed by
roughening. Every random draw uses the generator handed to the constructor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import ModeArray, MotionModel
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import (
    Predicted,
    RadioBelief,
    RadioUncertainty,
    ShadowMemory,
    TagRadioPrior,
    kalman_update,
    log_detected_density,
    log_detection_probability,
    predict_power,
    predict_prewhitened,
    shadow_conditioning,
)
from mexgen_gcs.core.resampling import (
    effective_sample_size,
    logsumexp,
    normalise_log_weights,
    roughen,
    systematic_resample,
)
from mexgen_gcs.errors import EstimationError

FloatArray = NDArray[np.float64]

_MIN_KAPPA = 1e-300
LEVEL_CLAIM_MASS = 0.05
"""A roughness level with at least this posterior probability must agree with a claimed
localisation radius (about the reported position)."""


@dataclass(frozen=True, slots=True)
class FilterConfig:
    """Settings of the per-tag Bernoulli particle filter."""

    n_particles: int = 2000
    survival_prob: float = 0.999
    birth_prob: float = 0.001
    initial_existence: float = 0.9
    resample_ess_fraction: float = 0.5
    roughening_k: float = 0.2
    localised_radius_m: float = 50.0
    """A tag is localised when its position uncertainty radius at ``localised_confidence``
    (from the trace of the position covariance) is at most this."""
    localised_confidence: float = 0.95
    localised_min_existence: float = 0.5
    radio_unknowns: RadioUncertainty = field(default_factory=RadioUncertainty)
    """What the filter does not know about the radio (all zero: the classic model)."""

    def __post_init__(self) -> None:
        if self.n_particles < 1:
            raise EstimationError(
                f"n_particles must be at least 1 (got {self.n_particles}); a filter with no "
                "particles cannot represent a belief"
            )
        for name in ("survival_prob", "birth_prob", "initial_existence", "localised_min_existence"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise EstimationError(f"{name} must be in [0, 1] (got {v})")
        if not 0.0 < self.localised_confidence < 1.0:
            raise EstimationError("localised_confidence must be in (0, 1)")

    def radius_from_trace(self, trace_pos_m2: float) -> float:
        """Uncertainty radius (m) at the configured confidence, treating the position
        covariance as isotropic with the same trace: r = sqrt(chi2_2(conf) * tr / 2)."""
        # the chi-square quantile with 2 degrees of freedom is -2 ln(1 - p), exactly
        return math.sqrt(-math.log1p(-self.localised_confidence) * max(trace_pos_m2, 0.0))


@dataclass(frozen=True, slots=True)
class TagEstimate:
    """What a filter says about one tag at one time."""

    existence: float
    mean: FloatArray
    """(4,) weighted mean state [x, y, vx, vy], ENU."""
    cov_pos: FloatArray
    """(2, 2) position covariance, m^2."""
    trace_pos_m2: float
    radius_m: float
    """Uncertainty radius at the configured confidence."""
    localised: bool
    ess: float
    p0_offset_db: float = 0.0
    """Estimated received-power offset of the tag about the mission's P0, dB."""
    path_loss_exponent: float = math.nan
    """Estimated path-loss exponent (the mission's when it is not estimated)."""


class BernoulliFilter:
    """One tag's particle Bernoulli filter. State is held; the maths is in module functions."""

    def __init__(
        self,
        motion: MotionModel,
        radio: RadioModel,
        area: SearchArea,
        config: FilterConfig,
        rng: np.random.Generator,
        tag_prior: TagRadioPrior | None = None,
    ) -> None:
        self.motion = motion
        self.radio = radio
        self.area = area
        self.config = config
        self.rng = rng
        self.unknowns = config.radio_unknowns
        self.tag_prior = tag_prior or TagRadioPrior()
        n = config.n_particles
        self.states, self.modes = self._birth(n)
        self.states = np.ascontiguousarray(self.states)
        self.radio_belief = self._radio_prior(n)
        speed = float(getattr(motion, "speed_max_m_s", 0.0))
        dist = self.unknowns.shadowing_distance_m
        self.shadow_memory = ShadowMemory(math.inf if speed <= 0.0 else 3.0 * dist / speed)
        self.t_s = 0.0
        self.log_w = np.full(n, -math.log(n))
        self.existence = config.initial_existence
        self.n_updates = 0
        self.n_resamples = 0

    # -- roles ------------------------------------------------------------------------------

    def _birth(self, n: int) -> tuple[FloatArray, ModeArray]:
        return self.motion.initial(self.area.sample_uniform(n, self.rng), self.rng)

    def _radio_prior(self, n: int) -> RadioBelief | None:
        if not self.unknowns.active and self.tag_prior.offset_db == 0.0:
            return None
        return RadioBelief.prior(n, self.radio, self.unknowns, self.tag_prior)

    def predict(self, dt_s: float) -> None:
        """Bernoulli prediction over dt_s seconds (birth mixing, survival, motion)."""
        if dt_s <= 0.0:
            return
        cfg = self.config
        p_s = cfg.survival_prob ** dt_s
        p_b = 1.0 - (1.0 - cfg.birth_prob) ** dt_s
        q = self.existence
        q_pred = p_b * (1.0 - q) + p_s * q
        if q_pred <= 0.0:
            self.existence = 0.0
        else:
            beta = p_b * (1.0 - q) / q_pred
            if beta > 0.0:
                reborn = self.rng.random(self.states.shape[0]) < beta
                k = int(reborn.sum())
                if k:
                    self.states = self.states.copy()
                    self.modes = self.modes.copy()
                    self.states[reborn], self.modes[reborn] = self._birth(k)
                    if self.radio_belief is not None:
                        self.radio_belief.rebirth(reborn, self.radio, self.unknowns,
                                                  self.tag_prior)
            self.existence = q_pred
        self.states, self.modes = self.motion.propagate(self.states, self.modes, dt_s, self.rng)
        self.t_s += dt_s

    def update(self, z_db: FloatArray, rx_xyz: FloatArray, rx_yaw_rad: float) -> None:
        """Bernoulli update with one pulse period's measurements z_db (m,) (empty = missed
        detection) taken at receiver position rx_xyz (3,) ENU with heading rx_yaw_rad."""
        z = np.asarray(z_db, dtype=np.float64).reshape(-1)
        rx = np.asarray(rx_xyz, dtype=np.float64)
        if not np.all(np.isfinite(z)) or not np.all(np.isfinite(rx)):
            raise EstimationError("update needs finite measurements and receiver position")
        belief = self.radio_belief
        xy = self.states[:, :2]
        if belief is None:
            pred = predict_power(self.radio, None, xy, rx, rx_yaw_rad)
            log_l, _ = bernoulli_log_likelihood(self.radio, self.unknowns, pred, z,
                                                self.radio.noise_var)
        else:
            log_l = self._robust_update(belief, z, rx, rx_yaw_rad)
        self.log_w, self.existence = bernoulli_update(self.log_w, self.existence, log_l)
        self.n_updates += 1
        self._resample_if_degenerate()

    def _robust_update(self, belief: RadioBelief, z: FloatArray, rx: FloatArray,
                       yaw: float) -> FloatArray:
        """log L per particle with the radio unknowns (core.radio_belief), updating each
        particle's Gaussian. One vectorised pass: only the shadowing conditioning differs
        between roughness levels, and it is indexed by each particle's level."""
        unc, radio, mem = self.unknowns, self.radio, self.shadow_memory
        levels = np.asarray(unc.levels)  # (L, 2) shadowing std, model error std
        lev = belief.level
        idx, d_new = mem.neighbours(self.t_s, rx[:2], unc.shadowing_distance_m)
        cond = [shadow_conditioning(mem, idx, d_new, sh * sh, radio.noise_var + me * me,
                                    unc.shadowing_distance_m) for sh, me in levels]
        beta = np.array([c[0] for c in cond]).reshape(len(cond), idx.size)[lev]  # (N, m)
        r2 = np.array([c[1] for c in cond])[lev]  # (N,)
        extra = (levels[:, 0] ** 2 + levels[:, 1] ** 2)[lev]
        xy = self.states[:, :2]
        marginal, pred = predict_prewhitened(radio, belief, xy, rx, yaw, mem, idx, beta)
        z_t = z[None, :] - (beta @ mem.z_db[idx])[:, None] if idx.size else np.broadcast_to(
            z, (xy.shape[0], z.size))
        log_l, gains = bernoulli_log_likelihood(radio, unc, marginal, z_t, r2,
                                                prewhitened=pred, extra_var=extra)
        for j in range(z.size):
            if j:  # the Gaussians moved: predict again for the next measurement
                marginal, pred = predict_prewhitened(radio, belief, xy, rx, yaw, mem, idx, beta)
            kalman_update(belief, pred, z_t[:, j], gains[:, j], r2)
        if z.size:
            w = np.exp(self.log_w)
            for j in range(z.size):  # remember the pulses that are most likely the tag's
                if float(w @ gains[:, j]) > 0.5:
                    mem.add(self.t_s, rx, yaw, float(z[j]))
        return log_l

    @property
    def n_levels(self) -> int:
        """Roughness hypotheses (particle slot i belongs to level i % n_levels)."""
        return 1 if self.radio_belief is None else len(self.unknowns.levels)

    def _resample_if_degenerate(self) -> None:
        frac = self.config.resample_ess_fraction
        step = self.n_levels
        if step == 1:
            if effective_sample_size(self.log_w) < frac * self.log_w.shape[0]:
                self.resample()
            return
        # per-level ESS = (sum w)^2 / sum w^2 within each level's slots
        w = np.exp(self.log_w - self.log_w.max())
        lev = np.arange(w.shape[0]) % step
        s1 = np.bincount(lev, weights=w, minlength=step)
        s2 = np.bincount(lev, weights=w * w, minlength=step)
        count = np.bincount(lev, minlength=step)
        with np.errstate(divide="ignore", invalid="ignore"):
            ess = s1 * s1 / s2
        for level in np.flatnonzero(ess < frac * count):  # NaN (a dead level) never resamples
            self.resample(int(level))

    def resample(self, level: int | None = None) -> None:
        """Systematic resampling to equal weights, then roughening of the states.

        With several roughness levels each level is resampled within its own particle slots
        (``level::n_levels``) and keeps its total weight, its posterior probability: a level
        is never crowded out by resampling, only by the evidence (a bank of filters, one per
        level, weighted by their marginal likelihoods). ``level`` None: every level."""
        step = self.n_levels
        for lev in range(step) if level is None else (level,):
            sl = slice(lev, None, step)
            lw = self.log_w[sl]
            norm, log_mass = normalise_log_weights(lw)
            m = lw.shape[0]
            idx = systematic_resample(norm, m, self.rng)
            self.states[sl] = roughen(self.states[sl][idx], self.config.roughening_k, self.rng)
            self.modes[sl] = self.modes[sl][idx]
            if self.radio_belief is not None:
                self.radio_belief.permute(sl, idx)
            self.log_w[sl] = (log_mass if np.isfinite(log_mass) else -math.log(step)) - math.log(m)
        self.log_w, _ = normalise_log_weights(self.log_w)
        self.n_resamples += 1

    # -- outputs ----------------------------------------------------------------------------

    def estimate(self) -> TagEstimate:
        w = np.exp(self.log_w)
        mean = w @ self.states
        d = self.states[:, :2] - mean[:2]
        cov = (d * w[:, None]).T @ d
        tr = float(cov[0, 0] + cov[1, 1])
        radius = self.config.radius_from_trace(tr)
        if self.n_levels > 1:  # the claim must hold under every plausible roughness level
            lev = np.arange(w.shape[0]) % self.n_levels
            mass = np.bincount(lev, weights=w, minlength=self.n_levels)
            spread = np.bincount(lev, weights=w * (d * d).sum(axis=1), minlength=self.n_levels)
            plausible = mass >= LEVEL_CLAIM_MASS
            if plausible.any():
                tr_l = float((spread[plausible] / mass[plausible]).max())
                radius = max(radius, self.config.radius_from_trace(tr_l))
        localised = (
            radius <= self.config.localised_radius_m
            and self.existence >= self.config.localised_min_existence
        )
        if self.radio_belief is None:
            offset, exponent = self.tag_prior.offset_db, self.radio.path_loss_exponent
        else:
            offset, exponent = (float(v) for v in w @ self.radio_belief.mean)
        return TagEstimate(
            existence=float(self.existence), mean=mean, cov_pos=cov, trace_pos_m2=tr,
            radius_m=radius, localised=localised, ess=effective_sample_size(self.log_w),
            p0_offset_db=offset, path_loss_exponent=exponent,
        )

    def sample(self, n: int, rng: np.random.Generator) -> tuple[FloatArray, ModeArray]:
        """n equal-weight particles (states (n, 4), modes (n,)) for the planner."""
        if n < 1:
            raise EstimationError(f"cannot sample {n} particles; ask for at least 1")
        idx = systematic_resample(self.log_w, n, rng)
        return self.states[idx], self.modes[idx]

    def sample_planning(self, n: int, rng: np.random.Generator
                        ) -> tuple[FloatArray, ModeArray, FloatArray | None, FloatArray | None]:
        """n equal-weight particles for the planner with, when the radio is uncertain, one
        draw of each particle's (offset dB, exponent) from its Gaussian: states (n, 4), modes
        (n,), offsets (n,) | None, exponents (n,) | None. The shadowing is left out: it
        decorrelates along the planned path (the planner adds its variance to the noise)."""
        if n < 1:
            raise EstimationError(f"cannot sample {n} particles; ask for at least 1")
        idx = systematic_resample(self.log_w, n, rng)
        belief = self.radio_belief
        if belief is None:
            offset = None if self.tag_prior.offset_db == 0.0 else np.full(
                n, self.tag_prior.offset_db)
            return self.states[idx], self.modes[idx], offset, None
        mu, c = belief.mean[idx], belief.cov[idx]
        g = rng.standard_normal((n, 2))
        # Cholesky of [[bb, bn], [bn, nn]]
        l11 = np.sqrt(np.maximum(c[:, 0], 0.0))
        l21 = np.divide(c[:, 1], l11, out=np.zeros(n), where=l11 > 0.0)
        l22 = np.sqrt(np.maximum(c[:, 2] - l21 * l21, 0.0))
        offset = mu[:, 0] + l11 * g[:, 0]
        exponent = np.maximum(mu[:, 1] + l21 * g[:, 0] + l22 * g[:, 1], 0.1)
        return self.states[idx], self.modes[idx], offset, exponent


def bernoulli_log_likelihood(
    radio: RadioModel, unknowns: RadioUncertainty, pred: Predicted, z_db: FloatArray,
    noise_var: FloatArray | float | None = None, *, prewhitened: Predicted | None = None,
    extra_var: FloatArray | float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """log L(x) (N,) for each particle and the probability (N, m) that each z is that
    particle's inlier detection (the weight of its Kalman step).

    L = 1 - pD + pD * sum_z g(z|x) / kappa, finite everywhere. ``pred``: each particle's
    predicted power (pD from it, widened by ``extra_var``); the density of z uses
    ``prewhitened`` (z then being the prewhitened measurements) if given, else ``pred``, with
    noise variance ``noise_var`` (default the radio's).
    """
    log_pd, log_miss = log_detection_probability(radio, pred, extra_var)
    if z_db.size == 0:
        return log_miss, np.empty((log_miss.shape[0], 0))
    log_kappa = math.log(max(radio.clutter_density, _MIN_KAPPA))
    r = radio.noise_var if noise_var is None else noise_var
    log_g, inlier = log_detected_density(radio, unknowns, prewhitened or pred, z_db, r)
    terms = log_pd[:, None] + log_g - log_kappa
    log_l = np.logaddexp(log_miss, logsumexp(terms, axis=1))
    return log_l, np.exp(terms - log_l[:, None]) * inlier


def bernoulli_update(
    log_w: FloatArray, existence: float, log_l: FloatArray
) -> tuple[FloatArray, float]:
    """Posterior (normalised log-weights (N,), existence) from the per-particle log L (N,)."""
    new_log_w, log_mean_l = normalise_log_weights(log_w + log_l)
    if not np.isfinite(log_mean_l):  # every particle impossible: keep the prior shape
        return log_w.copy(), existence
    if existence <= 0.0:
        return new_log_w, 0.0
    if existence >= 1.0:
        return new_log_w, 1.0
    # q' = q <L> / (1 - q + q <L>), on the log scale
    log_q_l = math.log(existence) + log_mean_l
    q_new = math.exp(log_q_l - np.logaddexp(math.log1p(-existence), log_q_l))
    return new_log_w, float(q_new)
