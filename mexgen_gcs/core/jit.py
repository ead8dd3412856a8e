"""The one place the compiled kernels are configured (numba; no frames or units here).

The filter's and the planner's hot loops are written once, as plain Python over arrays, and
compiled by numba's ``njit`` on first use: ahead-of-time compilation would need a compiler on
the user's machine, and numba ships as wheels. Compiled code is cached on disk
(``cache=True``: next to the module, or under ``NUMBA_CACHE_DIR`` where that is not
writable), so only the first run on a machine pays the compile.

Floating-point flags: the kernels may re-associate sums (so reductions vectorise), contract
multiply-adds and use approximate reciprocals and functions, but they keep IEEE infinities
and NaN semantics, because log-weights of impossible particles are ``-inf`` by design.

Random draws: a kernel that draws takes the caller's ``numpy.random.Generator`` as an
argument (numba compiles its methods against the same bit generator), so a run stays
reproducible by seed and draws from the one stream the caller owns.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])

FASTMATH: frozenset[str] = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})
"""LLVM fast-math flags of every kernel: not ``nnan``/``ninf`` (see the module docstring)."""


def kernel(fn: F) -> F:
    """Compile ``fn`` as a cached, GIL-free numba kernel (typed as the Python function)."""
    return cast(F, numba.njit(cache=True, nogil=True, fastmath=set(FASTMATH))(fn))


def inline(fn: F) -> F:
    """A helper that kernels call: compiled and inlined into its callers, never cached on
    its own."""
    return cast(F, numba.njit(inline="always", nogil=True, fastmath=set(FASTMATH))(fn))
