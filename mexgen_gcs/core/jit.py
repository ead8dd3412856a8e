"""The one place the compiled kernels are configured (numba; no frames or units here).

The filter's and the planner's hot loops are written once, as plain Python over arrays, and
compiled by numba's ``njit`` on first use: ahead-of-time compilation would need a compiler on
the user's machine, and numba ships as wheels. Compiled code is cached on disk (``cache=True``),
so only the first run on a machine pays the compile.

Where: ``<NUMBA_CACHE_DIR or ~/.cache/mexgen-gcs/numba>/<key>``, the key a hash of every
source file of ``core/`` and numba's version (:func:`cache_key`). Numba checks a cached kernel
against its own file only, so a change to a helper it inlines from another file (say
``core.radio.distance2_and_gain`` in the planner's kernels) would otherwise leave the old
machine code in use; with the key any change to ``core/`` starts a fresh cache. Set here, at
import, before any kernel is decorated (numba reads the location then).

Errors follow numpy, not Python (``error_model="numpy"``): a division by zero gives an
infinity or NaN instead of raising, so numba inserts no check into a loop and LLVM can
vectorise it (with the check, one division made the planner's power grid eight times slower).
For the same reason kernels take square roots with ``np.sqrt`` (an LLVM intrinsic), not
``math.sqrt`` (a call into libm in numba, which stops a loop from vectorising: 3x slower
for the filter's geometry).

Floating-point flags: the kernels may re-associate sums (so reductions vectorise), contract
multiply-adds and use approximate reciprocals and functions, but they keep IEEE infinities
and NaN semantics, because log-weights of impossible particles are ``-inf`` by design.

Random draws: a kernel that draws takes the caller's ``numpy.random.Generator`` as an
argument (numba compiles its methods against the same bit generator), so a run stays
reproducible by seed and draws from the one stream the caller owns.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numba
import numpy as np
from numpy.typing import NDArray

F = TypeVar("F", bound=Callable[..., Any])



def cache_key(source_dir: Path = Path(__file__).parent) -> str:
    """A hash of every ``*.py`` in ``source_dir`` (name and content) and numba's version."""
    h = hashlib.sha256(numba.__version__.encode())
    for path in sorted(source_dir.glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def cache_dir(key: str | None = None) -> Path:
    """The kernel cache of this source: ``NUMBA_CACHE_DIR`` (or the user's cache) / key."""
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"),
        "mexgen-gcs", "numba")
    return Path(base) / (key or cache_key())


numba.config.CACHE_DIR = str(cache_dir())  # type: ignore[attr-defined]

FASTMATH: frozenset[str] = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})
"""LLVM fast-math flags of every kernel: not ``nnan``/``ninf`` (see the module docstring)."""


def kernel(fn: F) -> F:
    """Compile ``fn`` as a cached, GIL-free numba kernel (typed as the Python function)."""
    return cast(F, numba.njit(cache=True, nogil=True, fastmath=set(FASTMATH),
                              error_model="numpy")(fn))


def inline(fn: F) -> F:
    """A helper that kernels call: compiled and inlined into its callers, never cached on
    its own."""
    return cast(F, numba.njit(inline="always", nogil=True, fastmath=set(FASTMATH),
                             error_model="numpy")(fn))


# -- float32 exp and log that vectorise ----------------------------------------------------
# numba calls libm for math.exp and math.log, one element at a time (~2-3 ns each here);
# these are the Cephes single-precision polynomials (S. L. Moshier, "Methods and Programs
# for Mathematical Functions", 1989: expf, logf), written in operations LLVM vectorises, so a
# kernel's loop runs at numpy's SIMD speed. Error: within 2e-7 relative of float64 (tested
# in tests/core/test_rollout_kernels.py), i.e. float32 rounding.

_F = np.float32


@inline
def exp32(x: np.float32) -> np.float32:
    """exp(x) in float32; exactly 0 below -87.3 (also for -inf), where float32 underflows."""
    xc = min(max(x, _F(-87.3)), _F(88.3))
    n = math.floor(xc * _F(1.44269504088896341) + _F(0.5))
    r = xc - n * _F(0.693359375) - n * _F(-2.12194440e-4)
    p = (((((_F(1.9875691500e-4) * r + _F(1.3981999507e-3)) * r + _F(8.3334519073e-3)) * r
           + _F(4.1665795894e-2)) * r + _F(1.6666665459e-1)) * r
         + _F(5.0000001201e-1)) * r * r + r + _F(1.0)
    scale = np.int32((np.int32(n) + np.int32(127)) << np.int32(23)).view(np.float32)
    return _F(0.0) if x < _F(-87.3) else p * scale


@inline
def log32(x: np.float32) -> np.float32:
    """log(x) in float32 for finite x > 0 (normal numbers; no check)."""
    bits = np.float32(x).view(np.int32)
    e = np.int32((bits >> np.int32(23)) & np.int32(0xFF)) - np.int32(126)
    m = np.int32((bits & np.int32(0x007FFFFF)) | np.int32(0x3F000000)).view(np.float32)
    if m < _F(0.707106781186547524):  # mantissa in [sqrt(1/2), sqrt(2)) - 1
        e -= np.int32(1)
        m = m + m - _F(1.0)
    else:
        m = m - _F(1.0)
    z = m * m
    y = ((((((((_F(7.0376836292e-2) * m - _F(1.1514610310e-1)) * m + _F(1.1676998740e-1)) * m
              - _F(1.2420140846e-1)) * m + _F(1.4249322787e-1)) * m - _F(1.6668057665e-1)) * m
           + _F(2.0000714765e-1)) * m - _F(2.4999993993e-1)) * m + _F(3.3333331174e-1)) * m * z
    fe = _F(e)
    y += _F(-2.12194440e-4) * fe - _F(0.5) * z
    return m + y + _F(0.693359375) * fe


LANES = 16
"""Partial results a reduction keeps side by side (one AVX-512 register of float32)."""


@inline
def max_lanes(x: NDArray[Any], lanes: NDArray[Any]) -> Any:
    """max(x) of a 1-D float array (-inf if empty; NaN-free input). A running maximum is a
    chain LLVM does not vectorise (3 times slower here); ``lanes`` (LANES,) scratch of x's
    dtype holds 16 running maxima side by side, which it does."""
    n = x.shape[0]
    lanes[:] = -np.inf
    full = n - n % LANES
    for i in range(0, full, LANES):
        for j in range(LANES):
            v = x[i + j]
            lanes[j] = v if v > lanes[j] else lanes[j]
    m = lanes[0]
    for j in range(1, LANES):
        m = lanes[j] if lanes[j] > m else m
    for i in range(full, n):
        m = x[i] if x[i] > m else m
    return m


@inline
def exp64(x: float) -> float:
    """exp(x) in float64 in operations that vectorise, within 1e-13 relative (the kernels'
    fast-math flags may re-associate the range reduction); exactly 0 below -708 (also for
    -inf), +inf above 709.7 (the float64 range)."""
    xc = min(max(x, -708.0), 709.7)
    n = math.floor(xc * 1.4426950408889634 + 0.5)
    r = xc - n * 0.6931471803691238 - n * 1.9082149292705877e-10  # ln 2 in two parts
    # Taylor to r^12 on |r| <= ln(2) / 2: truncation below 2e-17
    p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (
        1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0 + r * (1.0 / 40320.0 + r * (
            1.0 / 362880.0 + r * (1.0 / 3628800.0 + r * (1.0 / 39916800.0 + r * (
                1.0 / 479001600.0))))))))))))
    scale = np.int64((np.int64(n) + np.int64(1023)) << np.int64(52)).view(np.float64)
    if x < -708.0:
        return 0.0
    return math.inf if x > 709.7 else p * scale


@inline
def log64(x: float) -> float:
    """log(x) in float64 for finite normal x > 0 (no check), within 1e-15 relative, in
    operations that vectorise: x = m 2^e with m in [sqrt(1/2), sqrt(2)),
    log m = 2 atanh((m - 1) / (m + 1))."""
    bits = np.float64(x).view(np.int64)
    e = ((bits >> np.int64(52)) & np.int64(0x7FF)) - np.int64(1022)
    m = np.int64((bits & np.int64(0x000FFFFFFFFFFFFF)) | np.int64(0x3FE0000000000000)
                 ).view(np.float64)  # [0.5, 1)
    if m < 0.7071067811865476:
        m += m
        e -= np.int64(1)
    s = (m - 1.0) / (m + 1.0)  # |s| <= 0.172
    s2 = s * s
    # 2 atanh(s) = 2 (s + s^3/3 + ...), to s^23: truncation below 1e-18
    t = 2.0 + s2 * (2.0 / 3.0 + s2 * (2.0 / 5.0 + s2 * (2.0 / 7.0 + s2 * (2.0 / 9.0 + s2 * (
        2.0 / 11.0 + s2 * (2.0 / 13.0 + s2 * (2.0 / 15.0 + s2 * (2.0 / 17.0 + s2 * (
            2.0 / 19.0 + s2 * (2.0 / 21.0 + s2 * (2.0 / 23.0)))))))))))
    return s * t + np.float64(e) * 0.6931471805599453
