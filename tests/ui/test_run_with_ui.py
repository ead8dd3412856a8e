"""run_with_ui with a stand-in controller: the mission and the UI share one loop, the result
comes back, commands reach the controller, and a failing UI never takes the mission down."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import replace

import pytest

from mexgen_gcs.errors import MexgenError
from mexgen_gcs.io.snapshot import SnapshotBus
from mexgen_gcs.mission.controller import MissionResult
from mexgen_gcs.ui.app import run_with_ui
from mexgen_gcs.ui.confirm_screen import ConfirmScreen
from tests.ui.ui_helpers import make_snapshot, until


class StandInController:
    """Publishes snapshots at 20 Hz until told to RTL (or `steps` run out), then 'lands'."""

    def __init__(self, steps: int = 400, fail: bool = False, bad_snapshot: bool = False):
        self.bus = SnapshotBus()
        self.requests: list[str] = []
        self.steps = steps
        self.fail = fail
        self.bad_snapshot = bad_snapshot

    def request(self, cmd: str) -> None:
        self.requests.append(cmd)

    async def run(self) -> MissionResult:
        snap = make_snapshot()
        for i in range(self.steps):
            if "rtl" in self.requests:
                break
            if self.fail and i == 10:
                raise MexgenError("controller bug")
            s = replace(snap, t=snap.t + i, elapsed_s=snap.elapsed_s + i)
            if self.bad_snapshot and i == 5:
                s = replace(s, telemetry=None)  # a view must survive garbage
            self.bus.publish(s)
            await asyncio.sleep(0.05)
        self.bus.publish(replace(snap, state="done", end_reason="operator_rtl"))
        return MissionResult(end_reason="operator_rtl" if "rtl" in self.requests else "done",
                             exit_code=1, localised={}, duration_s=1.0, events=[])


async def test_quit_sends_rtl_and_returns_the_missions_result():
    ctl = StandInController()

    async def operator(pilot) -> None:
        await until(pilot, lambda: pilot.app.snapshot is not None)
        await pilot.press("q")
        await until(pilot, lambda: isinstance(pilot.app.screen, ConfirmScreen))
        await pilot.press("y")

    result = await asyncio.wait_for(
        run_with_ui(ctl, headless=True, size=(100, 30), auto_pilot=operator), 30)
    assert ctl.requests == ["rtl"]
    assert result.end_reason == "operator_rtl"


async def test_the_ui_closes_by_itself_after_the_mission():
    ctl = StandInController(steps=10)
    result = await asyncio.wait_for(run_with_ui(ctl, headless=True, linger_s=0.2), 30)
    assert result.end_reason == "done" and ctl.requests == []


async def test_a_failing_ui_does_not_stop_the_mission(caplog):
    ctl = StandInController(steps=40, bad_snapshot=True)
    with caplog.at_level(logging.WARNING, logger="mexgen_gcs.ui.app"):
        result = await asyncio.wait_for(run_with_ui(ctl, headless=True, linger_s=0.2), 30)
    assert "closed before the mission ended" in caplog.text  # the UI did fail, early
    assert result.end_reason == "done"  # and the mission ran all its steps without it


async def test_a_failing_mission_is_raised_and_the_ui_closed():
    ctl = StandInController(fail=True)
    with pytest.raises(MexgenError, match="controller bug"):
        await asyncio.wait_for(run_with_ui(ctl, headless=True), 30)
