"""LiveSource over a real SnapshotBus: latest value only, the final snapshot, commands."""

from __future__ import annotations

import asyncio

import pytest

from mexgen_gcs.io.snapshot import SnapshotBus
from mexgen_gcs.ui.source import LiveSource
from tests.ui.ui_helpers import later, make_snapshot


class BusOnly:
    """The two things LiveSource uses of a MissionController."""

    def __init__(self) -> None:
        self.bus = SnapshotBus()
        self.requests: list[str] = []

    def request(self, cmd: str) -> None:
        self.requests.append(cmd)


async def test_live_source_yields_latest_then_final_and_ends():
    ctl = BusOnly()
    over = asyncio.Event()
    source = LiveSource(ctl, over)
    first = make_snapshot()
    ctl.bus.publish(first)
    it = source.snapshots()
    assert await asyncio.wait_for(anext(it), 5) is first
    # a slow reader misses intermediate snapshots and only gets the newest
    for i in range(10):
        ctl.bus.publish(later(first, i + 1.0))
    newest = later(first, 20.0)
    ctl.bus.publish(newest)
    assert await asyncio.wait_for(anext(it), 5) is newest
    final = later(first, 30.0, state="done", end_reason="all_localised")
    ctl.bus.publish(final)
    over.set()
    rest = [s async for s in it]
    assert rest == [final]
    assert ctl.bus._queues == []  # unsubscribed once the stream ended


async def test_live_source_ends_when_the_mission_is_over_while_waiting():
    ctl = BusOnly()
    over = asyncio.Event()
    source = LiveSource(ctl, over)
    got = []

    async def read() -> None:
        async for s in source.snapshots():
            got.append(s)

    reader = asyncio.create_task(read())
    await asyncio.sleep(0.05)
    final = make_snapshot(state="done")
    ctl.bus.publish(final)
    over.set()
    await asyncio.wait_for(reader, 5)
    assert got == [final]


def test_live_source_forwards_only_known_commands():
    ctl = BusOnly()
    source = LiveSource(ctl, asyncio.Event())
    for cmd in ("pause", "resume", "rtl", "land", "abort", "method:pim"):
        source.command(cmd)
    assert ctl.requests == ["pause", "resume", "rtl", "land", "abort", "method:pim"]
    for bad in ("method:warp", "takeoff", ""):
        with pytest.raises(ValueError, match="unknown mission command"):
            source.command(bad)
    assert len(ctl.requests) == 6
