"""The GCS's own vehicle adapter and clock against real PX4 SITL (SIH) at speed factor 4.

PX4's SYSTEM_TIME carries the HOST's wall clock in time_unix_usec and the simulated clock in
time_boot_ms (test_px4_clock.py). The GCS reads both through MAVSDK's MAVLink-direct plugin,
so its mission clock must run at PX4's simulated rate (~3.9x), not at the wall's.
"""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from mexgen_gcs.io.clock import VehicleClock
from mexgen_gcs.io.vehicle import MavsdkVehicle
from tests.px4.conftest import Px4Factory

pytestmark = pytest.mark.px4

K = 4.0


async def test_the_mission_clock_runs_on_px4s_boot_clock(px4_factory: Px4Factory) -> None:
    px4 = await asyncio.to_thread(px4_factory, speed_factor=K)
    vehicle = MavsdkVehicle()
    await vehicle.connect(px4.mavsdk_url)
    clock = VehicleClock()
    vehicle.hub.on_time.append(clock.observe)
    task = asyncio.create_task(vehicle.run_telemetry())
    try:
        async with asyncio.timeout(60.0):
            while not clock.synced:
                await asyncio.sleep(0.2)
        await asyncio.sleep(15.0)
        info = clock.describe()
        print(f"PX4 speed factor {K:g}: mission clock {info}")
        assert 3.6 < clock.rate < 4.05, info
        assert info["source"] == "vehicle"
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
        await vehicle.close()
