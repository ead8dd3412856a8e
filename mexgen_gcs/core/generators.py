"""Measurement generators: PIM, MexGen-M and MC-M (paper sections 2.2 and 3).

Frame: local ENU metres; measurements are received powers in dB.

One role, one signature: ``generate(view, rng) -> GeneratedMeasurement``. A generator sees the
predicted belief of a batch of rows (a row is one tag x action x rollout of the planner) through
a :class:`BeliefView`, and returns for each row the power ``z_db`` it predicts should the pulse
be detected, and its prediction ``p_detect`` of the probability that the pulse is detected at
all. The planner weighs the two outcomes, detected (updated with z) and missed, by ``p_detect``
(:mod:`core.rollout`). The three generators differ only in how they predict:

- PIM (predicted ideal measurement): the noiseless power at the belief's weighted mean
  position; ``p_detect`` = pD at that power (the point estimate, again).
- MexGen-M (measurement expectation): M states sampled from the weighted belief, a noisy
  measurement and a Bernoulli(pD) detection draw for each; z = the mean of the detected
  samples' noisy powers (the expected measurement given a detection); ``p_detect`` = the mean
  detection over the samples. With the stratified sampler (default) that mean is taken
  exactly, ``sum w pD / sum w`` (the limit of the sample fraction, which costs nothing extra);
  with independent samples it is the fraction detected. The mean of k noisy measurements is
  drawn as (mean of the k noiseless powers) + N(0, R / k), which has exactly the distribution
  of the mean of k independent noisy draws and costs one normal per row.
- MC-M (Monte Carlo): the planner runs M independent rollouts (``rollouts = M``); each row gets
  one sampled state, one noisy measurement of it and one Bernoulli(pD) detection draw, so
  ``p_detect`` is its sampled outcome, 0 or 1.

Measurement functions are injected through the view (``power_db`` and ``log_pd`` per particle,
``mean_power`` and ``detection_probability`` at arbitrary positions), so the generators can be
checked against a linear model as well as the radio model.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import exp32, kernel
from mexgen_gcs.core.particle_sampling import iid_indices, row_counts
from mexgen_gcs.core.workspace import Workspace

_F = np.float32

FloatArray = NDArray[np.floating]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


class Method(enum.StrEnum):
    """The planner's measurement generators, defined here once; the values are the names in
    mission files, command lines and logs (a member equals its value as a string)."""

    MEXGEN = "mexgen"
    """MexGen-M: M samples of the measurement's distribution, stratified over the belief."""
    PIM = "pim"
    """The predicted ideal measurement at the mean state."""
    MC = "mc"
    """MC-M: Monte Carlo rollouts, one sampled state and measurement each."""


METHODS: tuple[str, ...] = tuple(m.value for m in Method)
"""The method names, in the order menus and tables show them."""


def method_name(name: str) -> Method:
    """``name`` as a Method; ValueError naming the choices if it is not one."""
    try:
        return Method(name)
    except ValueError:
        raise ValueError(f"unknown planner method {name!r}; expected one of "
                         f"{', '.join(METHODS)}") from None



@dataclass(frozen=True, slots=True)
class BeliefView:
    """The predicted belief of a batch of rows as the generators see it at one step.

    Shapes: B = batch (e.g. (T, A, R) tags x actions x rollouts), N = particles; arrays with
    fewer leading dimensions broadcast against B.
    """

    weights: FloatArray
    """(B..., N) particle weights of the predicted belief per row: non-negative with a positive
    row sum, not necessarily normalised."""
    positions_m: FloatArray
    """(..., N, 2) particle positions (east, north), broadcasting against the rows."""
    power_db: FloatArray
    """(..., N) noiseless measurement of every particle from the row's receiver pose."""
    log_pd: FloatArray
    """(..., N) log detection probability of every particle (log pD(power_db))."""
    mean_power: Callable[[FloatArray], FloatArray]
    """Noiseless measurement at positions (B..., 2) from each row's receiver pose -> (B...)."""
    detection_probability: Callable[[FloatArray], FloatArray]
    """pD of noiseless measurements, elementwise."""
    noise_std_db: float
    """Standard deviation of the measurement noise (sqrt R)."""
    scratch: Workspace | None = None
    """Buffers a generator may use for its temporaries (the planner's workspace)."""


@dataclass(frozen=True, slots=True)
class GeneratedMeasurement:
    """One generated measurement per row."""

    z_db: NDArray[np.float32]
    """(B...) the measurement should the pulse be detected (finite everywhere; not used where
    ``p_detect`` is 0)."""
    p_detect: NDArray[np.float32]
    """(B...) predicted probability that the pulse is detected, in [0, 1] (MC: its sampled
    outcome, exactly 0 or 1)."""


class MeasurementGenerator(Protocol):
    """The measurement-generator role. ``rollouts`` is the number of independent rollouts the
    planner must run per action for this generator (1 unless it is Monte Carlo)."""

    @property
    def name(self) -> str: ...

    @property
    def rollouts(self) -> int: ...

    def generate(self, view: BeliefView, rng: np.random.Generator) -> GeneratedMeasurement: ...


@dataclass(frozen=True, slots=True)
class PredictedIdealMeasurement:
    """PIM: noiseless measurement of the weighted mean position. Deterministic (rng unused)."""

    name: ClassVar[str] = "pim"
    rollouts: ClassVar[int] = 1

    def generate(self, view: BeliefView, rng: np.random.Generator) -> GeneratedMeasurement:
        """O(B N) for the mean (one matrix product), O(B) for the measurement."""
        w = np.asarray(view.weights)
        pos = np.asarray(view.positions_m)
        n = w.shape[-1]
        per_tag = pos.ndim == w.ndim + 1 and pos.shape[0] == w.shape[0]
        if per_tag and math.prod(pos.shape[1:-2]) == 1:
            # positions shared by every row of a leading (tag) index: one product per tag
            sums = np.matmul(w.reshape(w.shape[0], -1, n), pos.reshape(pos.shape[0], n, 2))
            sums = sums.reshape(*w.shape[:-1], 2)
        else:
            sums = np.matmul(w[..., None, :], pos)[..., 0, :]
        mean_xy = sums / w.sum(axis=-1, dtype=np.float32)[..., None]
        z = np.asarray(view.mean_power(mean_xy), dtype=np.float32)
        p = np.asarray(view.detection_probability(z), dtype=np.float32)
        return GeneratedMeasurement(z_db=z, p_detect=p)


@dataclass(frozen=True, slots=True)
class MexGen:
    """MexGen-M: the expectation of M sampled noisy measurements (paper default M = 512).

    Each of the M samples is a (particle, detected?) pair: a particle drawn from the weights
    and a detection drawn with its pD. ``stratified`` (default) draws the M pairs with one
    uniform per stratum over the joint distribution (mass w_i pD_i for "particle i, detected",
    the rest for "missed"): no search, O(N + M) per row, and a sample mean with variance no
    larger than independent draws give, so the paper's error bound holds as stated. With
    ``stratified=False`` the M pairs are independent draws, as in the paper's description.
    """

    samples: int = 512
    stratified: bool = True
    name: ClassVar[str] = "mexgen"
    rollouts: ClassVar[int] = 1

    def __post_init__(self) -> None:
        if self.samples < 1:
            raise ValueError(f"MexGen needs at least 1 sample (got {self.samples})")

    def generate(self, view: BeliefView, rng: np.random.Generator) -> GeneratedMeasurement:
        """O(B N) plus O(B M) (stratified) or O(B M log N) (independent)."""
        w = np.asarray(view.weights)
        batch, m = w.shape[:-1], self.samples
        if self.stratified:
            z = np.empty(batch, np.float32)
            p = np.empty(batch, np.float32)
            rows = z.size
            # drawn here rather than in the kernel: the same numbers, without numba's
            # ~5 us of unboxing a Generator on every call (20 calls a plan)
            u = rng.random(rows * m, dtype=np.float32)
            noise = rng.standard_normal(rows)
            _stratified_measure(_rows32(w, w.shape), _rows32(view.power_db, w.shape),
                                _rows32(view.log_pd, w.shape), m, view.noise_std_db, u, noise,
                                z.reshape(-1), p.reshape(-1))
            return GeneratedMeasurement(z_db=z, p_detect=p)
        idx = iid_indices(w, m, rng)  # (B..., M)
        sampled, log_pd = take_rows((view.power_db, view.log_pd), idx)
        pd = np.exp(log_pd)
        hit = rng.random(idx.shape, dtype=np.float32) < pd
        n_hit = np.count_nonzero(hit, axis=-1)
        total = np.where(hit, sampled, 0.0).sum(axis=-1, dtype=np.float64)
        fallback = sampled.mean(axis=-1, dtype=np.float64)
        p_detect = n_hit / np.float32(m)
        # Where no sample is detected (p_detect below ~1/M) z is the mean over every sample:
        # finite, and weighted by that small p_detect in the planner.
        k = np.maximum(n_hit, 1)
        mean = np.where(n_hit > 0, total / k, fallback)
        noise = rng.standard_normal(batch) * (view.noise_std_db / np.sqrt(k))
        return GeneratedMeasurement(z_db=(mean + noise).astype(np.float32),
                                    p_detect=np.clip(p_detect, 0.0, 1.0).astype(np.float32))


@dataclass(frozen=True, slots=True)
class MonteCarlo:
    """MC-M: M rollouts per action, each with one noisy measurement of one sampled state."""

    rollouts: int = 8
    name: ClassVar[str] = "mc"

    def __post_init__(self) -> None:
        if self.rollouts < 1:
            raise ValueError(f"MC needs at least 1 rollout (got {self.rollouts})")

    def generate(self, view: BeliefView, rng: np.random.Generator) -> GeneratedMeasurement:
        """O(B N) for the block sums, O(B) for the draws."""
        w = np.asarray(view.weights)
        idx = iid_indices(w, 1, rng)  # (B..., 1)
        power, log_pd = (g[..., 0] for g in take_rows((view.power_db, view.log_pd), idx))
        detected = rng.random(power.shape, dtype=np.float32) < np.exp(log_pd)
        noise = rng.standard_normal(power.shape) * view.noise_std_db
        return GeneratedMeasurement(z_db=(power + noise).astype(np.float32),
                                    p_detect=detected.astype(np.float32))


def _rows32(a: FloatArray, shape: tuple[int, ...]) -> NDArray[np.float32]:
    """``a`` broadcast to ``shape`` as contiguous float32 rows (rows, N): a view when it
    already is one (the planner's grids), else a copy."""
    arr = np.asarray(a)
    if arr.shape == shape and arr.dtype == np.float32 and arr.flags.c_contiguous:
        return arr.reshape(-1, shape[-1])  # the planner's case, without broadcast_to's ~2 us
    b = np.broadcast_to(arr, shape)
    return np.ascontiguousarray(b, dtype=np.float32).reshape(-1, shape[-1])


@kernel
def _stratified_measure(w: NDArray[np.float32], power: NDArray[np.float32],
                        log_pd: NDArray[np.float32], m: int, noise_std_db: float,
                        u: NDArray[np.float32], noise: NDArray[np.float64],
                        z: NDArray[np.float32], p_detect: NDArray[np.float32]) -> None:
    """MexGen's stratified measurement of each row (see :class:`MexGen`), into z, p_detect
    (rows,): w, power, log_pd (rows, N); u (rows M,) M uniforms per row (one per stratum),
    noise (rows,) one standard normal per row. The M (particle, detected?)
    pairs come from the joint mass w_i pD_i ("detected") and the rest ("missed") through
    :func:`core.particle_sampling.row_counts`. O(N + M) per row.
    """
    rows, n = w.shape
    mass = np.empty(n, np.float32)
    counts = np.empty(n, np.float32)
    for r in range(rows):
        w_total = _F(0.0)
        mass_total = _F(0.0)
        w_power = _F(0.0)
        for i in range(n):
            wi = w[r, i]
            mi = wi * exp32(log_pd[r, i])
            mass[i] = mi
            w_total += wi
            mass_total += mi
            w_power += wi * power[r, i]
        row_counts(mass, m / w_total, u[r * m:(r + 1) * m], counts)
        hit_power = _F(0.0)
        n_hit = _F(0.0)
        for i in range(n):
            hit_power += counts[i] * power[r, i]
            n_hit += counts[i]
        # where no sample is detected (p_detect below ~1/M) z is the mean over every sample:
        # finite, and weighted by that small p_detect in the planner
        k = max(n_hit, _F(1.0))
        mean = hit_power / k if n_hit > _F(0.0) else w_power / w_total
        z[r] = mean + noise[r] * (noise_std_db / np.sqrt(k))
        p_detect[r] = min(max(mass_total / w_total, _F(0.0)), _F(1.0))


def take_rows(
    grids: tuple[FloatArray, ...], idx: IntArray
) -> tuple[FloatArray, ...]:
    """``grid[row, idx]`` for each grid and each row: grids (B'..., N) of one shape broadcasting
    to the rows B of idx (B..., k); returns arrays (B..., k). Indexes the un-broadcast grids
    directly (no copy of a broadcast view). O(B k).
    """
    shape = np.shape(grids[0])
    n = shape[-1]
    owner = np.arange(math.prod(shape[:-1])).reshape(shape[:-1])
    flat = np.broadcast_to(owner, idx.shape[:-1])[..., None] * n + idx
    return tuple(np.asarray(g).reshape(-1)[flat] for g in grids)


def make_generator(
    method: Method | str, samples: int = 512, mc_rollouts: int = 8, stratified: bool = True
) -> MeasurementGenerator:
    """The generator for a planner method name: "pim" | "mexgen" (samples) | "mc" (rollouts)."""
    if method == Method.PIM:
        return PredictedIdealMeasurement()
    if method == Method.MEXGEN:
        return MexGen(samples, stratified)
    if method == Method.MC:
        return MonteCarlo(mc_rollouts)
    raise ValueError(f"unknown planner method {method!r}; expected pim, mexgen or mc")
