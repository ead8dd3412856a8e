"""Starting the simulator process (``mission.run.start_simulator``): the ready timeout bounds
every read, and an interrupt while waiting stops the process instead of orphaning it. A
stand-in process takes the simulator's place (no simulator runs here)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from mexgen_gcs.errors import MexgenError
from mexgen_gcs.mission import run
from mexgen_gcs.mission.run import SitlPorts, _wait_for_ready_line

pytestmark = pytest.mark.long  # stand-in Python processes

HANG_MID_LINE = "import sys, time; sys.stdout.write('sim rea'); sys.stdout.flush(); time.sleep(60)"


def _python(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)


def test_the_ready_line_is_found_across_reads():
    proc = _python("import sys, time; print('starting', flush=True); sys.stdout.write('sim ');"
                   "sys.stdout.flush(); time.sleep(0.3); print('ready on 1 2', flush=True);"
                   "time.sleep(60)")
    try:
        assert _wait_for_ready_line(proc, time.monotonic() + 30.0)
    finally:
        proc.kill()
        proc.wait()


def test_a_process_that_hangs_mid_line_times_out_on_the_deadline():
    proc = _python(HANG_MID_LINE)
    try:
        t0 = time.monotonic()
        assert not _wait_for_ready_line(proc, t0 + 1.0)
        # bounded by the deadline, not by the process's 60 s (a blocking readline waited)
        assert time.monotonic() - t0 < 30.0
    finally:
        proc.kill()
        proc.wait()


def test_an_exit_before_the_ready_line_is_not_ready():
    proc = _python("print('no luck')")
    assert not _wait_for_ready_line(proc, time.monotonic() + 30.0)
    proc.wait()


def _stand_in(monkeypatch: pytest.MonkeyPatch, code: str) -> list[subprocess.Popen[str]]:
    """The simulator's command replaced by `code`; the processes started."""
    started: list[subprocess.Popen[str]] = []
    real = subprocess.Popen

    def popen(cmd, **kw):
        proc = real([sys.executable, "-c", code], **kw)
        started.append(proc)
        return proc

    monkeypatch.setattr(run.subprocess, "Popen", popen)
    return started


def test_an_interrupt_while_waiting_stops_the_simulator(monkeypatch, tmp_path):
    started = _stand_in(monkeypatch, HANG_MID_LINE)

    def interrupted(proc, deadline):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "_wait_for_ready_line", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run.start_simulator(tmp_path / "m.yaml", seed=1, speedup=1.0, ports=SitlPorts(1, 2),
                            truth_dir=tmp_path)
    assert len(started) == 1 and started[0].poll() is not None  # not orphaned


def test_a_simulator_that_never_gets_ready_is_stopped(monkeypatch, tmp_path):
    started = _stand_in(monkeypatch, HANG_MID_LINE)
    with pytest.raises(MexgenError, match="did not start within 1 s"):
        run.start_simulator(tmp_path / "m.yaml", seed=1, speedup=1.0, ports=SitlPorts(1, 2),
                            truth_dir=tmp_path, ready_timeout_s=1.0)
    assert started[0].poll() is not None
