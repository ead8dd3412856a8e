"""The planner's measurement update on particles: tabulated detection model, likelihood of a
generated measurement, and the Bayes update of the weights.

Frame: local ENU metres (only received powers in dB appear here, no positions).

The rollout planner evaluates, at every look-ahead step, the likelihood of a generated
measurement for every particle and every action (and MC rollout). For a detection ``z``::

    L(x) = pD(P(x)) N(z; P(x), R)          (a missed detection: L(x) = 1 - pD(P(x)))

with ``pD(P) = pd_max Phi((P - sensitivity) / spread)`` from :class:`RadioModel`. Clutter is
not modelled in the rollout: a generated measurement is the tag's own. ``Phi`` through scipy
costs ~10 us per 1000 values, which would dominate a plan, so :class:`DetectionTable`
tabulates ``log pD`` and ``log(1 - pD)`` once per radio model on a fine grid (0.0025 spreads,
0.005 dB by default) and looks up the nearest entry: error < 0.01 in the log within 5 spreads
of the sensitivity, < 0.05 anywhere; powers beyond +-40 spreads are clamped (there log pD is
below -800 and no particle with such a power can matter).

Log-weights are handled "max-shifted": a row of log-weights ``l`` with ``max(l) = 0`` stands for
the normalised weights ``exp(l - log_total)``, ``log_total = log sum exp(l)``. Keeping the row
total aside instead of subtracting it saves a pass over the (rows, N) arrays per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from mexgen_gcs.core.radio import RadioModel

Float32Array = NDArray[np.float32]
IndexArray = NDArray[np.intp]
"""Table indices: numpy's take converts any other integer type to intp first (a copy)."""
BoolArray = NDArray[np.bool_]

_TABLE_HALF_WIDTH = 40.0
"""The table covers sensitivity +- this many detection spreads."""
_TABLE_STEP = 0.0025
"""Table step in detection spreads."""
LOG_FLOOR = -1.0e4
"""Floor of the tabulated logs, so that pD = 0 or pD = 1 never produces -inf (and no NaN)."""


@dataclass(frozen=True, eq=False)
class DetectionTable:
    """``log pD(P)``, ``log(1 - pD(P))``, ``pD(P)``, ``1 - pD(P)`` and ``(1 - pD(P))^alpha``
    for one :class:`RadioModel`, in float32.

    Build it with :func:`detection_table` (cached per radio model). All lookups take any shape
    of powers (dB) and return float32 of the same shape; cost ~5 passes over the input. A
    caller that needs several of them for the same powers computes the table :meth:`index`
    once (4 passes) and then ``take_*`` each (1 pass).
    """

    radio: RadioModel
    _offset: float = field(init=False)
    _inv_step: float = field(init=False)
    _log_pd: Float32Array = field(init=False, repr=False)
    _log_miss: Float32Array = field(init=False, repr=False)
    _log_gap: Float32Array = field(init=False, repr=False)
    _miss: Float32Array = field(init=False, repr=False)
    _log_miss_exact: NDArray[np.float64] = field(init=False, repr=False)
    _miss_pow: dict[float, Float32Array] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        r = self.radio
        n = round(2.0 * _TABLE_HALF_WIDTH / _TABLE_STEP) + 1
        x = np.linspace(-_TABLE_HALF_WIDTH, _TABLE_HALF_WIDTH, n)
        with np.errstate(divide="ignore"):
            log_pd_max = math.log(r.pd_max) if r.pd_max > 0.0 else -math.inf
            log_pd = log_pd_max + log_ndtr(x)
            # 1 - pd_max Phi(x) = (1 - pd_max) + pd_max Phi(-x): exact for pd_max up to 1.
            log_miss = np.logaddexp(np.log(1.0 - r.pd_max), log_pd_max + log_ndtr(-x))
        inv_step = 1.0 / (_TABLE_STEP * r.detection_spread_db)
        lo_db = r.sensitivity_db - _TABLE_HALF_WIDTH * r.detection_spread_db
        # index = round((P - lo) / step) = floor(P * inv_step + offset)
        object.__setattr__(self, "_offset", 0.5 - lo_db * inv_step)
        object.__setattr__(self, "_inv_step", inv_step)
        object.__setattr__(self, "_log_pd", np.maximum(log_pd, LOG_FLOOR).astype(np.float32))
        object.__setattr__(self, "_log_miss", np.maximum(log_miss, LOG_FLOOR).astype(np.float32))
        object.__setattr__(self, "_log_gap", self._log_miss - self._log_pd)
        # linear 1 - pD: exactly 0 (not the floor's e^-10000) where a miss is impossible
        object.__setattr__(self, "_miss", np.exp(log_miss).astype(np.float32))
        object.__setattr__(self, "_log_miss_exact", log_miss)
        object.__setattr__(self, "_miss_pow", {})

    def index(
        self, power_db: NDArray[np.floating],
        scratch: tuple[Float32Array, IndexArray] | None = None,
        bounded: bool = False,
    ) -> IndexArray:
        """The table entries of powers (dB), for the ``take_*`` lookups: (...) intp (written
        into ``scratch[1]`` if given, with ``scratch[0]`` a float32 temporary).

        ``bounded``: the caller guarantees finite powers within +-10^4 dB of the sensitivity
        (the planner's grid: at most ~100 dB from it), so the float-to-int conversion cannot
        overflow and the clip to the table happens in the ``take_*`` alone (one pass less).
        """
        if not bounded:
            return self._index(power_db, scratch)
        f = None if scratch is None else scratch[0]
        f = np.asarray(np.multiply(power_db, np.float32(self._inv_step), dtype=np.float32, out=f))
        f += np.float32(self._offset)
        if scratch is None:
            return f.astype(np.intp)  # truncation towards 0; take(mode="clip") clamps
        np.copyto(scratch[1], f, casting="unsafe")
        return scratch[1]

    def take_log_pd(self, index: IndexArray, out: Float32Array | None = None
                    ) -> Float32Array:
        """log pD (>= LOG_FLOOR) at table entries :meth:`index`."""
        return self._log_pd.take(index, out=out, mode="clip")

    def take_log_miss(self, index: IndexArray, out: Float32Array | None = None
                      ) -> Float32Array:
        """log(1 - pD) (>= LOG_FLOOR) at table entries :meth:`index`."""
        return self._log_miss.take(index, out=out, mode="clip")

    def take_log_miss_gap(self, index: IndexArray, out: Float32Array | None = None
                          ) -> Float32Array:
        """log(1 - pD) - log pD (both >= LOG_FLOOR) at table entries :meth:`index`."""
        return self._log_gap.take(index, out=out, mode="clip")

    def take_miss(self, index: IndexArray, out: Float32Array | None = None
                  ) -> Float32Array:
        """1 - pD at table entries :meth:`index`; exactly 0 where pD = 1 (pd_max = 1)."""
        return self._miss.take(index, out=out, mode="clip")

    def take_miss_pow(self, index: IndexArray, alpha: float,
                      out: Float32Array | None = None) -> Float32Array:
        """(1 - pD)^alpha at table entries :meth:`index` (the table for each alpha is built
        once, ~1 ms)."""
        table = self._miss_pow.get(alpha)
        if table is None:
            with np.errstate(under="ignore"):
                table = np.exp(alpha * self._log_miss_exact).astype(np.float32)
            self._miss_pow[alpha] = table
        return table.take(index, out=out, mode="clip")

    def _index(
        self, power_db: NDArray[np.floating], scratch: tuple[Float32Array, IndexArray] | None
    ) -> IndexArray:
        f = None if scratch is None else scratch[0]
        f = np.asarray(np.multiply(power_db, np.float32(self._inv_step), dtype=np.float32, out=f))
        f += np.float32(self._offset)
        np.clip(f, np.float32(0.0), np.float32(self._log_pd.size - 1), out=f)
        if scratch is None:
            return f.astype(np.intp)
        i = scratch[1]
        np.copyto(i, f, casting="unsafe")  # truncation = floor for f >= 0
        return i

    def log_pd(
        self,
        power_db: NDArray[np.floating],
        out: Float32Array | None = None,
        scratch: tuple[Float32Array, IndexArray] | None = None,
    ) -> Float32Array:
        """log pD(P) (>= LOG_FLOOR); (...) -> (...) float32, into ``out`` if given.
        ``scratch``: float32 and intp buffers shaped like the input (nothing is allocated)."""
        return self._log_pd.take(self._index(power_db, scratch), out=out, mode="clip")

    def log_miss(
        self,
        power_db: NDArray[np.floating],
        out: Float32Array | None = None,
        scratch: tuple[Float32Array, IndexArray] | None = None,
    ) -> Float32Array:
        """log(1 - pD(P)) (>= LOG_FLOOR); (...) -> (...) float32, into ``out`` if given."""
        return self._log_miss.take(self._index(power_db, scratch), out=out, mode="clip")

    def pd(self, power_db: NDArray[np.floating]) -> Float32Array:
        """pD(P) in [0, pd_max]; (...) -> (...) float32."""
        out = self.log_pd(power_db)
        np.exp(out, out=out)
        return out


@lru_cache(maxsize=16)
def detection_table(radio: RadioModel) -> DetectionTable:
    """The (cached) table of a radio model; building one costs ~1 ms."""
    return DetectionTable(radio)


def likelihood_coefficients(
    power_db: Float32Array, log_pd: Float32Array, noise_var_db2: float,
    out: Float32Array | None = None,
) -> Float32Array:
    """[2kP, log pD(P) - kP^2] with k = 1 / (2R): (..., N) grids -> (..., 2, N) float32.

    For a detection z, ``z * c[0] + c[1] = log pD(P) - (z - P)^2 / (2R) + k z^2``: the
    log-likelihood up to a per-row constant, linear in z.
    """
    k = np.float32(0.5 / noise_var_db2)
    if out is None:
        out = np.empty((*np.shape(power_db)[:-1], 2, np.shape(power_db)[-1]), dtype=np.float32)
    c1, c0 = out[..., 0, :], out[..., 1, :]
    np.multiply(power_db, 2.0 * k, out=c1)
    np.multiply(power_db, -k, out=c0)
    c0 *= power_db
    c0 += log_pd
    return out


def log_likelihood(
    z_db: NDArray[np.floating],
    detected: BoolArray,
    power_db: Float32Array,
    log_pd: Float32Array,
    table: DetectionTable,
    noise_var_db2: float,
    out: Float32Array | None = None,
    coef: Float32Array | None = None,
) -> Float32Array:
    """Log-likelihood of generated measurements for every particle, up to a constant per row.

    z_db, detected: (B...) one measurement per row (a row is tag x action x rollout);
    power_db, log_pd: (B'..., N) noiseless power of every particle and ``table.log_pd`` of it,
    B' broadcasting to B (e.g. one grid shared by all MC rollouts of an action).
    Returns (B..., N) float32 (written into ``out`` if given)::

        detected:  log pD(P) - (z - P)^2 / (2 R)   [+ a per-row constant, dropped]
        missed:    log(1 - pD(P))                   (looked up only for missed rows)

    The dropped constant (-log sqrt(2 pi R), and -z^2/2R on the shared-grid path) cancels when
    the weights are normalised and in the Renyi divergence. When the grid is shared by the rows
    along the last batch axis (B' = (..., 1), the planner's MC rollouts) the detection rows are
    one small matrix product ``[z, 1] @ coef`` per leading index, with ``coef`` (B'[:-1]..., 2,
    N) from :func:`likelihood_coefficients` (computed here unless given); otherwise four passes.
    Cost O(B N).
    """
    z = np.asarray(z_db, dtype=np.float32)
    det = np.asarray(detected, dtype=bool)
    batch = z.shape
    out_shape = (*batch, power_db.shape[-1])
    if out is None:
        out = np.empty(out_shape, dtype=np.float32)
    missed = None if det.all() else np.nonzero(~det)
    if missed is not None and missed[0].size == det.size:
        np.copyto(out, table.log_miss(power_db))
        return out
    shared = power_db.ndim == z.ndim + 1 and power_db.shape[-2] == 1 and batch[-1] > 1
    if coef is not None or shared:
        if coef is None:
            lp = np.broadcast_to(log_pd, power_db.shape)[..., 0, :]
            coef = likelihood_coefficients(power_db[..., 0, :], lp, noise_var_db2)
        zz = np.empty((*batch, 2), dtype=np.float32)
        zz[..., 0] = z
        zz[..., 1] = 1.0
        np.matmul(zz, coef, out=out)
    else:
        np.subtract(power_db, z[..., None], out=out)
        np.square(out, out=out)
        out *= np.float32(-0.5 / noise_var_db2)
        out += log_pd
    if missed is not None:  # only the missed rows' powers go through the table
        out[missed] = table.log_miss(np.broadcast_to(power_db, out_shape)[missed])
    return out


def pooled_log_likelihood(
    z_db: NDArray[np.floating],
    p_detect: NDArray[np.floating],
    power_db: Float32Array,
    log_pd: Float32Array,
    log_gap: Float32Array,
    noise_var_db2: float,
    out: Float32Array,
    scratch: Float32Array,
) -> Float32Array:
    """Log-likelihood of the expected outcome of a pulse detected with probability p::

        p [log pD(P) - (z - P)^2 / (2 R)] + (1 - p) log(1 - pD(P))
          = log pD(P) + (1 - p) gap(P) - p (z - P)^2 / (2 R),   gap = log(1 - pD) - log pD

    i.e. ``(pD N(z; P, R))^p (1 - pD)^(1 - p)`` up to a per-row constant: the detected
    likelihood at p = 1, the missed one at p = 0. z_db, p_detect: (B...) per row; power_db,
    log_pd, log_gap (``DetectionTable.take_log_miss_gap``): (B'..., N) broadcasting to the
    rows; ``out``, ``scratch``: (B..., N) float32. Six passes, no allocation of that size.
    """
    z = np.asarray(z_db, dtype=np.float32)[..., None]
    p = np.asarray(p_detect, dtype=np.float32)[..., None]
    np.subtract(power_db, z, out=out)
    np.square(out, out=out)
    out *= p * np.float32(-0.5 / noise_var_db2)
    out += log_pd
    np.multiply(log_gap, np.float32(1.0) - p, out=scratch)
    out += scratch
    return out


class Update(NamedTuple):
    """The weights of a batch of beliefs after a Bayes update (max-shifted, see the module)."""

    log_weights: Float32Array
    """(B..., N) log-weights with row maximum 0."""
    weights: Float32Array
    """(B..., N) exp(log_weights): row maximum 1, not normalised."""
    log_total: NDArray[np.float64]
    """(B...) log of the row sums of ``weights``; normalised = log_weights - log_total."""


def bayes_update(
    log_w: Float32Array, log_lik: Float32Array, out_weights: Float32Array | None = None
) -> Update:
    """Multiply weights by likelihoods, on the log scale.

    log_w: (B..., N) log-weights of the predicted belief (any per-row offset, a finite entry in
    each row); log_lik: (B..., N) log-likelihoods (any per-row constant cancels). ``log_lik``
    is overwritten with the new max-shifted log-weights and the linear weights go to
    ``out_weights`` if given, so a rollout allocates nothing per step. Rows where no particle
    has a finite likelihood (every entry -inf or NaN) keep their prior weights, so a
    measurement nothing explains never yields a NaN. Cost O(B N): one exp and 4 other passes.
    """
    a = log_lik
    a += log_w
    m = a.max(axis=-1, keepdims=True)
    if not np.isfinite(m.sum()):  # some row's likelihood is -inf or NaN everywhere
        rows = np.nonzero(~np.isfinite(m[..., 0]))
        a[rows] = np.broadcast_to(log_w, a.shape)[rows]
        m = a.max(axis=-1, keepdims=True)
    a -= m
    e = np.exp(a, out=out_weights)
    total = e.sum(axis=-1, dtype=np.float32).astype(np.float64)
    return Update(a, e, np.log(total))
