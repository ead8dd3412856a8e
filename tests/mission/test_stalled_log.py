"""A stalled log disk does not stall the flight: the flight-log file's writes block for a
second each for 4 s of the search (an NFS mount, a dying SD card), and the setpoint stream
keeps its rate, because records are written by the log's own thread (mission.logsink)."""

from __future__ import annotations

import time
from typing import Any

import pytest

from mexgen_gcs.mission.phases.common import SETPOINT_HZ
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle

STALL_S = 4.0
BLOCK_S = 1.0


class _StallingFile:
    """The log file; once `stall()` is called, every write blocks BLOCK_S for STALL_S."""

    def __init__(self, real: Any) -> None:
        self.real = real
        self.until = -1.0

    def stall(self) -> None:
        self.until = time.monotonic() + STALL_S

    def write(self, data: Any) -> int:
        if time.monotonic() < self.until:
            time.sleep(BLOCK_S)
        return self.real.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.real, name)


class _Timed(FakeVehicle):
    """Records the wall time of every setpoint that reaches the vehicle."""

    def __post_init__(self) -> None:
        super().__post_init__()
        self.setpoint_walls: list[float] = []

    async def set_velocity_ned(self, *args: float) -> None:
        await super().set_velocity_ned(*args)
        self.setpoint_walls.append(time.monotonic())


@pytest.mark.long  # 12 s of a stalled disk in real time
async def test_setpoints_keep_their_rate_while_the_log_disk_stalls(tmp_path):
    fake = _Timed(make_mission().local_frame())
    files: list[_StallingFile] = []
    window: list[float] = []

    class Writer:
        """The real flight-log writer on a stalling file; the stall starts with offboard."""

        def __init__(self, real: Any) -> None:
            self.real = real
            files.append(_StallingFile(real._file))
            real._file = files[0]

        def write(self, type: str, **fields: Any) -> Any:
            if type == "event" and fields.get("kind") == "offboard_started" and not window:
                files[0].stall()
                window.append(time.monotonic())
            return self.real.write(type, **fields)

        def __getattr__(self, name: str) -> Any:
            return getattr(self.real, name)

    # the report rules off: the flight must last until the operator's return, 200 s in
    f = await fly(tmp_path / "log", fake, wrap_log=Writer, requests=(("offboard", 200.0, "rtl"),),
                  overrides={"localisation.stall_window_s": None,
                             "localisation.tag_budget_s": None})
    assert f.result.end_reason == "operator_rtl", f.result.events[-12:]
    # the stall began when the writer thread reached offboard_started: the setpoints of the
    # STALL_S after it (the loop had queued that record a moment before)
    start = window[0]
    during = [t for t in fake.setpoint_walls if start <= t < start + STALL_S]
    expected = SETPOINT_HZ * STALL_S
    assert len(during) >= 0.6 * expected, (len(during), expected)
    assert fake.offboard_violations == []
    # nothing lost: the queue held the records until the disk came back
    assert f.result.counters["log_records_lost"] == 0
    setpoints = [r for r in f.records if r["type"] == "setpoint"]
    assert len(setpoints) >= len(during)
