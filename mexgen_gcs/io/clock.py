"""The Clock port: mission time in unix seconds, and sleeping on it.

A real flight uses the wall clock. A simulator run faster than real time (``--speedup K``) maps
wall time to mission time as ``t = epoch + K * (wall - epoch)``: at the wall instant ``epoch``
both clocks agree, afterwards mission time runs K times faster. The simulator uses the same
formula with the same epoch, so both processes agree on time without a handshake, and
detection timestamps, pulse periods, re-plan intervals and timeouts all live on one clock.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass
from typing import Protocol


class Clock(Protocol):
    speedup: float

    def now(self) -> float:
        """Mission time, unix seconds."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Sleep for `seconds` of mission time."""
        ...


@dataclass(frozen=True, slots=True)
class WallClock:
    """Real time."""

    speedup: float = 1.0

    def now(self) -> float:
        return time.time()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0))


@dataclass(frozen=True, slots=True)
class ScaledClock:
    """Mission time running `speedup` times faster than the wall clock from `epoch` on."""

    epoch: float
    speedup: float = 1.0

    def __post_init__(self) -> None:
        if not self.speedup > 0:
            raise ValueError("speedup must be > 0")

    def now(self) -> float:
        return self.epoch + self.speedup * (time.time() - self.epoch)

    def to_wall_seconds(self, seconds: float) -> float:
        return seconds / self.speedup

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0) / self.speedup)
