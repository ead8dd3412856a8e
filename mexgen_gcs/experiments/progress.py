"""A plain-text progress bar with ETA for a terminal; quiet when the stream is not a tty.

No frames here. One line, redrawn with a carriage return, at most ``max_hz`` times a second
(always on the last run)::

    localise cv-ift  [##########----------]  30/60  50%  2 failed  0:01:12 elapsed  ETA 0:01:12
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TextIO

_WIDTH = 20


def _hms(seconds: float) -> str:
    s = max(0, round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


class Progress:
    """Counts finished runs; draws on a tty only."""

    def __init__(self, total: int, label: str, stream: TextIO,
                 clock: Callable[[], float] = time.monotonic, max_hz: float = 10.0,
                 force: bool | None = None) -> None:
        self.total = total
        self.label = label
        self.stream = stream
        self.clock = clock
        self.t0 = clock()
        self.done = 0
        self.failed = 0
        self.enabled = force if force is not None else _isatty(stream)
        self._min_gap_s = 1.0 / max_hz
        self._last_draw = -float("inf")

    def update(self, failed: bool = False) -> None:
        """One more run finished (``failed``: it raised)."""
        self.done += 1
        self.failed += int(failed)
        now = self.clock()
        if self.enabled and (self.done >= self.total or now - self._last_draw >= self._min_gap_s):
            self._last_draw = now
            self.stream.write("\r" + self.line(now))
            self.stream.flush()

    def line(self, now: float | None = None) -> str:
        now = self.clock() if now is None else now
        elapsed = now - self.t0
        frac = self.done / self.total if self.total else 1.0
        bar = "#" * round(frac * _WIDTH)
        eta = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        eta_text = _hms(eta) if eta == eta else "-:--:--"
        failed = f"  {self.failed} failed" if self.failed else ""
        return (f"{self.label}  [{bar:-<{_WIDTH}}]  {self.done}/{self.total}  {100 * frac:3.0f}%"
                f"{failed}  {_hms(elapsed)} elapsed  ETA {eta_text}")

    def close(self) -> None:
        if self.enabled and self.done:
            self.stream.write("\n")
            self.stream.flush()


def _isatty(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False
