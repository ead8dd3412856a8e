"""Particle Bernoulli filter for one tag (Ristic, Vo, Vo and Farina 2013, single sensor).

Frame: local ENU metres about home. The belief of one tag is an existence probability ``q``
and weighted particles ``states (N, 4)`` ``[x, y, vx, vy]`` with IMM modes ``(N,) int8`` and
log-weights ``(N,)``, normalised by the update's kernel (:mod:`core.filter_kernels`) and after
resampling (``resampling.normalise_log_weights``).

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

with L >= 1 - pd_max > 0 as a probability and the weights on the log scale, so that no
weight underflow produces a NaN. With radio unknowns
(``FilterConfig.radio_unknowns``) each particle also carries a Gaussian over the tag's power
offset, the path-loss exponent and the shadowing (:mod:`core.radio_belief`): ``pD`` and ``g``
are then marginal over them, ``g`` is an outlier mixture, and each detection updates the
Gaussians by a Kalman step (a Rao-Blackwellised particle filter). The update is one compiled
pass over the particles (:mod:`core.filter_kernels`), the motion one more
(:mod:`core.motion`). Resampling is systematic when the effective sample size drops below a
fraction of N, followed by roughening (one compiled pass, :mod:`core.resampling`). Every
random draw uses the generator handed to the constructor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.filter_kernels import classic_update, radio_params, robust_update
from mexgen_gcs.core.jit import exp64, kernel
from mexgen_gcs.core.motion import ModeArray, MotionModel
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import (
    PulseNoise,
    RadioBelief,
    RadioUncertainty,
    ShadowMemory,
    TagRadioPrior,
    shadow_conditioning,
)
from mexgen_gcs.core.resampling import (
    normalise_log_weights,
    resample_roughen,
    systematic_resample,
)
from mexgen_gcs.errors import EstimationError

FloatArray = NDArray[np.float64]

_NO_ROWS2, _NO_ROWS3 = np.zeros((0, 2)), np.zeros((0, 3))  # no radio belief to resample
COLLAPSED_RADIUS_M = 1e-3
"""A radius below this is a cloud of one particle's copies (every weight on one ancestor;
roughening adds nothing where the copies do not spread), not a posterior: it claims nothing
(its radius, rounding of 0, says nothing about where the tag is)."""


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
        # roughen only the state columns the model moves (a static or random-walk tag's
        # velocity stays zero); models that do not say move them all
        self._rough_dims = int(getattr(motion, "moving_dims", 4))  # (east, north, v_e, v_n)
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
        self._params = radio_params(radio, self.unknowns.outlier_prob)
        levels = np.asarray(self.unknowns.levels)  # (L, 2) shadowing std, model error std
        self._level_shadow_var = np.ascontiguousarray(levels[:, 0] ** 2)
        self._level_noise_var = radio.noise_var + levels[:, 1] ** 2  # receiver + model error
        step = len(levels)
        self._level_slots = (n - np.arange(step) + step - 1) // step  # particles per level
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
                # each particle reborn with probability beta, independently: the number is
                # Binomial(N, beta) and, given it, which ones a uniform subset (one draw, not
                # N uniforms: beta is ~1e-3 and this runs every pulse for every tag)
                n = self.states.shape[0]
                k = int(self.rng.binomial(n, beta))
                if k:
                    reborn = np.zeros(n, dtype=np.bool_)
                    reborn[self.rng.choice(n, k, replace=False)] = True
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
        z = np.ascontiguousarray(z_db, dtype=np.float64).reshape(-1)
        rx = np.ascontiguousarray(rx_xyz, dtype=np.float64).reshape(3)
        if not math.isfinite(float(z.sum()) + float(rx.sum())):
            raise EstimationError("update needs finite measurements and receiver position")
        belief = self.radio_belief
        if belief is None:
            log_mean_l, ess = classic_update(self.states, rx, float(rx_yaw_rad), z, self.log_w,
                                             self._params)
        else:
            log_mean_l, s1, s2 = self._robust_update(belief, z, rx, float(rx_yaw_rad))
        self.n_updates += 1
        if not math.isfinite(log_mean_l):
            # every particle impossible: the weights keep their prior shape (unchanged since
            # the last update's degeneracy check, so no resampling either)
            return
        self.existence = posterior_existence(self.existence, log_mean_l)
        if belief is None:
            if ess < self.config.resample_ess_fraction * self.log_w.shape[0]:
                self.resample()
        else:
            self._resample_degenerate_levels(s1, s2)

    def _robust_update(self, belief: RadioBelief, z: FloatArray, rx: FloatArray, yaw: float
                       ) -> tuple[float, FloatArray, FloatArray]:
        """The update with the radio unknowns (core.radio_belief): every particle's Gaussian
        moves, and the detections most likely the tag's are remembered. The shadowing
        conditioning, shared by the particles of a roughness level, is solved here per
        level; the per-particle work is one kernel. Returns (log mean likelihood, per-level
        sum w, sum w^2)."""
        unc, mem = self.unknowns, self.shadow_memory
        idx, d_new = mem.neighbours(self.t_s, rx[:2], unc.shadowing_distance_m)
        beta, r2 = shadow_conditioning(mem, idx, d_new, self._level_shadow_var,
                                       self._level_noise_var, unc.shadowing_distance_m)
        shadow_left = np.maximum(r2 - self._level_noise_var, 0.0)
        misses_k = 0.0 if z.shape[0] else mem.misses_near(self.t_s, rx[:2],
                                                          unc.shadowing_distance_m)
        log_mean_l, mass, s1, s2 = robust_update(
            self.states, belief.mean, belief.cov, belief.level, rx, yaw,
            np.ascontiguousarray(mem.poses[idx]), np.ascontiguousarray(mem.z_db[idx]), beta, r2,
            shadow_left, misses_k, z, self.log_w, self._params)
        for j in np.flatnonzero(mass > 0.5):  # remember the pulses most likely the tag's
            mem.add(self.t_s, rx, yaw, float(z[j]))
        if not z.shape[0]:
            mem.add_miss(self.t_s, rx[:2])
        return log_mean_l, s1, s2

    @property
    def n_levels(self) -> int:
        """Roughness hypotheses (particle slot i belongs to level i % n_levels)."""
        return 1 if self.radio_belief is None else len(self.unknowns.levels)

    def _resample_degenerate_levels(self, s1: FloatArray, s2: FloatArray) -> None:
        """Resample each roughness level whose effective sample size (sum w)^2 / sum w^2
        (from its (L,) sums ``s1``, ``s2``) is below the configured fraction of its slots;
        a dead level (s1 = s2 = 0) never resamples."""
        frac = self.config.resample_ess_fraction
        degenerate = np.flatnonzero(s1 * s1 < frac * self._level_slots * s2)
        if degenerate.size:
            self.resample(tuple(int(lev) for lev in degenerate))

    def resample(self, levels: tuple[int, ...] | None = None) -> None:
        """Systematic resampling to equal weights, then roughening of the states.

        With several roughness levels each level is resampled within its own particle slots
        (``level::n_levels``) and keeps its total weight, its posterior probability: a level
        is never crowded out by resampling, only by the evidence (a bank of filters, one per
        level, weighted by their marginal likelihoods). ``levels`` None: every level."""
        step = self.n_levels
        for lev in range(step) if levels is None else levels:
            sl = slice(lev, None, step)
            belief = self.radio_belief
            mean, cov = (_NO_ROWS2, _NO_ROWS3) if belief is None else (belief.mean[sl],
                                                                       belief.cov[sl])
            log_mass = resample_roughen(self.log_w[sl], self.states[sl], self.modes[sl], mean,
                                        cov, self.config.roughening_k, self._rough_dims,
                                        self.rng)
            mass = log_mass if math.isfinite(log_mass) else -math.log(step)
            self.log_w[sl] = mass - math.log(self.log_w[sl].shape[0])
        self.log_w, _ = normalise_log_weights(self.log_w)
        self.n_resamples += 1

    # -- outputs ----------------------------------------------------------------------------

    def estimate(self) -> TagEstimate:
        step = self.n_levels
        radio_mean = _NO_RADIO if self.radio_belief is None else self.radio_belief.mean
        out = weighted_moments(self.states, self.log_w, step, radio_mean)
        mean, cov = out[0:4], out[4:8].reshape(2, 2)
        radio_est, sum_w2 = out[8:10], float(out[10])
        mass, spread = out[11:11 + step], out[11 + step:11 + 2 * step]
        tr = float(cov[0, 0] + cov[1, 1])
        radius = self.config.radius_from_trace(tr)
        if step > 1:  # the bank's own radius: each roughness level a Gaussian of its spread
            radius = mixture_radius(mass, spread, 1.0 - self.config.localised_confidence)
        localised = (
            radius <= self.config.localised_radius_m
            and self.existence >= self.config.localised_min_existence
            and radius >= COLLAPSED_RADIUS_M
        )
        if self.radio_belief is None:
            offset, exponent = self.tag_prior.offset_db, self.radio.path_loss_exponent
        else:
            offset, exponent = float(radio_est[0]), float(radio_est[1])
        return TagEstimate(
            existence=float(self.existence), mean=mean, cov_pos=cov, trace_pos_m2=tr,
            radius_m=radius, localised=localised, ess=float(1.0 / sum_w2),
            p0_offset_db=offset, path_loss_exponent=exponent,
        )

    def sample(self, n: int, rng: np.random.Generator) -> tuple[FloatArray, ModeArray]:
        """n equal-weight particles (states (n, 4), modes (n,)) for the planner."""
        if n < 1:
            raise EstimationError(f"cannot sample {n} particles; ask for at least 1")
        idx = systematic_resample(self.log_w, n, rng)
        return self.states[idx], self.modes[idx]

    def sample_planning(self, n: int, rng: np.random.Generator
                        ) -> tuple[FloatArray, ModeArray, FloatArray | None, FloatArray | None,
                                   FloatArray | None]:
        """n equal-weight particles for the planner with, when the radio is uncertain, each
        particle's mean (offset dB, exponent) and the particles' mean covariance of them:
        states (n, 4), modes (n,), offsets (n,) | None, exponents (n,) | None, covariance (3,)
        ``[bb, bn, nn]`` | None.

        Means, not draws: the filter keeps the unknowns as a Gaussian per particle and moves
        particle weights only by where the tag is, so the planner's weights must too. With a
        draw per particle, a pulse anywhere (far from every tag, where it says nothing about
        the position) told particles apart by their drawn offsets, and the planner flew away to
        learn them. Their uncertainty enters each pulse's noise instead (:mod:`core.rollout`).
        The shadowing is the planner's noise too (:meth:`planning_noise`)."""
        if n < 1:
            raise EstimationError(f"cannot sample {n} particles; ask for at least 1")
        idx = systematic_resample(self.log_w, n, rng)
        belief = self.radio_belief
        if belief is None:
            offset = None if self.tag_prior.offset_db == 0.0 else np.full(
                n, self.tag_prior.offset_db)
            return self.states[idx], self.modes[idx], offset, None, None
        mu = belief.mean[idx]
        # the planner predicts with the mission's antenna pattern: an unknown front-to-back
        # ratio (theta's c) moves the filter's weights, not the planner's expected pulses
        return (self.states[idx], self.modes[idx], mu[:, 0].copy(), np.maximum(mu[:, 1], 0.1),
                belief.cov[idx][:, :3].mean(axis=0))

    def planning_noise(self) -> PulseNoise | None:
        """What another pulse would tell the planner (:class:`PulseNoise`) under the filter's
        most likely roughness level, from the cells the filter would condition it on; None
        for the classic filter (the planner then uses the receiver noise)."""
        if self.radio_belief is None:
            return None
        n_levels = self.n_levels
        mass = np.bincount(np.arange(self.log_w.shape[0]) % n_levels,
                           weights=np.exp(self.log_w - self.log_w.max()), minlength=n_levels)
        lev = int(np.argmax(mass))
        mem = self.shadow_memory
        k = mem.count
        usable = np.ones(k, dtype=np.bool_)
        if math.isfinite(mem.horizon_s):
            usable = mem.t_s[:k] >= self.t_s - mem.horizon_s
        return PulseNoise(np.ascontiguousarray(mem.poses[:k, :2][usable]),
                          np.ascontiguousarray(mem.n[:k][usable]),
                          float(self._level_shadow_var[lev]), float(self._level_noise_var[lev]),
                          self.unknowns.shadowing_distance_m)


def posterior_existence(existence: float, log_mean_l: float) -> float:
    """q' = q <L> / (1 - q + q <L>) from the log of the weighted mean likelihood <L>, on the
    log scale (``log_mean_l`` finite)."""
    if existence <= 0.0:
        return 0.0
    if existence >= 1.0:
        return 1.0
    log_q_l = math.log(existence) + log_mean_l
    return math.exp(log_q_l - float(np.logaddexp(math.log1p(-existence), log_q_l)))


_NO_RADIO = np.zeros((0, 2))


@kernel
def mixture_radius(mass: FloatArray, spread: FloatArray, tail: float) -> float:
    """The radius R (m) about the reported position that holds all but ``tail`` of a bank of
    roughness levels, each level a circular Gaussian about that position with its own trace
    (level l: weight ``mass[l]``, weighted squared distance ``spread[l]``, so trace
    t_l = spread_l / mass_l): sum_l m_l exp(-R^2 / t_l) = tail with m normalised. One level
    gives the trace radius sqrt(-ln(tail) t); the sum decreases in R^2, so bisection on R^2
    within [0, -ln(tail) max t] (60 halvings, to machine precision)."""
    total = 0.0
    t_max = 0.0
    for lev in range(mass.shape[0]):
        if mass[lev] > 0.0:
            total += mass[lev]
            t_max = max(t_max, spread[lev] / mass[lev])
    if total <= 0.0 or t_max <= 0.0:
        return 0.0
    lo, hi = 0.0, -math.log(tail) * t_max
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        acc = 0.0
        for lev in range(mass.shape[0]):
            if mass[lev] > 0.0:
                acc += mass[lev] * math.exp(-mid * mass[lev] / max(spread[lev], 1e-300))
        if acc > tail * total:
            lo = mid
        else:
            hi = mid
    return math.sqrt(hi)


@kernel
def weighted_moments(states: FloatArray, log_w: FloatArray, n_levels: int,
                     radio_mean: FloatArray) -> FloatArray:
    """What :meth:`BernoulliFilter.estimate` reports, in three passes over the particles,
    packed in one array (one allocation to return, which is most of the cost at N = 2000):
    [0:4] the weighted mean state, [4:8] the position covariance (2, 2) row by row, [8:10]
    the weighted mean of the first two columns of ``radio_mean`` (N, K) (zeros if it is
    empty), [10] sum w^2 (1 / the effective sample size), then each roughness level's weight
    (L,) and weighted squared distance from the mean (L,) (particle slot i belongs to level
    i % L). log_w: (N,) normalised."""
    n = states.shape[0]
    w = np.empty(n)
    # short loops with scalar accumulators (not array elements): LLVM vectorises each
    s_w = s_w2 = s_x = s_y = s_vx = s_vy = 0.0
    for i in range(n):
        wi = exp64(log_w[i])
        w[i] = wi
        s_w += wi
        s_w2 += wi * wi
    for i in range(n):
        wi = w[i]
        s_x += wi * states[i, 0]
        s_y += wi * states[i, 1]
        s_vx += wi * states[i, 2]
        s_vy += wi * states[i, 3]
    out = np.zeros(11 + 2 * n_levels)
    out[0], out[1], out[2], out[3], out[10] = s_x, s_y, s_vx, s_vy, s_w2
    for k in range(min(radio_mean.shape[1], 2) if radio_mean.shape[0] > 0 else 0):
        acc = 0.0
        for i in range(n):
            acc += w[i] * radio_mean[i, k]
        out[8 + k] = acc
    cxx = 0.0
    cxy = 0.0
    cyy = 0.0
    for i in range(n):
        dx = states[i, 0] - s_x
        dy = states[i, 1] - s_y
        cxx += w[i] * dx * dx
        cxy += w[i] * dx * dy
        cyy += w[i] * dy * dy
    out[4], out[5], out[6], out[7] = cxx, cxy, cxy, cyy
    if n_levels > 1:
        for i in range(n):
            dx = states[i, 0] - s_x
            dy = states[i, 1] - s_y
            out[11 + i % n_levels] += w[i]
            out[11 + n_levels + i % n_levels] += w[i] * (dx * dx + dy * dy)
    else:
        out[11], out[12] = s_w, cxx + cyy
    return out
