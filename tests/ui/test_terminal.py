"""A slow terminal never slows the mission: output that cannot be written is dropped (and
the screen repainted later) instead of blocking the event loop; log records do not scribble
over the UI."""

from __future__ import annotations

import io
import json
import logging
import os
import pty
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from mexgen_gcs.ui.terminal_driver import NonBlockingWriter
from mexgen_gcs.ui.terminal_logging import terminal_logging_held

HERE = Path(__file__).parent


def test_writer_never_blocks_on_a_stalled_pipe_and_recovers():
    r, w = os.pipe()
    caught_up = threading.Event()
    with os.fdopen(w, "w", encoding="utf-8") as wfile:
        writer = NonBlockingWriter(wfile, caught_up.set, max_queued=8)
        writer.start()
        frame = "x" * 20_000
        worst = 0.0
        for _ in range(200):  # 4 MB into a pipe nobody reads (it holds ~64 kB)
            t0 = time.monotonic()
            writer.write(frame)
            worst = max(worst, time.monotonic() - t0)
        assert worst < 1.0  # a blocking write would wait for a reader forever
        assert writer.dropped > 150
        assert not caught_up.is_set()
        drained = 0

        def drain() -> None:
            nonlocal drained
            while chunk := os.read(r, 1 << 16):
                drained += len(chunk)

        reader = threading.Thread(target=drain, daemon=True)
        reader.start()
        assert caught_up.wait(10.0)  # once the terminal caught up, a repaint is asked for
        writer.stop()
        assert not writer.is_alive()
    reader.join(10.0)
    assert 0 < drained < 200 * len(frame)


def _probe(mode: str, tmp_path: Path, seconds: float) -> dict | None:
    """Run the UI on a pty nobody reads; the probe's result, or None if its loop stalled."""
    master, slave = pty.openpty()
    out = tmp_path / f"{mode}.json"
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "120", "LINES": "40",
           "PYTHONPATH": os.pathsep.join([str(HERE.parents[1]), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, str(HERE / "slow_terminal_probe.py"), mode,
                             str(out), str(seconds)], stdin=slave, stdout=slave, stderr=slave,
                            env=env, start_new_session=True)
    os.close(slave)
    try:
        deadline = time.monotonic() + 4 * seconds + 20.0
        while time.monotonic() < deadline and not out.exists():
            time.sleep(0.1)
        time.sleep(0.2)
        return json.loads(out.read_text()) if out.exists() else None
    finally:
        proc.kill()
        proc.wait(10.0)
        os.close(master)


@pytest.mark.long  # the UI in a Python subprocess on a pty
def test_ui_on_a_terminal_that_is_never_read_keeps_the_loop_running(tmp_path):
    result = _probe("nonblocking", tmp_path, seconds=3.0)
    assert result is not None, "the event loop stalled behind the terminal"
    assert result["dropped"] > 0  # the terminal really was stalled
    # a 20 ms ticker never waited long (the stock writer stalls it for good)
    assert result["max_gap_s"] < 1.0, result
    assert result["ticks"] > 20  # it kept ticking the whole time


def test_log_records_are_held_while_the_ui_owns_the_terminal():
    stream = io.StringIO()
    root = logging.getLogger()
    to_terminal = logging.StreamHandler(sys.stderr)
    to_terminal.setLevel(logging.WARNING)
    to_file = logging.StreamHandler(stream)  # not the terminal: left alone
    root.addHandler(to_terminal)
    root.addHandler(to_file)
    old_stderr = sys.stderr
    captured = io.StringIO()
    try:
        sys.stderr = to_terminal.stream = captured  # what the handler would scribble on
        with terminal_logging_held():
            assert to_terminal not in root.handlers and to_file in root.handlers
            logging.getLogger("mexgen_gcs.test").warning("link lost at %d s", 12)
            assert captured.getvalue() == ""
        assert to_terminal in root.handlers
        assert "link lost at 12 s" in captured.getvalue()
        assert "link lost at 12 s" in stream.getvalue()
    finally:
        sys.stderr = old_stderr
        root.removeHandler(to_terminal)
        root.removeHandler(to_file)
