"""What each particle believes about the radio it cannot see: a Gaussian over two or three
unknowns.

Frame: local ENU metres about home (x east, y north, z up; tags on the ground at z = 0); yaw is
a compass heading in radians, as in :mod:`core.radio`.

Given a tag position, the log-distance model is linear in the unknowns ``theta = (b, n)``: the
tag's received-power offset ``b`` (transmit power, antenna mean gain) and the path-loss
exponent ``n``; with an uncertain antenna (``front_back_std_db``) also ``c``, the change of
half the front-to-back ratio, whose regressor is the mission's pattern's shape::

    P(x, u) = P0 + g(x, u) + [1, l(x, u), a(x, u)] theta,
    l = -10 log10(max(d, d_min) / d0),     a = (cos(dpsi) - 1) cos(elev)

(dpsi the tag's bearing from the nose, elev its depression angle), so each particle carries a
Gaussian ``N(mu, Sigma)`` over theta and the filter stays a particle filter over position
only: a Rao-Blackwellised particle filter (Doucet et al. 2000). ``c`` shows only where the tag
is seen ahead and behind; on an orbit about the tag it stays at its prior. Per
particle and pulse this costs a 2- or 3-state Kalman step, in one compiled pass over the particles
(:func:`core.filter_kernels.robust_update`); this module holds the beliefs, the shadowing
memory and the neighbour conditioning shared by every particle.

- Shadowing is a static Gaussian field over the receiver's position, ``cov = sigma_s^2
  exp(-|u - u'| / L)`` (Gudmundson's model), so a pulse heard near earlier ones repeats their
  shadowing. Each detection is conditioned on the m nearest earlier detections (a nearest-
  neighbour, Vecchia, Gaussian-process approximation): with ``beta = (C + R I)^-1 c`` and
  ``r^2 = sigma_s^2 + R - c' beta`` (C among the neighbours, c to them, both shared by every
  particle), the prewhitened measurement ``z~ = z - sum beta_j z_j`` has mean
  ``c~ + H~ theta`` with ``c~ = (P0 + g) - sum beta_j (P0 + g_j)``, ``H~ = H - sum beta_j H_j``
  and variance ``r^2``: still linear-Gaussian in theta, so the Kalman step below is unchanged
  and a hover or a revisit adds only what it really adds. ``R = noise^2 + model_error^2``.
- Roughness levels: shadowing and model error are scaled by a level per particle (particle
  slot ``i`` has level ``i % L``); the filter resamples within levels, so the levels form a
  bank of filters weighted by their marginal likelihoods (:mod:`core.bernoulli`).
- Detection and the reported power share everything but the receiver noise ``R0``
  (``noise_std_db^2``): the received power given the neighbours is ``N(pred, vp)`` with
  ``pred = z_shift + c~ + H~ mu`` and ``vp = H~ Sigma H~' + r^2 - R0`` (parameters, shadowing
  and model error), and a pulse is detected on that power. So a missed pulse has
  ``1 - pD`` with::

      pD = pd_max Phi((pred - sensitivity) / sqrt(spread^2 + vp))

  and a detected power ``z`` carries both its density and the evidence that the power was
  above the threshold *given z* (the power given z is ``N(pred + vp e / S, vp R0 / S)``)::

      pD(z) = pd_max Phi((pred + vp e / S - sensitivity) / sqrt(spread^2 + vp R0 / S))

  Using the marginal pD for a detection instead counts the selection twice: under shadowing
  and fading the detected pulses are the strong ones, and their power already says so.

- A detected power ``z`` has the robust likelihood of an outlier mixture::

      g(z | x) = (1 - eps) pD(z) N(z~; c~ + H~ mu, S) + eps pD U(z; clutter range)

  The Kalman step is weighted by the particle's inlier responsibility ``w`` and
  moment-matched, so one bad pulse neither drags the unknowns nor collapses their variance::

      mu    <- mu + w K e,      K = Sigma H~' / S,  S = H~ Sigma H~' + r^2,  e = z~ - c~ - H~ mu
      Sigma <- Sigma - (w / S - w (1 - w) e^2 / S^2) Sigma H~' H~ Sigma

- A missed pulse weights the particles by ``1 - pD`` and also moves theta: with
  ``u = H~ theta + c~`` (variance ``q = H~ Sigma H~'``) the miss says the received power
  ``u + r`` (``r`` the rest of the variance, less the receiver noise) was probably below the
  threshold. The moment-matched posterior of ``u`` (a probit step mixed with the pulse lost
  anyway, ``1 - pd_max``; ``core.filter_kernels.miss_moments``) gives ``du`` and ``dq``, and::

      mu    <- mu + Sigma H~' du / q,      Sigma <- Sigma + (dq / q^2) Sigma H~' H~ Sigma

  only when ``dq < 0``: a miss that should have been heard has a bimodal posterior (lost, or
  a weak power) whose Gaussian would widen with every such miss; it only weights.
- Misses share the shadowing too. The memory keeps the misses in cells as well, and a new
  miss at ``u`` is scored given ``K = sum_j n_j exp(-|u - u_j| / L)`` earlier ones, as if
  they were at its shadowing ``s`` (the level's shadowing left after the neighbours)::

      P(miss | K earlier) = E[a(s)^(K+1)] / E[a(s)^K],   a(s) = 1 - pD given s

  (:func:`core.filter_kernels.correlated_miss`; K = 0 is ``1 - pD``), and its step of the
  Gaussian is divided by ``1 + K``. Without this, a flight through one weak patch punished
  every place near the threshold once per pulse, and taught the Gaussian the same miss
  again and again: in the field world the claims held for 0.86 (docs/results/localisation.md).

With every uncertainty zero this is exactly the classic model of :mod:`core.radio`.
Covariances are stored as their unique entries, packed (:func:`packed_index`): ``[bb, bn,
nn]``, then ``[bc, nc, cc]``. The formulas below write ``H~`` for the row of regressors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import kernel
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.errors import EstimationError

FloatArray = NDArray[np.float64]

BB, BN, NN = range(3)


@dataclass(frozen=True, slots=True)
class RadioUncertainty:
    """What the estimator does not know about the radio. All zero: the classic estimator,
    which trusts the mission's radio model exactly (the filter of earlier versions)."""

    p0_std_db: float = 0.0
    """Prior std of each tag's received-power offset b about the mission's P0, dB."""
    path_loss_exponent_std: float = 0.0
    """Prior std of the path-loss exponent about the mission's, per tag."""
    shadowing_std_db: tuple[float, ...] = (0.0,)
    """Hypotheses about the std of the shadowing (a static field over the receiver position),
    dB. Each (shadowing, model error) pair of the two lists is a roughness level; every
    particle belongs to one level for its life, and the filter resamples within levels, so
    the levels form a bank of filters weighted by their marginal likelihoods: the data select
    how rough the radio is, and a benign world does not pay for the priors of a rough one."""
    shadowing_distance_m: float = 50.0
    """Correlation distance L of the shadowing, exp(-d / L), m."""
    outlier_prob: float = 0.0
    """eps: probability that a detected power is an outlier (uniform over the clutter range)."""
    model_error_std_db: tuple[float, ...] = (0.0,)
    """Hypotheses about uncorrelated model error added to the receiver noise (fading,
    antenna pattern error), dB; see shadowing_std_db."""
    front_back_std_db: float = 0.0
    """Prior std of the antenna's front-to-back ratio about the mission's, dB (an airframe
    changes it): theta gains ``c``, half the change, with the regressor ``(cos(dpsi) - 1)
    cos(elev)`` (the mission's pattern's shape). 0: the mission's pattern is trusted and
    theta is (b, n)."""

    def __post_init__(self) -> None:
        for name in ("p0_std_db", "path_loss_exponent_std", "front_back_std_db"):
            if not (getattr(self, name) >= 0.0 and math.isfinite(getattr(self, name))):
                raise EstimationError(f"{name} must be finite and >= 0 (got {getattr(self, name)})")
        for name in ("shadowing_std_db", "model_error_std_db"):
            v = getattr(self, name)
            if not v or not all(math.isfinite(x) and x >= 0.0 for x in v):
                raise EstimationError(f"{name} must be a non-empty list of numbers >= 0 "
                                      f"(got {v})")
        if not self.shadowing_distance_m > 0.0:
            raise EstimationError("shadowing_distance_m must be > 0")
        if not 0.0 <= self.outlier_prob < 1.0:
            raise EstimationError(f"outlier_prob must be in [0, 1) (got {self.outlier_prob})")

    @property
    def levels(self) -> tuple[tuple[float, float], ...]:
        """The roughness levels: every (shadowing std, model error std) pair, dB."""
        return tuple((s, m) for s in self.shadowing_std_db for m in self.model_error_std_db)

    @property
    def n_unknowns(self) -> int:
        """K, the entries of theta: (b, n), or (b, n, c) with an unknown front-back ratio."""
        return 3 if self.front_back_std_db > 0.0 else 2

    @property
    def active(self) -> bool:
        """True if anything differs from the classic model."""
        return (self.p0_std_db > 0.0 or self.path_loss_exponent_std > 0.0
                or self.front_back_std_db > 0.0 or self.outlier_prob > 0.0
                or any(s > 0.0 or m > 0.0 for s, m in self.levels))


@dataclass(frozen=True, slots=True)
class TagRadioPrior:
    """One tag's prior received-power offset about the mission's P0 (from a calibration)."""

    offset_db: float = 0.0
    std_db: float | None = None
    """None: the mission's ``p0_std_db``."""


@dataclass(slots=True)
class RadioBelief:
    """Per-particle Gaussians over theta: ``mean (N, K)``, ``cov (N, K (K + 1) / 2)`` packed
    (:func:`packed_index`), and each particle's roughness level ``level (N,) int8`` (fixed by
    its slot)."""

    mean: FloatArray
    cov: FloatArray
    level: NDArray[np.int8]

    @classmethod
    def prior(cls, n: int, radio: RadioModel, unc: RadioUncertainty,
              tag: TagRadioPrior | None = None) -> RadioBelief:
        mean_row, cov_row = _prior_rows(radio, unc, tag)
        level = (np.arange(n) % len(unc.levels)).astype(np.int8)
        return cls(np.tile(mean_row, (n, 1)), np.tile(cov_row, (n, 1)), level)

    def rebirth(self, rows: NDArray[np.bool_], radio: RadioModel, unc: RadioUncertainty,
                tag: TagRadioPrior | None) -> None:
        """Rows ``rows`` (N,) return to the prior of their own level (births)."""
        self.mean[rows], self.cov[rows] = _prior_rows(radio, unc, tag)


def packed_index(i: int, j: int) -> int:
    """Where entry (i, j) of a symmetric K x K covariance lies in its packed row: the upper
    triangle column by column, ``j (j + 1) / 2 + i`` for i <= j. The first three entries are
    ``[bb, bn, nn]`` whatever K, so the (b, n) block reads the same for K = 2 and K = 3."""
    if i > j:
        i, j = j, i
    return j * (j + 1) // 2 + i


def _prior_rows(radio: RadioModel, unc: RadioUncertainty, tag: TagRadioPrior | None
                ) -> tuple[FloatArray, FloatArray]:
    """One particle's prior theta mean (K,) and packed covariance (K (K + 1) / 2,)."""
    tag = tag or TagRadioPrior()
    std_b = unc.p0_std_db if tag.std_db is None else tag.std_db
    k = unc.n_unknowns
    mean = np.zeros(k)
    mean[0], mean[1] = tag.offset_db, radio.path_loss_exponent
    cov = np.zeros(k * (k + 1) // 2)
    cov[BB] = std_b**2
    cov[NN] = unc.path_loss_exponent_std**2
    if k > 2:
        cov[packed_index(2, 2)] = (0.5 * unc.front_back_std_db) ** 2
    return mean, cov


SHADOW_NEIGHBOURS = 12
"""m: earlier detection cells each detection is conditioned on (Vecchia approximation). The
cells are noisy (receiver noise and fading on each pulse), and a nearest-neighbour
approximation conditioned on noisy responses needs more neighbours than one on the field
itself (Katzfuss and Guinness 2021); with 6 each pulse looked more independent than it is: in
1000 field-world surveys the claims held for 0.86 and the final radii for 0.88, with 12 for
0.96 and 0.97 (tests/core/test_calibration.py, docs/results/localisation.md)."""
CELL_M = 5.0
"""Detections within this distance (and CELL_YAW_RAD of heading) share a memory cell."""
CELL_YAW_RAD = math.radians(30.0)
_MIN_CORRELATION = 0.02
"""Earlier cells less correlated than this with a new detection are not neighbours."""


@dataclass(slots=True)
class ShadowMemory:
    """The detections a filter has used, summarised in small cells (pose of the first
    detection, mean power, count, last time), to condition new detections on. A cell of n
    pulses conditions like one pulse with noise R / n: hovering over one spot converges on
    its shadowing instead of leaking ~1/m of it as new information with every pulse. The
    missed pulses are kept in cells too (position, count, last time), to count how many
    earlier misses a new one repeats (:meth:`misses_near`).

    Static tags keep every cell; for moving tags only cells used within ``horizon_s`` (the
    shadowing is a field about the tag's place too, which moves on)."""

    horizon_s: float = math.inf
    poses: FloatArray = dataclass_field(default_factory=lambda: np.zeros((0, 4)))
    """(K, 4) receiver east, north, up, yaw_rad of each cell's first detection."""
    z_sum: FloatArray = dataclass_field(default_factory=lambda: np.zeros(0))
    n: FloatArray = dataclass_field(default_factory=lambda: np.zeros(0))
    t_s: FloatArray = dataclass_field(default_factory=lambda: np.zeros(0))
    count: int = 0
    miss_xy: FloatArray = dataclass_field(default_factory=lambda: np.zeros((0, 2)))
    """(K', 2) east, north of each miss cell; ``miss_n`` its misses, ``miss_t`` the last."""
    miss_n: FloatArray = dataclass_field(default_factory=lambda: np.zeros(0))
    miss_t: FloatArray = dataclass_field(default_factory=lambda: np.zeros(0))
    miss_count: int = 0

    @property
    def z_db(self) -> FloatArray:
        """(K,) mean power of each cell."""
        k = self.count
        return self.z_sum[:k] / np.maximum(self.n[:k], 1.0)

    def add(self, t_s: float, rx_xyz: FloatArray, yaw_rad: float, z_db: float) -> None:
        k = self.count
        if k:
            d = np.hypot(self.poses[:k, 0] - rx_xyz[0], self.poses[:k, 1] - rx_xyz[1])
            dyaw = np.abs((self.poses[:k, 3] - yaw_rad + math.pi) % (2 * math.pi) - math.pi)
            same = np.flatnonzero((d < CELL_M) & (dyaw < CELL_YAW_RAD))
            if same.size:
                c = int(same[np.argmin(d[same])])
                self.z_sum[c] += z_db
                self.n[c] += 1.0
                self.t_s[c] = t_s
                return
        if k >= self.z_sum.shape[0]:
            self.poses, self.z_sum, self.n, self.t_s = _grown(k, self.poses, self.z_sum,
                                                               self.n, self.t_s)
        self.poses[k, :3], self.poses[k, 3] = rx_xyz, yaw_rad
        self.z_sum[k], self.n[k], self.t_s[k] = z_db, 1.0, t_s
        self.count = k + 1

    def add_miss(self, t_s: float, rx_xy: FloatArray) -> None:
        """Remember a missed pulse at rx_xy (2,) (cells of CELL_M, any heading)."""
        k = self.miss_count
        if k:
            d = np.hypot(self.miss_xy[:k, 0] - rx_xy[0], self.miss_xy[:k, 1] - rx_xy[1])
            c = int(np.argmin(d))
            if d[c] < CELL_M:
                self.miss_n[c] += 1.0
                self.miss_t[c] = t_s
                return
        if k >= self.miss_n.shape[0]:
            self.miss_xy, self.miss_n, self.miss_t = _grown(k, self.miss_xy, self.miss_n,
                                                            self.miss_t)
        self.miss_xy[k] = rx_xy[:2]
        self.miss_n[k], self.miss_t[k] = 1.0, t_s
        self.miss_count = k + 1

    def misses_near(self, t_s: float, rx_xy: FloatArray, distance_m: float) -> float:
        """K: the earlier misses that share a new pulse's shadowing, each counted by its
        correlation with it, sum n_j exp(-d_j / L)."""
        k = self.miss_count
        if k == 0:
            return 0.0
        d = np.hypot(self.miss_xy[:k, 0] - rx_xy[0], self.miss_xy[:k, 1] - rx_xy[1])
        w = np.exp(-d / distance_m) * self.miss_n[:k]
        if math.isfinite(self.horizon_s):
            w = np.where(self.miss_t[:k] >= t_s - self.horizon_s, w, 0.0)
        return float(w.sum())

    def neighbours(self, t_s: float, rx_xy: FloatArray, distance_m: float
                   ) -> tuple[NDArray[np.intp], FloatArray]:
        """Indices of the m nearest usable cells and their distances to rx."""
        k = self.count
        if k == 0:
            return np.empty(0, np.intp), np.empty(0)
        d = np.hypot(self.poses[:k, 0] - rx_xy[0], self.poses[:k, 1] - rx_xy[1])
        ok = d < -distance_m * math.log(_MIN_CORRELATION)
        if math.isfinite(self.horizon_s):
            ok &= self.t_s[:k] >= t_s - self.horizon_s
        idx = np.flatnonzero(ok)
        if idx.size > SHADOW_NEIGHBOURS:
            idx = idx[np.argpartition(d[idx], SHADOW_NEIGHBOURS)[:SHADOW_NEIGHBOURS]]
        return idx, d[idx]


def _grown(k: int, *arrays: FloatArray) -> tuple[FloatArray, ...]:
    """The memory's arrays (first axis k, full) grown to max(64, 2k) rows of zeros after k."""
    size = max(64, 2 * k)
    return tuple(np.concatenate([a, np.zeros((size - k, *a.shape[1:]))]) for a in arrays)


def shadow_conditioning(memory: ShadowMemory, idx: NDArray[np.intp], d_new: FloatArray,
                        shadow_var: FloatArray, noise_var: FloatArray, distance_m: float
                        ) -> tuple[FloatArray, FloatArray]:
    """(beta (L, m), r^2 (L,)) of a new detection given the mean powers of cells ``idx``
    (m,) at distances d_new (m,) from it, for L hypotheses of the shadowing and noise
    variances ``shadow_var``, ``noise_var`` (L,) each (a cell of n pulses has noise R / n)."""
    return _condition(np.ascontiguousarray(memory.poses[idx, :2]),
                      np.ascontiguousarray(memory.n[idx]), np.ascontiguousarray(d_new),
                      np.ascontiguousarray(shadow_var, dtype=np.float64),
                      np.ascontiguousarray(noise_var, dtype=np.float64), distance_m)


@kernel
def _condition(cells_xy: FloatArray, n_pulses: FloatArray, d_new: FloatArray,
               shadow_var: FloatArray, noise_var: FloatArray, distance_m: float
               ) -> tuple[FloatArray, FloatArray]:
    """beta = (C + R diag(1 / n))^-1 c and r^2 = s + R - c' beta per hypothesis (see the
    module; C = s exp(-|u_i - u_j| / L), c = s exp(-d_new / L)), by Cholesky: C + R / n is
    symmetric positive definite (an exponential covariance plus a positive diagonal)."""
    m = cells_xy.shape[0]
    n_levels = shadow_var.shape[0]
    beta = np.zeros((n_levels, m))
    r2 = shadow_var + noise_var
    corr = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            dx = cells_xy[i, 0] - cells_xy[j, 0]
            dy = cells_xy[i, 1] - cells_xy[j, 1]
            corr[i, j] = math.exp(-math.sqrt(dx * dx + dy * dy) / distance_m)
    chol = np.empty((m, m))
    y = np.empty(m)
    for lev in range(n_levels):
        sv = shadow_var[lev]
        if m == 0 or sv <= 0.0:
            continue
        for i in range(m):  # lower Cholesky factor of C + R / n
            for j in range(i + 1):
                acc = sv * corr[i, j] + (noise_var[lev] / n_pulses[i] if i == j else 0.0)
                for k in range(j):
                    acc -= chol[i, k] * chol[j, k]
                chol[i, j] = math.sqrt(acc) if i == j else acc / chol[j, j]
        for i in range(m):  # forward: chol y = c
            acc = sv * math.exp(-d_new[i] / distance_m)
            for k in range(i):
                acc -= chol[i, k] * y[k]
            y[i] = acc / chol[i, i]
        quad = 0.0
        for i in range(m - 1, -1, -1):  # back: chol' beta = y; c' beta = y' y
            acc = y[i]
            for k in range(i + 1, m):
                acc -= chol[k, i] * beta[lev, k]
            beta[lev, i] = acc / chol[i, i]
            quad += y[i] * y[i]
        r2[lev] = max(sv + noise_var[lev] - quad, 1e-9)
    return beta, r2


@dataclass(frozen=True, slots=True, eq=False)
class PulseNoise:
    """What one more pulse at a receiver position would tell the planner, given what the
    filter has heard (its :class:`ShadowMemory`) under its most likely roughness level.

    A pulse at ``u`` will be conditioned on the memory's nearest cells, as the filter
    conditions it: its power enters as ``z~ = z - sum beta_j z_j`` with variance ``r^2``, so a
    candidate tag position ``x`` predicts ``P(x, u) - sum beta_j P(x, u_j)``. The planner
    takes the neighbours' part at their beta-weighted centroid ``u_c``::

        P~(x, u) = P(x, u) - c P(x, u_c),   c = sum beta_j,   noise variance r^2(u)

    Far from every cell ``c = 0`` and ``r^2 = sigma_s^2 + R`` (shadowing, receiver noise and
    model error); where the filter has listened the pulse repeats what it heard (``u_c`` near
    ``u``, c near 1: the difference it makes between candidate positions vanishes), while a
    pass beside earlier ones, near the tag where the power changes fast, still tells.
    """

    cells_xy: FloatArray
    """(K, 2) east, north of the cells the filter conditions on."""
    n_pulses: FloatArray
    """(K,) pulses per cell."""
    shadow_var: float
    noise_var: float
    """R: receiver noise plus model error variance, dB^2."""
    distance_m: float

    def __post_init__(self) -> None:
        order = np.argsort(self.cells_xy[:, 0], kind="stable") if self.cells_xy.size else None
        if order is not None:  # sorted east to west: each position scans a band of cells
            object.__setattr__(self, "cells_xy", np.ascontiguousarray(self.cells_xy[order]))
            object.__setattr__(self, "n_pulses", np.ascontiguousarray(self.n_pulses[order]))

    def conditioning(self, rx_xy: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(r^2 (...), c (...), u_c (..., 2)) of a pulse at each receiver position rx_xy
        (..., 2); u_c is rx where c = 0."""
        shape = np.shape(rx_xy)[:-1]
        flat = np.ascontiguousarray(np.asarray(rx_xy, dtype=np.float64).reshape(-1, 2))
        r2, c, centre = _pulse_conditioning(self.cells_xy, self.n_pulses, flat, self.shadow_var,
                                            self.noise_var, self.distance_m, SHADOW_NEIGHBOURS)
        return r2.reshape(shape), c.reshape(shape), centre.reshape(*shape, 2)


@kernel
def _pulse_conditioning(cells_xy: FloatArray, n_pulses: FloatArray, rx_xy: FloatArray,
                        shadow_var: float, noise_var: float, distance_m: float, m: int
                        ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(r^2, c, u_c) of :class:`PulseNoise` at P positions rx_xy (P, 2) from cells sorted by
    east: the m nearest within the correlation cut-off of each (a band of cells by east,
    an insertion list by distance), then :func:`_condition`."""
    n_cells = cells_xy.shape[0]
    r2_out = np.full(rx_xy.shape[0], shadow_var + noise_var)
    c_out = np.zeros(rx_xy.shape[0])
    centre = rx_xy.copy()
    if shadow_var <= 0.0 or n_cells == 0 or m <= 0:
        return r2_out, c_out, centre
    cutoff = -distance_m * math.log(_MIN_CORRELATION)
    east = np.ascontiguousarray(cells_xy[:, 0])
    sv = np.array([shadow_var])
    nv = np.array([noise_var])
    best_d = np.empty(m)
    best_i = np.empty(m, np.intp)
    for p in range(rx_xy.shape[0]):
        x, y = rx_xy[p, 0], rx_xy[p, 1]
        count = 0
        for k in range(np.searchsorted(east, x - cutoff), np.searchsorted(east, x + cutoff)):
            dx = cells_xy[k, 0] - x
            dy = cells_xy[k, 1] - y
            d = np.sqrt(dx * dx + dy * dy)
            if d >= cutoff or (count == m and d >= best_d[m - 1]):
                continue
            j = min(count, m - 1)  # insert, dropping the farthest when full
            while j > 0 and best_d[j - 1] > d:
                best_d[j] = best_d[j - 1]
                best_i[j] = best_i[j - 1]
                j -= 1
            best_d[j] = d
            best_i[j] = k
            count = min(count + 1, m)
        if count == 0:
            continue
        idx = best_i[:count]
        beta, r2 = _condition(cells_xy[idx], n_pulses[idx], best_d[:count].copy(), sv, nv,
                              distance_m)
        c = np.sum(beta[0])
        r2_out[p] = r2[0]
        if abs(c) > 1e-9:  # else no neighbours' part (and no centroid to speak of)
            c_out[p] = c
            cx = 0.0
            cy = 0.0
            for j in range(count):
                cx += beta[0, j] * cells_xy[idx[j], 0]
                cy += beta[0, j] * cells_xy[idx[j], 1]
            centre[p, 0] = cx / c
            centre[p, 1] = cy / c
    return r2_out, c_out, centre
