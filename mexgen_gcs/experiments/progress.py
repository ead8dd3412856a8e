"""The experiments' progress bar with ETA (rich's), on a terminal only. No frames here.

One line, redrawn at most ``max_hz`` times a second (always on the last run)::

    localise cv-ift ━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━  30/60  50% 2 failed 0:01:12 0:01:12
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress


class Progress:
    """Counts finished runs; draws on a tty only (``force``: whatever the stream is)."""

    def __init__(self, total: int, label: str, stream: TextIO,
                 clock: Callable[[], float] = time.monotonic, max_hz: float = 10.0,
                 force: bool | None = None) -> None:
        self.total = total
        self.label = label
        self.clock = clock
        self.done = 0
        self.failed = 0
        self.enabled = force if force is not None else _isatty(stream)
        self._min_gap_s = 1.0 / max_hz
        self._last_draw = -float("inf")
        self._bar: RichProgress | None = None
        if self.enabled:
            console = Console(file=stream, force_terminal=True, width=120)
            self._bar = RichProgress(
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                TaskProgressColumn(), TextColumn("{task.fields[failed]}"),
                TimeElapsedColumn(), TimeRemainingColumn(), console=console,
                auto_refresh=False, get_time=clock)
            self._task = self._bar.add_task(label, total=total, failed="")
            self._bar.start()

    def update(self, failed: bool = False) -> None:
        """One more run finished (``failed``: it raised)."""
        self.done += 1
        self.failed += int(failed)
        if self._bar is None:
            return
        self._bar.update(self._task, completed=self.done,
                         failed=f"{self.failed} failed" if self.failed else "")
        now = self.clock()
        if self.done >= self.total or now - self._last_draw >= self._min_gap_s:
            self._last_draw = now
            self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


def _isatty(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False
