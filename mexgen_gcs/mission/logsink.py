"""The mission's flight-log sink: writing never stalls the flight, and a write that fails on
the disk never stops it.

``write`` runs on the flight's event loop (the 20 Hz setpoint loop among others), so it only
makes the record's values JSON-safe (a snapshot: arrays may change afterwards) and puts it on
a bounded queue; a thread of its own encodes, checks against the documented record types and
writes. A stalled disk (NFS, a dying SD card) then stalls that thread, not the setpoints;
while it stays stalled the queue fills and further records are counted as lost. ``fsync``:
the thread forces the file to disk at most every ``fsync_every_s`` wall seconds (0: after
every record, None: never; the mission's ``log.fsync_every_s``, default 1 s), so a power cut
loses at most about that much of the tail.

A record the disk refuses (OSError: disk full, I/O error) or the full queue drops is counted;
the first loss and then at most one every ``warn_every_s`` wall seconds become a warning on
the mission's logger; once writing works again a ``log_loss`` record says how many were lost.
A value that cannot be logged (TypeError) raises in ``write``, in the task that wrote, where
the mission contains it; any other exception in the writer thread is raised by the next
``write`` the same way. ``close`` drains the queue (bounded) and stops the thread. No frames.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from mexgen_gcs.io.jsonl import to_jsonable
from mexgen_gcs.io.records import Record

log = logging.getLogger(__name__)

QUEUE_RECORDS = 4096
"""Records the queue holds while the disk is slow (minutes of a flight's records)."""
CLOSE_WAIT_S = 2.0
"""Wall seconds ``close`` waits for the queue to drain."""


class RecordWriter(Protocol):
    def write(self, type: str, **fields: Any) -> Any: ...


def invalid_counts(writer: RecordWriter) -> Mapping[str, int]:
    """What the writer found not matching the documented record types (io.jsonl), by reason."""
    found = getattr(writer, "invalid", None)
    return found if isinstance(found, Mapping) else {}


_STOP = object()


class MissionLog:
    def __init__(self, writer: RecordWriter, *, warn_every_s: float = 10.0,
                 on_loss: Callable[[str], None] | None = None,
                 monotonic: Callable[[], float] = time.monotonic,
                 fsync_every_s: float | None = None, queue_records: int = QUEUE_RECORDS
                 ) -> None:
        self.writer = writer
        self.lost = 0
        self._unreported = 0
        self._warn_every_s = warn_every_s
        self._last_warn = -float("inf")
        self._monotonic = monotonic
        self.on_loss = on_loss
        """Called with a warning text when records start being lost (e.g. an in-memory event)."""
        self._invalid_said: set[str] = set()
        self._fsync_every_s = fsync_every_s
        self._last_sync = monotonic()
        self._dirty = False
        self._lock = threading.Lock()
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=queue_records)
        self._bug: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="flight-log", daemon=True)
        self._thread.start()

    # -- the event loop's side ---------------------------------------------------------------

    def write_record(self, record: Record) -> bool:
        """Write a typed record (see `write`)."""
        fields = record.to_dict()
        return self.write(fields.pop("type"), **fields)

    def write(self, type: str, **fields: Any) -> bool:
        """Queue one record; False if it was lost (the queue full: counted)."""
        if self._bug is not None:
            bug, self._bug = self._bug, None
            raise bug
        item = (type, to_jsonable(fields))  # TypeError here: a value that cannot be logged
        if self._thread.is_alive():
            try:
                self._queue.put_nowait(item)
            except queue.Full:
                self._lose(f"the disk is {self._queue.maxsize} records behind")
                return False
            return True
        return self._write_now(*item)  # closed: written here (nothing is queued any more)

    def flush(self, timeout_s: float | None = None) -> bool:
        """Wait until every queued record is written; False on timeout."""
        deadline = None if timeout_s is None else self._monotonic() + timeout_s
        while self._queue.unfinished_tasks:
            if deadline is not None and self._monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def close(self, timeout_s: float = CLOSE_WAIT_S) -> None:
        """Drain the queue (at most ``timeout_s``), force it to disk, stop the thread.
        Records still queued then (a stalled disk) are counted as lost."""
        if not self._thread.is_alive():
            return
        drained = self.flush(timeout_s)
        try:
            self._queue.put(_STOP, timeout=max(timeout_s, 0.1))
        except queue.Full:
            drained = False
        self._thread.join(0.5 if not drained else timeout_s)
        if self._thread.is_alive():
            left = self._queue.qsize()
            with self._lock:
                self.lost += left
            log.warning("flight log: the disk did not take the last %d record(s) within %.1f s",
                        left, timeout_s)
        elif self._fsync_every_s is not None and self._dirty:
            self._sync()

    # -- the writer thread -------------------------------------------------------------------

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is _STOP:
                    return
                try:
                    self._write_now(*item)
                except Exception as exc:  # a bug: raised by the next write, on the loop
                    self._bug = exc
                if self._fsync_every_s is not None and self._dirty and (
                        self._monotonic() - self._last_sync >= self._fsync_every_s):
                    self._sync()
            finally:
                self._queue.task_done()

    def _sync(self) -> None:
        sync = getattr(self.writer, "sync", None)
        self._last_sync = self._monotonic()
        self._dirty = False
        if sync is None:
            return
        try:
            sync()
        except (OSError, ValueError) as exc:
            log.warning("flight log: fsync failed (%s)", exc)

    def _write_now(self, type: str, fields: dict[str, Any]) -> bool:
        try:
            unreported = self._unreported
            if unreported:
                self.writer.write("log_loss", t=fields.get("t"), lost=unreported,
                                  lost_total=self.lost)
                with self._lock:  # the loop may have lost more meanwhile (a full queue)
                    self._unreported -= unreported
            before = sum(invalid_counts(self.writer).values())
            self.writer.write(type, **fields)
            self._dirty = True
            if sum(invalid_counts(self.writer).values()) > before:
                self._report_invalid(type)
        except OSError as exc:
            self._lose(f"flight log write failed ({exc.strerror or exc})")
            return False
        return True

    def _lose(self, why: str) -> None:
        with self._lock:
            self.lost += 1
            self._unreported += 1
            lost = self.lost
            now = self._monotonic()
            warn = now - self._last_warn >= self._warn_every_s
            if warn:
                self._last_warn = now
        if warn:
            text = f"{why}; {lost} record(s) lost so far; the flight goes on"
            log.warning("%s", text)
            if self.on_loss is not None:
                self.on_loss(text)

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


