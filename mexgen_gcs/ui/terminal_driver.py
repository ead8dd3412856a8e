"""A terminal driver whose output never blocks the event loop the mission runs on.

Textual's POSIX driver hands each screen update to a writer thread through a bounded queue
and blocks the caller when that queue is full, which is what happens when the terminal stops
reading (a stalled SSH link, a paused tmux pane): the event loop, and with it the mission's
setpoint stream, would stall. Here a full queue drops the update instead, and once the
terminal has caught up the whole screen is repainted, so nothing stale stays on it.
No frames.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
from collections.abc import Callable
from typing import IO, Any

from textual.driver import Driver

log = logging.getLogger(__name__)

#: screen updates that may wait for a slow terminal before new ones are dropped
MAX_QUEUED_WRITES = 64
STOP_TIMEOUT_S = 5.0


class NonBlockingWriter(threading.Thread):
    """A file-like writer thread: ``write`` never blocks; overflow drops and asks a repaint."""

    def __init__(self, file: IO[str], on_caught_up: Callable[[], None],
                 max_queued: int = MAX_QUEUED_WRITES) -> None:
        super().__init__(daemon=True, name="mexgen-ui-output")
        self._queue: queue.Queue[str | None] = queue.Queue(max_queued)
        self._file = file
        self._on_caught_up = on_caught_up
        self._overrun = threading.Event()
        self.dropped = 0

    def write(self, text: str) -> None:
        try:
            self._queue.put_nowait(text)
        except queue.Full:
            self.dropped += 1
            self._overrun.set()

    def isatty(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._file.fileno()

    def flush(self) -> None:
        """Flushing happens in the thread whenever the queue runs empty."""

    def run(self) -> None:
        while True:
            text = self._queue.get()
            if text is None:
                break
            try:
                self._file.write(text)
                if self._queue.qsize() == 0:
                    self._file.flush()
            except OSError as exc:  # the terminal went away: keep draining, never block
                log.debug("terminal write failed: %s", exc)
            if self._overrun.is_set() and self._queue.qsize() == 0:
                self._overrun.clear()
                self._on_caught_up()
        with contextlib.suppress(OSError):
            self._file.flush()

    def stop(self) -> None:
        """Ask the thread to finish and wait a bounded time (it is a daemon thread)."""
        try:
            self._queue.put(None, timeout=STOP_TIMEOUT_S)
        except queue.Full:
            return
        self.join(timeout=STOP_TIMEOUT_S)


def nonblocking_driver_class(base: type[Driver]) -> type[Driver]:
    """`base` (Textual's POSIX driver) with its writer thread replaced by NonBlockingWriter.

    If this Textual's driver does not keep its writer where expected, `base` is used as is.
    """

    class NonBlockingDriver(base):  # type: ignore[valid-type, misc]
        def start_application_mode(self) -> None:
            super().start_application_mode()
            old: Any = getattr(self, "_writer_thread", None)
            file = getattr(self, "_file", None)
            if old is None or file is None or not hasattr(old, "stop"):
                log.warning("unknown Textual driver layout: terminal writes may block")
                return
            old.stop()  # drains the start-up sequences it already holds
            writer = NonBlockingWriter(file, self._caught_up)
            writer.start()
            self._writer_thread = writer

        def _caught_up(self) -> None:
            """From the writer thread: repaint everything once on the app's loop."""
            app = self._app
            loop = getattr(self, "_loop", None)
            if loop is None or loop.is_closed():
                return
            loop.call_soon_threadsafe(_repaint, app)

    NonBlockingDriver.__name__ = f"NonBlocking{base.__name__}"
    NonBlockingDriver.__qualname__ = NonBlockingDriver.__name__
    return NonBlockingDriver


def _repaint(app: Any) -> None:
    """A full-screen update: the screen's own region dirty makes Textual send every cell."""
    try:
        if app.is_running and app.screen is not None:
            app.screen.refresh()
    except Exception as exc:  # a repaint must never raise into the loop
        log.debug("repaint after a slow terminal failed: %s", exc)
