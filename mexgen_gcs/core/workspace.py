"""Reusable scratch buffers for the planner's array work (no positions or frames here).

On this class of machine glibc returns freed heap to the OS and every page touched afresh
costs ~2 us, so a plan that allocated its megabytes of temporaries anew each time spent more
time in page faults than in arithmetic (and how much depended on the heap's history). The
planner keeps one :class:`Workspace` between plans and hands named buffers to the hot loops.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray


class Workspace:
    """Named flat buffers, grown on demand; :meth:`get` returns a contiguous view of the
    requested shape (its contents are whatever was there before).

    Not thread-safe: one workspace per planning thread.
    """

    def __init__(self) -> None:
        self._buffers: dict[str, NDArray[Any]] = {}

    def get(
        self, name: str, shape: tuple[int, ...], dtype: type[np.number] = np.float32
    ) -> NDArray[Any]:
        size = math.prod(shape)
        buf = self._buffers.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = np.empty(size, dtype=dtype)
            self._buffers[name] = buf
        return buf[:size].reshape(shape)

    @property
    def nbytes(self) -> int:
        return sum(b.nbytes for b in self._buffers.values())
