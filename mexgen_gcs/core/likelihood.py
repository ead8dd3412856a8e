"""The planner's detection model, tabulated: ``log pD``, ``log(1 - pD)`` and what the
compiled rollout step (:mod:`core.rollout_kernels`) reads of them.

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

_TABLE_HALF_WIDTH = 40.0
"""The table covers sensitivity +- this many detection spreads."""
_TABLE_STEP = 0.0025
"""Table step in detection spreads."""
LOG_FLOOR = -1.0e4
"""Floor of the tabulated logs, so that pD = 0 or pD = 1 never produces -inf (and no NaN)."""


class TableArrays(NamedTuple):
    """A detection table's arrays as the planner's kernels read them (float32, K entries)."""

    log_pd: Float32Array
    """(K,) log pD."""
    update: Float32Array
    """(3, K): log(1 - pD) - log pD, 1 - pD, (1 - pD)^alpha."""


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
    _arrays: dict[float, TableArrays] = field(init=False, repr=False)

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
        object.__setattr__(self, "_arrays", {})

    @property
    def inv_step(self) -> float:
        """Table entries per dB: entry = floor(P * inv_step + offset), clipped to the table."""
        return self._inv_step

    @property
    def offset(self) -> float:
        return self._offset

    def arrays(self, alpha: float) -> TableArrays:
        """The tables the planner's kernels read (built once per alpha, ~1 ms)."""
        arrays = self._arrays.get(alpha)
        if arrays is None:
            with np.errstate(under="ignore"):
                miss_pow = np.exp(alpha * self._log_miss_exact).astype(np.float32)
            arrays = TableArrays(self._log_pd, np.stack([self._log_gap, self._miss, miss_pow]))
            self._arrays[alpha] = arrays
        return arrays

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
