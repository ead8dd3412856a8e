"""A cancelled mission (the task running ``MissionController.run`` is cancelled, as the UI's
task group does when it closes) still takes its safe action: return to launch commanded, a
``result`` record written, and the CancelledError propagates to the canceller."""

from __future__ import annotations

import asyncio

import pytest

from mexgen_gcs.io.flightlog import read_flight_log
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle, Scripted


async def _fly_and_cancel(log_dir, trigger: str, after_s: float, **kw):
    flight: asyncio.Task | None = None

    def cancel(_v: FakeVehicle) -> None:
        assert flight is not None
        flight.cancel()

    fake = FakeVehicle(make_mission().local_frame(), script=[Scripted(trigger, after_s, cancel)])
    flight = asyncio.create_task(fly(log_dir, fake, **kw))
    with pytest.raises(asyncio.CancelledError):
        await flight
    return fake, read_flight_log(log_dir).records


async def test_cancel_during_search_returns_and_writes_the_result(tmp_path):
    fake, records = await _fly_and_cancel(tmp_path / "log", "offboard", 10.0)
    names = [c.name for c in fake.commands]
    assert "start_offboard" in names
    assert names[-1] == "return_to_launch", names  # commanded after the cancel
    events = [r for r in records if r["type"] in ("event", "error")]
    cancelled = [e for e in events if e["kind"] == "cancelled"]
    assert cancelled and cancelled[0]["phase"] == "search"
    assert any(e["kind"] == "rtl_commanded" for e in events)
    results = [r for r in records if r["type"] == "result"]
    assert len(results) == 1
    assert results[0]["end_reason"] == "cancelled" and results[0]["exit_code"] == 1


async def test_cancel_before_arming_commands_nothing_and_writes_the_result(tmp_path):
    """Cancelled while waiting for a radio that never comes: nothing armed, nothing
    commanded, the result record written."""
    fake, records = await _fly_and_cancel(tmp_path / "log", "start", 10.0,
                                          receiver_kw={"silent": True})
    reads = {"read_params", "download_geofence"}  # preflight reads the vehicle, commands nothing
    assert [c.name for c in fake.commands if c.name not in reads] == []
    results = [r for r in records if r["type"] == "result"]
    assert len(results) == 1 and results[0]["end_reason"] == "cancelled"
