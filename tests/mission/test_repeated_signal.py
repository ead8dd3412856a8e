"""A stop request that cannot be obeyed: the vehicle is gone (no telemetry, no command
reaches it), the first SIGTERM asks for a return and a landing that cannot come; the second
escalates to an immediate, logged exit with a result record (``mission.run.StopSignals``).
In-process against the fake vehicle; tests/mission/test_sitl_e2e.py does it to the real
``mexgen-gcs sitl`` with its simulator killed."""

from __future__ import annotations

import asyncio
import time

import pytest

from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.mission.run import StopSignals
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle, Scripted


async def test_a_second_sigterm_with_the_vehicle_gone_exits_at_once(tmp_path):
    fake = FakeVehicle(make_mission().local_frame())
    forced: list[str] = []
    second_at: list[float] = []

    def on_start(controller) -> None:
        stops = StopSignals(controller, asyncio.current_task(), force_exit=forced.append)

        def second(_v: FakeVehicle) -> None:
            second_at.append(time.monotonic())
            stops.on_signal("SIGTERM", "signal:SIGTERM")

        fake.script += [
            Scripted("offboard", 8.0, lambda v: v.drop_link(1e6)),  # the vehicle is gone
            Scripted("offboard", 12.0, lambda v: stops.on_signal("SIGTERM", "signal:SIGTERM")),
            Scripted("offboard", 60.0, second),  # 2.4 s wall later: still waiting
        ]

    with pytest.raises(asyncio.CancelledError):
        await fly(tmp_path / "log", fake, on_start=on_start, timeout_s=120.0)
    elapsed_s = time.monotonic() - second_at[0]
    assert elapsed_s < 5.0  # the promise; it takes well under a second
    records = read_flight_log(tmp_path / "log").records
    events = [r for r in records if r["type"] in ("event", "error")]
    kinds = [e["kind"] for e in events]
    assert "signal" in kinds and "landed_and_disarmed" not in kinds
    repeated = [e for e in events if e["kind"] == "signal_repeated"]
    assert len(repeated) == 1 and "SIGTERM after SIGTERM" in repeated[0]["why"]
    results = [r for r in records if r["type"] == "result"]
    assert len(results) == 1 and results[0]["end_reason"] == "signal_repeated"
    assert results[0]["exit_code"] == 1
    assert forced == []  # the backstop timer has not fired: the exit was cooperative
