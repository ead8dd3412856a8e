"""Drawing particle indices from many weighted rows at once (used by the MexGen and MC
generators; a row is one tag x action x rollout of the planner).

No positions here, only weights. Two samplers, both vectorised over every row:

- :func:`stratified_counts` / :func:`stratified_indices`: n draws per row, one uniform in each
  stratum [j/n, (j+1)/n) pushed through the row's inverse CDF. Each particle's number of draws
  follows in closed form from the CDF (no search at all), so the cost is O(N + n) per row, in
  one compiled pass (:func:`row_counts`, which MexGen's kernel calls too). The
  draws are an unbiased sample of the row's distribution whose sample mean has a variance no
  larger than with independent draws (stratification with proportional allocation never
  increases it).
- :func:`iid_indices`: n independent draws per row by a two-level inverse CDF (blocks of 16
  particles, then the particle within the block).

Why not ``cumsum`` + ``searchsorted`` for the independent draws: numpy's cumsum runs ~3.5 ns
per element and a random binary search ~65 ns per query on this class of CPU (branch
mispredictions), which at 8 x 512 draws per look-ahead step would cost more than the rest of a
plan. Block sums come from one small float32 matrix product with an upper-triangular matrix
instead. Block CDFs are accumulated in float32 (relative error ~1e-6 at N = 20000, far below
any sampling error); the stratified counts sum each row in float64.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import inline, kernel
from mexgen_gcs.core.workspace import Workspace

FloatArray = NDArray[np.floating]
IntArray = NDArray[np.intp]

_BLOCK = 16
_UPPER = np.triu(np.ones((_BLOCK, _BLOCK), dtype=np.float32))
_ONES = np.ones(_BLOCK, dtype=np.float32)
_MATMUL_CUMSUM_MAX = 256
"""Block CDFs with up to this many blocks are accumulated by a matrix product too."""


_MATMUL_CHUNK_MACS = 1 << 19
"""OpenBLAS starts threads for products of about 2^20 multiply-adds and more; on a busy
two-core machine those threads made one block-CDF product 100x slower (8 ms instead of 80 us).
Products are therefore split along their rows into pieces that stay single-threaded."""


@lru_cache(maxsize=32)
def _upper(n: int) -> NDArray[np.float32]:
    return np.triu(np.ones((n, n), dtype=np.float32))


def _matmul_rows(
    a: NDArray[np.float32], b: NDArray[np.float32], out: NDArray[np.float32] | None = None
) -> NDArray[np.float32]:
    """a (M, K) @ b (K, N) in row chunks small enough for single-threaded BLAS."""
    m, k = a.shape
    if out is None:
        out = np.empty((m, b.shape[1]), dtype=np.float32)
    step = max(1, _MATMUL_CHUNK_MACS // max(1, k * b.shape[1]))
    for r0 in range(0, m, step):
        np.matmul(a[r0 : r0 + step], b, out=out[r0 : r0 + step])
    return out


def _rows(weights: FloatArray) -> tuple[tuple[int, ...], int, int, NDArray[np.float32]]:
    w = np.asarray(weights)
    if w.ndim < 1 or w.shape[-1] == 0:
        raise ValueError("weights need a non-empty last (particle) axis")
    batch, n = w.shape[:-1], w.shape[-1]
    rows = math.prod(batch)
    return batch, rows, n, np.ascontiguousarray(w.reshape(rows, n), dtype=np.float32)


def _blocks(w: NDArray[np.float32]) -> NDArray[np.float32]:
    """(rows, N) -> (rows, ceil(N / 16), 16); zero weights in the padding (a copy only then)."""
    rows, n = w.shape
    nb = -(-n // _BLOCK)
    if nb * _BLOCK != n:
        padded = np.zeros((rows, nb * _BLOCK), dtype=np.float32)
        padded[:, :n] = w
        w = padded
    return w.reshape(rows, nb, _BLOCK)


def _cdf32(w: NDArray[np.float32], scratch: Workspace | None = None) -> NDArray[np.float32]:
    """Un-normalised cumulative sums of (rows, N) float32 weights, (rows, N) float32."""
    rows, n = w.shape
    blocks = _blocks(w)
    nb = blocks.shape[1]
    out = None if scratch is None else scratch.get("sampling_cdf", (rows * nb, _BLOCK))
    cdf = _matmul_rows(blocks.reshape(rows * nb, _BLOCK), _UPPER, out).reshape(rows, nb, _BLOCK)
    starts = np.zeros((rows, nb), dtype=np.float32)
    np.cumsum(cdf[:, :-1, -1], axis=-1, out=starts[:, 1:])
    cdf += starts[:, :, None]
    return cdf.reshape(rows, nb * _BLOCK)[:, :n]


def row_cdf(weights: FloatArray, normalise: bool = True) -> NDArray[np.float64]:
    """Cumulative sums of each row of (rows, N) weights: float64 (rows, N). Normalised: the last
    column exactly 1 (every row needs a positive sum). O(rows N)."""
    _, _, _, w = _rows(weights)
    cdf = _cdf32(w).astype(np.float64)
    if normalise:
        cdf /= cdf[:, -1:]
    return cdf


def stratified_counts(
    mass: FloatArray,
    n_draws: int,
    rng: np.random.Generator,
    dtype: type[np.number] = np.int64,
    total: FloatArray | None = None,
    scratch: Workspace | None = None,
) -> NDArray[np.number]:
    """Stratified draws over each row's particles plus an implicit "none" outcome: counts.

    mass: (B..., N) non-negative; particle i has probability ``mass[..., i] / total`` (total:
    (B...), default 1, at least the row sum up to rounding), "none" the rest. One uniform U_j
    per stratum [j/n, (j+1)/n) goes through the inverse CDF; the number of draws below a CDF
    value x is ``k + [U_k < x n - k]`` with ``k = floor(x n)``, so particle i gets
    ``below(cdf_i) - below(cdf_(i-1))`` draws without any search (:func:`row_counts`).
    Returns (B..., N) counts as ``dtype``; row sums <= n_draws. O(N + n) per row.
    ``scratch``: a workspace for the (rows, N) result (valid until its next use).
    """
    if n_draws < 1:
        raise ValueError(f"n_draws must be >= 1 (got {n_draws})")
    batch, rows, n, m = _rows(mass)
    scale = np.full(rows, float(n_draws)) if total is None else (
        float(n_draws) / np.asarray(total, dtype=np.float64).reshape(rows))
    counts = np.empty((rows, n), np.float32) if scratch is None else scratch.get(
        "sampling_counts", (rows, n))
    u = rng.random(rows * n_draws, dtype=np.float32).reshape(rows, n_draws)
    _counts_kernel(m, scale, u, counts)
    return counts.reshape(*batch, n).astype(dtype, copy=False)


@inline
def row_counts(mass: NDArray[np.float32], scale: float | np.floating[Any],
               u: NDArray[np.float32],
               counts: NDArray[np.float32]) -> None:
    """One row of :func:`stratified_counts` in a kernel: mass (N,), ``scale`` = n_draws /
    total, u (n_draws,) one uniform per stratum; writes counts (N,). One pass, no search."""
    n_draws = u.shape[0]
    top = float(n_draws - 1)
    cum = 0.0
    prev = 0.0
    for i in range(mass.shape[0]):
        cum += mass[i]
        y = cum * scale
        k = math.floor(min(y, top))
        below = k + (1.0 if u[int(k)] < y - k else 0.0)
        counts[i] = below - prev
        prev = below


@kernel
def _counts_kernel(mass: NDArray[np.float32], scale: NDArray[np.float64],
                   u: NDArray[np.float32], counts: NDArray[np.float32]) -> None:
    for r in range(mass.shape[0]):
        row_counts(mass[r], scale[r], u[r], counts[r])


def stratified_indices(weights: FloatArray, n_draws: int, rng: np.random.Generator) -> IntArray:
    """n_draws stratified draws of particle indices per row (sorted within the row).

    weights: (B..., N) non-negative, each row with a positive sum (need not be normalised).
    Returns (B..., n_draws) indices in [0, N); see :func:`stratified_counts`.
    """
    if n_draws < 1:
        raise ValueError(f"n_draws must be >= 1 (got {n_draws})")
    batch, rows, n, w = _rows(weights)
    # the kernel sums each row in float64, so its last CDF value is n_draws to ~1e-13, above
    # every float32 uniform: each row gets exactly n_draws
    counts = stratified_counts(w, n_draws, rng, np.intp, total=w.sum(axis=1, dtype=np.float64))
    idx = np.repeat(np.tile(np.arange(n), rows), counts.ravel().astype(np.intp))
    return idx.reshape(*batch, n_draws)


def iid_indices(weights: FloatArray, n_draws: int, rng: np.random.Generator) -> IntArray:
    """n_draws independent draws of particle indices per row, in proportion to the weights.

    weights: (B..., N) non-negative, each row with a positive sum. Returns (B..., n_draws).
    First a block of 16 particles by the inverse CDF of the block totals, then the particle
    within the block. O(N) per row + O(n_draws (log(N / 16) + 16)).
    """
    if n_draws < 1:
        raise ValueError(f"n_draws must be >= 1 (got {n_draws})")
    batch, rows, n, w = _rows(weights)
    blocks = _blocks(w)
    nb = blocks.shape[1]
    totals = np.matmul(blocks, _ONES)  # (rows, nb) float32
    if nb <= _MATMUL_CUMSUM_MAX:
        ends = _matmul_rows(totals, _upper(nb))
    else:
        ends = np.cumsum(totals, axis=-1, dtype=np.float64).astype(np.float32)
    u = rng.random((rows, n_draws), dtype=np.float32)
    u *= ends[:, -1:]  # target, in units of the row's total weight
    if n_draws * 8 <= nb:
        # Few draws: count the block ends at or below the target (no search).
        block = (ends[:, None, :] <= u[:, :, None]).sum(axis=-1)
    else:
        # Rows' block CDFs laid end to end, row r shifted to [r, r + 1]: one searchsorted.
        row_base = np.arange(rows)[:, None]
        keys = (ends / ends[:, -1:]).astype(np.float64)
        keys += row_base
        q = (u / ends[:, -1:]).astype(np.float64)
        q += row_base
        block = np.searchsorted(keys.ravel(), q.ravel(), side="right").reshape(rows, n_draws)
        block -= row_base * nb
    np.minimum(block, nb - 1, out=block)
    flat_block = block + (np.arange(rows) * nb)[:, None]
    u -= ends.ravel()[flat_block]
    u += totals.ravel()[flat_block]  # residual within the chosen block
    picked = blocks.reshape(rows * nb, _BLOCK)[flat_block.ravel()]
    within = _matmul_rows(picked, _UPPER).reshape(rows, n_draws, _BLOCK)
    j = (within <= u[..., None]).sum(axis=-1)
    idx = block * _BLOCK + np.minimum(j, _BLOCK - 1)
    np.minimum(idx, n - 1, out=idx)
    return idx.reshape(*batch, n_draws)
