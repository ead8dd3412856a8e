"""Fly a whole mission against the fake vehicle and receiver (``fake_vehicle``): a small
mission, the real controller, VehicleClock, flight-log writer and core, and the log read back.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tests.mission.fake_vehicle import FakeReceiver, FakeVehicle, Scripted

MISSION_YAML = """
version: 1
name: fake
kind: localise
home: {lat_deg: -34.9212, lon_deg: 138.6011}
area:
  rectangle_m: {west_m: -300, east_m: 300, south_m: -300, north_m: 300}
flight: {alt_m: 20.0, speed_m_s: 8.0, max_accel_m_s2: 3.0}
tags:
  - {id: T1, freq_hz: 150100000}
filter: {n_particles: 300}
planner: {samples: 16, n_particles: 100, replan_interval_s: 5.0, lookahead_s: 10.0}
localisation: {radius_m: 0.5}
receiver: {heartbeat_timeout_s: 3.0}
safety: {max_mission_time_s: 600.0, radio_loss_timeout_s: 15.0}
"""


@dataclass
class Flight:
    result: Any
    records: list[dict[str, Any]]
    vehicle: FakeVehicle
    controller: Any

    def kinds(self) -> list[str]:
        return [r.get("kind", "") for r in self.records if r["type"] in ("event", "error")]

    def events(self, kind: str) -> list[dict[str, Any]]:
        return [r for r in self.records if r["type"] in ("event", "error")
                and r.get("kind") == kind]

    @property
    def result_record(self) -> dict[str, Any]:
        found = [r for r in self.records if r["type"] == "result"]
        assert len(found) == 1, f"expected one result record, found {len(found)}"
        return found[0]


def make_mission(overrides: dict[str, Any] | None = None) -> Any:
    from mexgen_gcs.config import parse_mission
    from mexgen_gcs.mission.run import apply_overrides

    return apply_overrides(parse_mission(MISSION_YAML, "fake.yaml"), overrides)


async def fly(log_dir: Any, vehicle: FakeVehicle | None = None, *, overrides: dict[str, Any]
              | None = None, requests: tuple[tuple[str, float, str], ...] = (),
              receiver_kw: dict[str, Any] | None = None,
              wrap_log: Callable[[Any], Any] | None = None, options: Any = None,
              timeout_s: float = 60.0, clock: Any = None,
              on_start: Callable[[Any], None] | None = None) -> Flight:
    """Fly the fake mission against `vehicle`; `requests` are operator commands
    (trigger, after vehicle s, command) like the vehicle's script; `wrap_log` wraps the
    flight-log writer (to inject write failures); `on_start(controller)` runs before the
    flight."""
    from mexgen_gcs.io.clock import VehicleClock
    from mexgen_gcs.io.flightlog import FlightLogWriter, read_flight_log
    from mexgen_gcs.mission.controller import ControllerOptions, MissionController

    mission = make_mission(overrides)
    vehicle = vehicle or FakeVehicle(mission.local_frame())
    receiver = FakeReceiver(vehicle, mission.tag_ids, **(receiver_kw or {}))
    clock = clock or VehicleClock()
    rng = np.random.default_rng(1)
    opts = options or ControllerOptions(connect_timeout_s=5, ready_timeout_s=5, radio_wait_s=5,
                                        clock_wait_s=5, takeoff_timeout_s=60,
                                        landing_timeout_s=300, print_progress=False)
    writer = FlightLogWriter(log_dir, mission, seed=1, method="mexgen", clock=clock.now)
    controller = MissionController(mission, vehicle, receiver, clock, mission.mission_core(rng),
                                   wrap_log(writer) if wrap_log is not None else writer,
                                   method="mexgen", rng=rng, connect_url="fake://",
                                   options=opts)
    if on_start is not None:  # sees the controller before it flies
        on_start(controller)
    for trigger, after_s, cmd in requests:
        vehicle.script.append(Scripted(trigger, after_s,
                                       lambda _v, c=cmd: controller.request(c)))
    with writer:
        async with asyncio.timeout(timeout_s):
            radio = asyncio.create_task(receiver.run())
            try:
                result = await controller.run()
            finally:
                radio.cancel()
    return Flight(result, read_flight_log(log_dir).records, vehicle, controller)
