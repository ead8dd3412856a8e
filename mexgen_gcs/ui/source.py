"""Where the UI's snapshots come from, and where its commands go: one interface, two sources.

``LiveSource`` reads a running MissionController's SnapshotBus (latest value only, so a slow
UI misses snapshots instead of slowing the mission) and forwards operator commands to
``controller.request``. ``ReplaySource`` plays a recorded sequence of snapshots at a chosen
speed, with pause, single step, faster and slower. No frames here (snapshots carry their own).
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from mexgen_gcs.core.generators import METHODS
from mexgen_gcs.io.snapshot import MissionSnapshot

#: operator commands a live mission accepts (controller.request)
MISSION_COMMANDS = ("pause", "resume", "rtl", "land", "abort")
#: commands a replay accepts
REPLAY_COMMANDS = ("replay:toggle", "replay:pause", "replay:play", "replay:step",
                   "replay:faster", "replay:slower")


class SnapshotSource(Protocol):
    """What the app reads from and commands; live missions and replays look alike."""

    kind: Literal["live", "replay"]

    def snapshots(self) -> AsyncIterator[MissionSnapshot]:
        """Snapshots in time order; ends when the mission (or the recording) is over."""
        ...

    def command(self, cmd: str) -> None:
        """Send an operator command; never blocks."""
        ...


class LiveSource:
    """A running mission: its controller's snapshot bus and command queue.

    ``mission_over`` is set by whoever owns the mission task once ``controller.run()`` has
    returned; the stream then yields the final snapshot and ends.
    """

    kind: Literal["live", "replay"] = "live"

    def __init__(self, controller: Any, mission_over: asyncio.Event) -> None:
        self._controller = controller
        self._over = mission_over

    def command(self, cmd: str) -> None:
        if cmd not in MISSION_COMMANDS and not (
                cmd.startswith("method:") and cmd.split(":", 1)[1] in METHODS):
            raise ValueError(f"unknown mission command {cmd!r}")
        self._controller.request(cmd)

    async def snapshots(self) -> AsyncIterator[MissionSnapshot]:
        bus = self._controller.bus
        queue: asyncio.Queue[MissionSnapshot] = bus.subscribe()
        over = asyncio.ensure_future(self._over.wait())
        shown: MissionSnapshot | None = None
        try:
            while not self._over.is_set():
                get = asyncio.ensure_future(queue.get())
                await asyncio.wait({get, over}, return_when=asyncio.FIRST_COMPLETED)
                if get.done():
                    shown = get.result()
                    yield shown
                else:
                    get.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await get
            while not queue.empty():  # the final snapshot, published as run() returned
                shown = queue.get_nowait()
                yield shown
            last = bus.latest
            if last is not None and last is not shown:
                yield last
        finally:
            over.cancel()
            bus.unsubscribe(queue)


@dataclass(frozen=True, slots=True)
class ReplayStatus:
    index: int
    total: int
    speedup: float
    paused: bool
    finished: bool


class ReplaySource:
    """Plays snapshots with their recorded spacing divided by ``speedup``.

    At most ``max_hz`` snapshots a second reach the UI: at high speed the ones in between
    are skipped (the latest due is shown). Pause holds the current one; ``step`` shows the
    next one and stays paused.
    """

    kind: Literal["live", "replay"] = "replay"
    SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0)

    def __init__(self, snapshots: Sequence[MissionSnapshot], speedup: float = 1.0,
                 *, max_hz: float = 10.0, start_paused: bool = False) -> None:
        if not snapshots:
            raise ValueError("nothing to replay: no snapshots")
        if not speedup > 0:
            raise ValueError("speedup must be > 0")
        self._snaps = list(snapshots)
        self._t = [s.t for s in self._snaps]
        self.speedup = float(speedup)
        self.max_hz = max_hz
        self.paused = start_paused
        self._steps = 0
        self.index = 0
        self.finished = False
        self._changed = asyncio.Event()

    def status(self) -> ReplayStatus:
        return ReplayStatus(self.index, len(self._snaps), self.speedup, self.paused,
                            self.finished)

    def command(self, cmd: str) -> None:
        if cmd == "replay:toggle":
            self.paused = not self.paused
        elif cmd == "replay:pause":
            self.paused = True
        elif cmd == "replay:play":
            self.paused = False
        elif cmd == "replay:step":
            self.paused = True
            self._steps += 1
        elif cmd == "replay:faster":
            self.speedup = next((s for s in self.SPEEDS if s > self.speedup), self.speedup)
        elif cmd == "replay:slower":
            self.speedup = next((s for s in reversed(self.SPEEDS) if s < self.speedup),
                                self.speedup)
        else:
            raise ValueError(f"unknown replay command {cmd!r}")
        self._changed.set()

    async def _wait_change(self, timeout_s: float | None) -> None:
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await self._changed.wait()
        self._changed.clear()

    async def snapshots(self) -> AsyncIterator[MissionSnapshot]:
        n = len(self._snaps)
        self.index = 0
        self.finished = False
        cursor_t = self._t[0]
        yield self._snaps[0]
        last_wall = time.monotonic()
        while self.index < n - 1:
            if self.paused and self._steps == 0:
                await self._wait_change(None)
                last_wall = time.monotonic()
                continue
            if self._steps > 0:
                self._steps -= 1
                self.index += 1
                cursor_t = self._t[self.index]
                last_wall = time.monotonic()
                yield self._snaps[self.index]
                continue
            due_s = (self._t[self.index + 1] - cursor_t) / self.speedup
            await self._wait_change(max(due_s, 1.0 / self.max_hz))
            now = time.monotonic()
            if not self.paused:
                cursor_t += (now - last_wall) * self.speedup
            last_wall = now
            j = min(bisect.bisect_right(self._t, cursor_t) - 1, n - 1)
            if j > self.index:
                self.index = j
                yield self._snaps[j]
        self.finished = True
