"""While the UI owns the terminal, log records must not be written onto it.

``terminal_logging_held()`` takes the root logger's handlers that write to the terminal
(stream handlers on stdout/stderr) out for the duration, keeps the records they would have
written (bounded), and replays them through those handlers afterwards, so warnings raised
during a flight are still seen once the screen is back. Handlers writing to files stay.
No frames.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import sys
from collections.abc import Iterator

MAX_HELD_RECORDS = 500


class _HoldingHandler(logging.Handler):
    def __init__(self, level: int) -> None:
        super().__init__(level)
        self.records: collections.deque[logging.LogRecord] = collections.deque(
            maxlen=MAX_HELD_RECORDS)
        self.dropped = 0

    def emit(self, record: logging.LogRecord) -> None:
        if len(self.records) == self.records.maxlen:
            self.dropped += 1
        self.records.append(record)


def _writes_to_terminal(handler: logging.Handler) -> bool:
    if isinstance(handler, logging.FileHandler) or not isinstance(handler,
                                                                   logging.StreamHandler):
        return False
    stream = getattr(handler, "stream", None)
    return stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__)


@contextlib.contextmanager
def terminal_logging_held() -> Iterator[None]:
    root = logging.getLogger()
    held = [h for h in root.handlers if _writes_to_terminal(h)]
    if not held:
        yield
        return
    holder = _HoldingHandler(min(h.level for h in held))
    for h in held:
        root.removeHandler(h)
    root.addHandler(holder)
    try:
        yield
    finally:
        root.removeHandler(holder)
        for h in held:
            root.addHandler(h)
        if holder.dropped:
            root.warning("%d earlier log records were dropped while the UI was shown",
                         holder.dropped)
        for record in holder.records:
            for h in held:
                if record.levelno >= h.level:
                    h.handle(record)
