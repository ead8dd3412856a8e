"""Replay: a recorded sequence of snapshots drives the same panels, with pause, single step,
faster and slower; the ReplaySource's pacing on its own."""

from __future__ import annotations

import asyncio
import time
from dataclasses import replace

import pytest

from mexgen_gcs.io.snapshot import MissionSnapshot
from mexgen_gcs.ui.app import build_app, run_replay_async
from mexgen_gcs.ui.replay_bar import ReplayBar
from mexgen_gcs.ui.source import ReplaySource
from mexgen_gcs.ui.status_bar import StatusBar
from tests.ui.ui_helpers import make_snapshot, svg_rows, until


def recording(n: int = 20, dt_s: float = 0.5) -> list[MissionSnapshot]:
    """n snapshots, dt_s apart, the altitude telling them apart (40.0, 40.5, ...)."""
    base = make_snapshot()
    out = []
    for i in range(n):
        tel = replace(base.telemetry, rel_alt_m=40.0 + 0.5 * i)
        out.append(replace(base, t=base.t + dt_s * i, elapsed_s=base.elapsed_s + dt_s * i,
                           telemetry=tel))
    return out


async def test_replay_drives_the_same_panels_to_the_end():
    snaps = recording(20)
    source = ReplaySource(snaps, speedup=40.0)
    app = build_app(source, linger_s=None)
    async with app.run_test(size=(120, 40)) as pilot:
        await until(pilot, lambda: app.ended)
        await pilot.pause()
        text = "\n".join(svg_rows(app.export_screenshot(), 120, 40))
        assert app.snapshot is snaps[-1]
        assert "alt 49.5 m" in text  # the last snapshot's number
        assert "REPLAY ENDED" in text and "20/20" in text
        assert "+T2" in text and "next re-plan in 3.2 s" in text  # same map and planner
        # mission commands are not offered in a replay; its own keys are
        for s in ("Play/Pause", "Step", "Faster", "Slower"):
            assert s in text
        assert "RTL" not in text.splitlines()[-1]
        await pilot.press("r")
        await pilot.pause()
        assert app.is_running and len(app.screen_stack) == 1
        await pilot.press("q")  # no confirmation needed: nothing is flying
        await until(pilot, lambda: not app.is_running)


async def test_replay_pause_step_faster_slower():
    snaps = recording(20)
    source = ReplaySource(snaps, speedup=1.0, start_paused=True)
    app = build_app(source, linger_s=None)
    async with app.run_test(size=(120, 40)) as pilot:
        await until(pilot, lambda: app.snapshot is snaps[0])
        await pilot.pause(0.3)
        assert app.snapshot is snaps[0]  # paused: stays on the first
        await pilot.press("n")
        await until(pilot, lambda: app.snapshot is snaps[1])
        await pilot.press("n")
        await until(pilot, lambda: app.snapshot is snaps[2])
        assert "alt 41.0 m" in app.query_one(StatusBar).render().plain
        assert source.paused
        await pilot.press("right_square_bracket", "right_square_bracket")
        assert source.speedup == 4.0
        await pilot.press("left_square_bracket")
        assert source.speedup == 2.0
        bar = app.query_one(ReplayBar).render().plain
        assert "PAUSED" in bar and "×2" in bar and "3/20" in bar
        await pilot.press("space")  # play
        await until(pilot, lambda: source.index > 4)
        await pilot.press("space")  # pause again
        await pilot.pause(0.1)
        held = source.index
        await pilot.pause(0.5)
        assert source.index == held


async def test_replay_pacing_follows_recorded_time_and_skips_when_fast():
    snaps = recording(11, dt_s=1.0)  # 10 s recorded
    source = ReplaySource(snaps, speedup=20.0, max_hz=10.0)
    seen = []
    t0 = time.monotonic()
    async for s in source.snapshots():
        seen.append(s)
    wall = time.monotonic() - t0
    # paced: 10 s at x20 is 0.5 s, and load can only make it longer; skipping: at most
    # max_hz snapshots a second of the wall time it took, however long that was
    assert wall >= 0.8 * 0.5
    assert len(seen) <= 10.0 * wall + 2
    assert seen[0] is snaps[0] and seen[-1] is snaps[-1]
    assert [s.t for s in seen] == sorted(s.t for s in seen)
    assert source.finished


async def test_replay_at_very_high_speed_shows_at_most_max_hz():
    snaps = recording(200, dt_s=0.25)  # 50 s recorded
    source = ReplaySource(snaps, speedup=128.0, max_hz=10.0)
    seen = [s async for s in source.snapshots()]
    assert seen[-1] is snaps[-1]
    assert len(seen) < 20  # ~0.4 s of wall time at <= 10 Hz, not 200 frames


def test_replay_rejects_nothing_and_unknown_commands():
    with pytest.raises(ValueError, match="nothing to replay"):
        ReplaySource([])
    with pytest.raises(ValueError, match="unknown replay command"):
        ReplaySource(recording(2)).command("rtl")


async def test_run_replay_async_entry_point():
    snaps = recording(5)

    async def script(pilot) -> None:
        await until(pilot, lambda: pilot.app.ended, timeout_s=10.0)
        await pilot.press("q")

    await asyncio.wait_for(
        run_replay_async(snaps, speedup=50.0, headless=True, size=(80, 24), auto_pilot=script),
        timeout=30.0)
