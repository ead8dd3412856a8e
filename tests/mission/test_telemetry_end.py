"""A telemetry stream that ends is a fault: logged, and the phase's safe action follows.

At the port (MavsdkVehicle against stand-in MAVSDK plugins): one stream ending (the flight
mode) ends ``run_telemetry`` with a VehicleError naming it, although the other streams would
keep the link looking fresh. In the mission (the fake vehicle port): telemetry that ends is a
fault, the vehicle returns to launch, the streams are re-subscribed to watch the landing, and
the result record says why."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Any

import pytest

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.vehicle import MavsdkVehicle
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle, Scripted


class _Forever:
    """A stand-in MAVSDK telemetry plugin: every stream yields forever, except `ending`,
    which yields once and ends."""

    def __init__(self, ending: str) -> None:
        self.ending = ending

    def __getattr__(self, name: str) -> Any:
        if not name.startswith("subscribe_"):
            raise AttributeError(name)

        async def stream() -> AsyncIterator[Any]:
            while True:  # None: a malformed value the pumps ignore; the time in us
                yield 1_800_000_000_000_000 if name == "subscribe_unix_epoch_time" else None
                if name == self.ending:
                    return
                await asyncio.sleep(0.01)

        stream.__name__ = name
        return stream


class _System:
    async def is_connected_state(self) -> AsyncIterator[bool]:
        while True:
            yield True
            await asyncio.sleep(0.01)


@pytest.mark.parametrize("ending", ["subscribe_flight_mode", "subscribe_status_text",
                                    "subscribe_unix_epoch_time"])
async def test_a_stream_that_ends_ends_run_telemetry_naming_it(ending):
    vehicle = MavsdkVehicle()
    vehicle._system = _System()
    vehicle._plugins = {"telemetry": _Forever(ending)}
    with pytest.raises(VehicleError, match="ended") as err:
        async with asyncio.timeout(5.0):
            await vehicle.run_telemetry()
    expected = {"subscribe_flight_mode": "flight_mode", "subscribe_status_text": "status_text",
                "subscribe_unix_epoch_time": "time"}[ending]
    assert err.value.call == f"telemetry stream {expected}"


async def test_telemetry_that_ends_is_a_fault_and_the_vehicle_returns(tmp_path):
    fake = FakeVehicle(make_mission().local_frame(),
                       script=[Scripted("offboard", 8.0, lambda v: v.end_telemetry())])
    f = await fly(tmp_path / "log", fake)
    assert f.result.end_reason == "error", f.result.events[-12:]
    fault = f.events("fault")[0]
    assert fault["where"] == "telemetry" and "streams ended" in fault["error"]
    assert "return_to_launch" in [c.name for c in fake.commands]
    assert fake.telemetry_runs >= 2  # re-subscribed, so the landing was watched
    assert "landed_and_disarmed" in f.kinds()
    rec = f.result_record
    assert rec["end_reason"] == "error" and "streams ended" in rec["error"]
    assert fake.offboard_violations == []
