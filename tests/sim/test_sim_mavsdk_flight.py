"""Fly the simulator with plain MAVSDK calls (no project code on the client side).

connect -> health ok -> arm -> take off to 50 m -> offboard heading 45 deg at 10 m/s for 10 s
-> return to launch -> land -> disarm, at SPEEDUP x wall speed. Then the simulator exits by
itself (landed and disarmed after flying).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from mexgen_gcs.io.truthfile import read_truth_file
from tests.sim.sim_helpers import SimFactory, free_udp_port

pytestmark = pytest.mark.e2e

SPEEDUP = 10.0


async def first(stream: AsyncIterator[Any], predicate: Any, timeout_s: float) -> Any:
    """The first item of a MAVSDK stream that satisfies predicate, within timeout_s."""
    async with asyncio.timeout(timeout_s):
        async for item in stream:
            if predicate(item):
                return item
    raise AssertionError("stream ended")


async def test_fly_with_plain_mavsdk(sim_factory: SimFactory) -> None:
    port = free_udp_port()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        t0 = time.monotonic()
        sim = await asyncio.to_thread(sim_factory, mavlink_port=port, speedup=SPEEDUP)
        system = await mavsdk.first_autopilot(timeout_s=20.0)
        assert system is not None
        telemetry, action, offboard = (TelemetryAsync(system), ActionAsync(system),
                                       OffboardAsync(system))
        modes: list[FlightMode] = []

        async def record_modes() -> None:
            async for mode in telemetry.subscribe_flight_mode():
                if not modes or modes[-1] != mode:
                    modes.append(mode)

        recorder = asyncio.create_task(record_modes())
        try:
            await first(telemetry.subscribe_health_all_ok(), bool, 20.0)
            health_s = time.monotonic() - t0
            print(f"sim start -> MAVSDK health ok: {health_s:.2f} s")
            assert health_s < 10.0

            home = await first(telemetry.subscribe_home(), lambda h: True, 10.0)
            assert home.latitude_deg == pytest.approx(-34.9212, abs=1e-6)

            await action.set_takeoff_altitude(50.0)
            assert await action.get_takeoff_altitude() == pytest.approx(50.0)
            await action.arm()
            await action.takeoff()
            pos = await first(telemetry.subscribe_position(),
                              lambda p: p.relative_altitude_m > 49.0, 60.0)
            assert pos.relative_altitude_m < 51.0
            await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, 10.0)

            await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 45.0))
            await offboard.start()
            v = 10.0 / math.sqrt(2.0)
            await offboard.set_velocity_ned(VelocityNedYaw(v, v, 0.0, 45.0))
            start = await telemetry.position_velocity_ned()
            await asyncio.sleep(10.0 / SPEEDUP)
            end = await telemetry.position_velocity_ned()
            heading = await telemetry.heading()
            await offboard.stop()

            dn = end.position.north_m - start.position.north_m
            de = end.position.east_m - start.position.east_m
            dist = math.hypot(dn, de)
            # 10 s at 10 m/s reached at 4 m/s^2: 87.5 m; wall-clock jitter at 10x adds +-15 m.
            assert 65.0 < dist < 115.0, (dn, de)
            assert math.degrees(math.atan2(de, dn)) == pytest.approx(45.0, abs=5.0)
            assert heading.heading_deg == pytest.approx(45.0, abs=5.0)
            assert math.hypot(end.velocity.north_m_s, end.velocity.east_m_s) \
                == pytest.approx(10.0, abs=0.5)

            await action.return_to_launch()
            await first(telemetry.subscribe_armed(), lambda armed: not armed, 90.0)
            assert not await telemetry.in_air()
            final = await telemetry.position_velocity_ned()
            assert math.hypot(final.position.north_m, final.position.east_m) < 2.0
        finally:
            recorder.cancel()
    assert [m for m in modes if m in (FlightMode.TAKEOFF, FlightMode.OFFBOARD,
                                      FlightMode.RETURN_TO_LAUNCH)] == [
        FlightMode.TAKEOFF, FlightMode.OFFBOARD, FlightMode.RETURN_TO_LAUNCH]
    # Landed and disarmed after flying: the simulator ends by itself, cleanly.
    assert await asyncio.to_thread(sim.wait_exit, 15.0) == 0
    records = read_truth_file(sim.truth_path).records
    assert records[-1]["type"] == "end" and records[-1]["reason"] == "landed"
    top = max(r["up_m"] for r in records if r["type"] == "vehicle")
    assert 49.0 < top < 51.0  # RTL from 50 m stays at 50 m (RTL_RETURN_ALT is 30 m)
