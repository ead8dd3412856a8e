"""Several logs side by side: heat maps per planner method and a table per log."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mexgen_gcs.analysis import load_flight
from mexgen_gcs.analysis.cli import cmd_analyze
from mexgen_gcs.analysis.compare import HEATMAP_PNG, heat_counts

pytestmark = pytest.mark.e2e


def test_two_methods_compared(demo_log: Path, pim_log: Path, tmp_path: Path,
                              make_args: Any, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    assert cmd_analyze(make_args(log=[str(demo_log), str(pim_log)], out=str(out),
                                 export=True)) == 0
    assert "compared 2 flights (mexgen, pim)" in capsys.readouterr().out
    assert (out / HEATMAP_PNG).read_bytes().startswith(b"\x89PNG")
    md = (out / "compare.md").read_text()
    header = next(line for line in md.splitlines() if line.startswith("|  |"))
    assert demo_log.name in header and pim_log.name in header
    assert "| method | mexgen | pim |" in md
    data = json.loads((out / "compare.json").read_text())
    assert [s["totals"]["method"] for s in data["summaries"]] == ["mexgen", "pim"]
    for log in (demo_log, pim_log):
        assert (out / log.name / "flight.geojson").is_file()
    # --truth belongs to one log
    assert cmd_analyze(make_args(log=[str(demo_log), str(pim_log)],
                                 truth=str(demo_log / "truth.jsonl"))) == 2


def test_heat_counts_are_seconds_at_altitude(demo_log: Path) -> None:
    flight = load_flight(demo_log)
    w, e, s, n = flight.area.bounds
    counts = heat_counts([flight], (w - 50, e + 50, s - 50, n + 50))
    tr = flight.track
    high = tr.t[tr.up_m > 0.5 * flight.mission.flight.alt_m]
    assert counts.sum() == pytest.approx(high.max() - high.min(), rel=0.05)
    assert np.all(counts >= 0)
