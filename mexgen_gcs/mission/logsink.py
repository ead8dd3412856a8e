"""The mission's flight-log sink: a write that fails on the disk never stops a flight.

A record the disk refuses (OSError: disk full, I/O error) is counted and dropped; the first
failure and then at most one every ``warn_every_s`` wall seconds become a warning on the
mission's logger; once writing works again a ``log_loss`` record says how many were lost.
Any other exception (a value that cannot be logged) is a bug and propagates to the task that
wrote, where the mission contains it. No frames here.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from mexgen_gcs.io.records import Record

log = logging.getLogger(__name__)


class RecordWriter(Protocol):
    def write(self, type: str, **fields: Any) -> Any: ...


def invalid_counts(writer: RecordWriter) -> Mapping[str, int]:
    """What the writer found not matching the documented record types (io.jsonl), by reason."""
    found = getattr(writer, "invalid", None)
    return found if isinstance(found, Mapping) else {}


class MissionLog:
    def __init__(self, writer: RecordWriter, *, warn_every_s: float = 10.0,
                 on_loss: Callable[[str], None] | None = None,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.writer = writer
        self.lost = 0
        self._unreported = 0
        self._warn_every_s = warn_every_s
        self._last_warn = -float("inf")
        self._monotonic = monotonic
        self.on_loss = on_loss
        """Called with a warning text when records start being lost (e.g. an in-memory event)."""
        self._invalid_said: set[str] = set()

    def write_record(self, record: Record) -> bool:
        """Write a typed record (see `write`)."""
        fields = record.to_dict()
        return self.write(fields.pop("type"), **fields)

    def write(self, type: str, **fields: Any) -> bool:
        """Write one record; False if the disk refused it (counted)."""
        try:
            if self._unreported:
                self.writer.write("log_loss", t=fields.get("t"), lost=self._unreported,
                                  lost_total=self.lost)
                self._unreported = 0
            before = sum(invalid_counts(self.writer).values())
            self.writer.write(type, **fields)
            if sum(invalid_counts(self.writer).values()) > before:
                self._report_invalid(type)
        except OSError as exc:
            self.lost += 1
            self._unreported += 1
            now = self._monotonic()
            if now - self._last_warn >= self._warn_every_s:
                self._last_warn = now
                text = (f"flight log write failed ({exc.strerror or exc}); {self.lost} "
                        "record(s) lost so far; the flight goes on")
                log.warning("%s", text)
                if self.on_loss is not None:
                    self.on_loss(text)
            return False
        return True

    def _report_invalid(self, type: str) -> None:
        """A record that does not match its documented type was written anyway (a bug: the
        analysis will skip it); said once per record type, never stopping the flight."""
        if type in self._invalid_said:
            return
        self._invalid_said.add(type)
        text = (f"a {type!r} record does not match its documented type "
                "(docs/flight-log.md); written anyway, readers will skip it")
        log.warning("%s", text)
        if self.on_loss is not None:
            self.on_loss(text)
