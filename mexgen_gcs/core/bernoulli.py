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

computed on the log scale so that no weight underflow produces a NaN. Resampling is
systematic when the effective sample size drops below a fraction of N, followed by
roughening. Every random draw uses the generator handed to the constructor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import ModeArray, MotionModel
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.resampling import (
    effective_sample_size,
    logsumexp,
    normalise_log_weights,
    roughen,
    systematic_resample,
)
from mexgen_gcs.errors import EstimationError

FloatArray = NDArray[np.float64]

_PD_CEIL = 1.0 - 1e-12
_MIN_KAPPA = 1e-300


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


class BernoulliFilter:
    """One tag's particle Bernoulli filter. State is held; the maths is in module functions."""

    def __init__(
        self,
        motion: MotionModel,
        radio: RadioModel,
        area: SearchArea,
        config: FilterConfig,
        rng: np.random.Generator,
    ) -> None:
        self.motion = motion
        self.radio = radio
        self.area = area
        self.config = config
        self.rng = rng
        n = config.n_particles
        self.states, self.modes = self._birth(n)
        self.log_w = np.full(n, -math.log(n))
        self.existence = config.initial_existence
        self.n_updates = 0
        self.n_resamples = 0

    # -- roles ------------------------------------------------------------------------------

    def _birth(self, n: int) -> tuple[FloatArray, ModeArray]:
        return self.motion.initial(self.area.sample_uniform(n, self.rng), self.rng)

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
            self.existence = q_pred
        self.states, self.modes = self.motion.propagate(self.states, self.modes, dt_s, self.rng)

    def update(self, z_db: FloatArray, rx_xyz: FloatArray, rx_yaw_rad: float) -> None:
        """Bernoulli update with one pulse period's measurements z_db (m,) (empty = missed
        detection) taken at receiver position rx_xyz (3,) ENU with heading rx_yaw_rad."""
        z = np.asarray(z_db, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(z)) or not np.all(np.isfinite(rx_xyz)):
            raise EstimationError("update needs finite measurements and receiver position")
        power = self.radio.power_db(self.states[:, :2], np.asarray(rx_xyz), rx_yaw_rad)
        log_l = bernoulli_log_likelihood(self.radio, power, z)
        self.log_w, self.existence = bernoulli_update(self.log_w, self.existence, log_l)
        self.n_updates += 1
        if effective_sample_size(self.log_w) < self.config.resample_ess_fraction * len(self.log_w):
            self.resample()

    def resample(self) -> None:
        """Systematic resampling to N equal weights, then roughening of the states."""
        n = self.config.n_particles
        idx = systematic_resample(self.log_w, n, self.rng)
        self.states = roughen(self.states[idx], self.config.roughening_k, self.rng)
        self.modes = self.modes[idx]
        self.log_w = np.full(n, -math.log(n))
        self.n_resamples += 1

    # -- outputs ----------------------------------------------------------------------------

    def estimate(self) -> TagEstimate:
        w = np.exp(self.log_w)
        mean = w @ self.states
        d = self.states[:, :2] - mean[:2]
        cov = (d * w[:, None]).T @ d
        tr = float(cov[0, 0] + cov[1, 1])
        radius = self.config.radius_from_trace(tr)
        localised = (
            radius <= self.config.localised_radius_m
            and self.existence >= self.config.localised_min_existence
        )
        return TagEstimate(
            existence=float(self.existence), mean=mean, cov_pos=cov, trace_pos_m2=tr,
            radius_m=radius, localised=localised, ess=effective_sample_size(self.log_w),
        )

    def sample(self, n: int, rng: np.random.Generator) -> tuple[FloatArray, ModeArray]:
        """n equal-weight particles (states (n, 4), modes (n,)) for the planner."""
        if n < 1:
            raise EstimationError(f"cannot sample {n} particles; ask for at least 1")
        idx = systematic_resample(self.log_w, n, rng)
        return self.states[idx], self.modes[idx]


def bernoulli_log_likelihood(
    radio: RadioModel, power_db: FloatArray, z_db: FloatArray
) -> FloatArray:
    """log L(x) for each particle: power (N,) noiseless predictions, z (m,) measurements.

    L = 1 - pD + pD * sum_z g(z|x) / kappa. Finite for every input (pD is kept below 1).
    """
    pd = np.minimum(radio.detection_probability(power_db), _PD_CEIL)
    log_miss = np.log1p(-pd)
    if z_db.size == 0:
        return log_miss
    log_kappa = math.log(max(radio.clutter_density, _MIN_KAPPA))
    ll = radio.log_likelihood(z_db[None, :], power_db[:, None])  # (N, m)
    log_det = np.log(np.maximum(pd, 1e-300)) + logsumexp(ll, axis=1) - log_kappa
    return np.logaddexp(log_miss, log_det)


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
