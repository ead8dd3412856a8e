"""Analysing a 20-minute flight takes seconds (slow: flies ~1 minute of wall time first).

Run with: python -m pytest tests/analysis -m slow -q
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from mexgen_gcs.analysis.cli import cmd_analyze
from mexgen_gcs.mission.controller import ControllerOptions
from mexgen_gcs.mission.run import SitlPorts, run_sitl

pytestmark = [pytest.mark.slow, pytest.mark.e2e]


def test_twenty_minute_log_is_analysed_in_seconds(tmp_path: Path, missions_dir: Path,
                                                  make_args: Any,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    result = run_sitl(missions_dir / "follow_cv.yaml", seed=5, speedup=20.0,
                      ports=SitlPorts.free(), log_dir=tmp_path,
                      overrides={"follow.duration_s": 1200.0,
                                 "safety.max_mission_time_s": 1500.0},
                      options=ControllerOptions(print_progress=False))
    assert result.duration_s >= 1200.0
    t0 = time.perf_counter()
    assert cmd_analyze(make_args(log=result.log_dir, out=str(tmp_path / "report"),
                                 export=True)) == 0
    elapsed = time.perf_counter() - t0
    with capsys.disabled():
        print(f"\nanalysed a {result.duration_s / 60:.1f}-minute log in {elapsed:.1f} s")
    assert elapsed < 20.0
