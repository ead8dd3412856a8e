"""Planner-in-the-loop replay of a real flight: the table's recorded choices are the log's
plan records, the replayed filters track the recorded ones, and the UI gets snapshots."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path
from typing import Any

import pytest

from mexgen_gcs.analysis import load_flight
from mexgen_gcs.analysis.cli import cmd_replay
from mexgen_gcs.analysis.replay import replay
from mexgen_gcs.analysis.snapshots import build_snapshots
from mexgen_gcs.cli import main
from mexgen_gcs.io.snapshot import MissionSnapshot

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def steps(pim_log: Path) -> list[Any]:
    return replay(load_flight(pim_log), "mexgen")


def _plans(log: Path) -> list[dict]:
    rows = [json.loads(x) for x in (log / "flight.jsonl").read_text().splitlines()]
    return sorted((r for r in rows if r["type"] == "plan"), key=lambda r: r["t"])


def test_headless_table_shows_the_recorded_choices(pim_log: Path,
                                                   capsys: pytest.CaptureFixture[str],
                                                   make_args: Any) -> None:
    assert cmd_replay(make_args(log=str(pim_log), method="mc", headless=True)) == 0
    out = capsys.readouterr().out.splitlines()
    head = out[0].split()
    assert head[:3] == ["t+", "(s)", "targets"] and "mc" in head
    rows = [line.split() for line in out[2:] if line[:8].strip().replace(".", "").isdigit()]
    plans = _plans(pim_log)
    assert len(rows) == len(plans) > 3
    for row, plan in zip(rows, plans, strict=True):
        assert row[1] == ",".join(plan["targets"])
        assert float(row[2].rstrip("*")) == pytest.approx(plan["chosen_heading_deg"])
    assert any("mc chose the recorded heading in" in line for line in out)


def test_replay_api_follows_the_recorded_flight(pim_log: Path, steps: list[Any]) -> None:
    plans = _plans(pim_log)
    assert [s.recorded_heading_deg for s in steps] == [p["chosen_heading_deg"] for p in plans]
    assert all(s.method == "mexgen" and s.recorded_method == "pim" for s in steps)


def test_replayed_filters_and_planner_reproduce_the_flight(demo_log: Path) -> None:
    """Same seed, same detections, same pulses: the replayed belief stays close to the
    recorded one and the recorded method mostly makes the recorded choice again (not always:
    missed-detection poses are interpolated from the track, and near-ties flip)."""
    steps = replay(load_flight(demo_log), "pim")
    assert len(steps) == len(_plans(demo_log)) > 15
    # the replayed belief is the recorded one up to interpolated missed-detection poses
    gaps = [s.estimate_gap_m for s in steps if s.estimate_gap_m is not None]
    assert gaps and sorted(gaps)[len(gaps) // 2] < 25.0
    same = sum(s.replay_agrees for s in steps)
    assert same >= 0.5 * len(steps), [(s.recorded_heading_deg, s.replayed_heading_deg)
                                      for s in steps]


def test_replay_goes_through_the_command_line(pim_log: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(pim_log)]) == 0  # stdout is not a terminal: the table
    captured = capsys.readouterr()
    assert "recorded pim" in captured.out and "mexgen" in captured.out
    assert "replaying" in captured.err


def test_snapshots_for_the_ui(pim_log: Path, steps: list[Any]) -> None:
    flight = load_flight(pim_log)
    snaps = build_snapshots(flight, steps)
    assert all(isinstance(s, MissionSnapshot) for s in snaps)
    ts = [s.t for s in snaps]
    assert ts == sorted(ts) and ts[0] == pytest.approx(flight.t_start)
    assert snaps[-1].state == "done" and snaps[-1].end_reason == "max_mission_time"
    assert {s.state for s in snaps} >= {"preflight", "searching", "returning"}
    by_t = {s.t: s for s in snaps}
    for p in flight.plans:
        view = by_t[p.t].plan
        assert view is not None and view.chosen_heading_deg == p.chosen_heading_deg
        assert any("replay: recorded pim" in e for e in by_t[p.t].events)
    last = snaps[-1]
    assert [t.tag_id for t in last.tags] == list(flight.tag_ids)
    assert sum(t.detections_total for t in last.tags) == flight.detections.t.size
    assert len(last.track_en_m) > 10 and len(last.area_en_m) == 4


def test_replay_uses_the_ui_when_it_has_run_replay(pim_log: Path, make_args: Any,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}

    def run_replay(snapshots: list[MissionSnapshot], speedup: float = 1.0) -> int:
        seen.update(n=len(snapshots), speedup=speedup, first=snapshots[0])
        return 0

    fake = types.ModuleType("mexgen_gcs.ui")
    fake.run_replay = run_replay  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "mexgen_gcs.ui", fake)
    monkeypatch.setattr(sys.stdout, "isatty", lambda: True)
    assert cmd_replay(make_args(log=str(pim_log), headless=False, speedup=4.0)) == 0
    assert seen["n"] > 10 and seen["speedup"] == 4.0
    assert isinstance(seen["first"], MissionSnapshot)


def test_bad_method_is_refused(pim_log: Path, make_args: Any,
                               capsys: pytest.CaptureFixture[str]) -> None:
    assert cmd_replay(make_args(log=str(pim_log), method="greedy")) == 2
    assert "--method" in capsys.readouterr().err


async def test_snapshots_play_to_the_end_in_the_terminal_ui(pim_log: Path,
                                                            steps: list[Any]) -> None:
    """The real UI (mexgen_gcs.ui) renders a replay built from a real log to its end."""
    app_module = pytest.importorskip("mexgen_gcs.ui.app")
    source_module = pytest.importorskip("mexgen_gcs.ui.source")
    snaps = build_snapshots(load_flight(pim_log), steps)
    app = app_module.build_app(source_module.ReplaySource(snaps, speedup=100.0), linger_s=None)
    async with app.run_test(size=(120, 40)) as pilot:
        for _ in range(600):  # bounded wait: ~190 s of flight at 100x is ~2 s
            if app.ended:
                break
            await pilot.pause(0.05)
        assert app.ended and app.snapshot is snaps[-1]
        await pilot.press("q")
