"""Fault schedule, fault flags, sim clock, parameter table, truth writer, fence geometry."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from sim.clock import SimClock
from sim.faults import Fault, FaultSchedule, fault_from_config, parse_fault_flag
from sim.fence import (
    FENCE_CIRCLE_EXCLUSION,
    FENCE_POLYGON_VERTEX_INCLUSION,
    FENCE_RETURN_POINT,
    FenceItem,
    build_fence,
)
from sim.params import ParamTable, decode_param_id
from sim.truth import TruthWriter


def test_fault_flags_parse_and_validate() -> None:
    f = parse_fault_flag("detection_dropout,at_s=30,duration_s=8,probability=0.5")
    assert (f.kind, f.at_s, f.duration_s, f.probability) == ("detection_dropout", 30, 8, 0.5)
    assert parse_fault_flag("clock_offset, at_s=0, offset_s=-12").offset_s == -12.0
    for bad in ("meteor,at_s=1", "link_drop,duration_s=3", "gps_loss,at_s=1,percent=3",
                "battery_sag,at_s=1,percent=150", "clutter,at_s=nan,rate_per_s=1",
                "link_drop,at_s=1,duration_s"):
        with pytest.raises(ValueError):
            parse_fault_flag(bad)
    assert fault_from_config({"kind": "battery_sag", "at_s": 5, "percent": 20}).percent == 20


def test_schedule_sim_and_wall_durations() -> None:
    s = FaultSchedule([Fault("gps_loss", 10.0, duration_s=5.0),
                       Fault("link_drop", 10.0, duration_s=2.0),
                       Fault("battery_sag", 12.0, percent=30.0),
                       Fault("clock_offset", 1.0, offset_s=3.0)])
    assert s.next_start_s(0.0) == 1.0
    assert s.update(0.5, 0.05) == []
    assert [(w, f.kind) for w, f in s.update(10.0, 1.0)] == [
        ("start", "clock_offset"), ("start", "gps_loss"), ("start", "link_drop")]
    assert s.active("link_drop") and s.active("gps_loss") and s.active("clock_offset")
    # At 20x: 15 s of sim is 0.75 s of wall; link_drop (wall) outlasts gps_loss (sim).
    changes = [(w, f.kind) for w, f in s.update(15.0, 1.75)]
    assert changes == [("end", "gps_loss"), ("start", "battery_sag")]
    assert s.active("link_drop") and not s.active("gps_loss") and not s.active("battery_sag")
    assert [(w, f.kind) for w, f in s.update(16.0, 3.0)] == [("end", "link_drop")]
    assert s.active("clock_offset")  # permanent
    assert s.next_start_s(16.0) == math.inf


def test_sim_clock_scales_and_drops_stalls() -> None:
    now = [100.0]
    clock = SimClock(10.0, monotonic=lambda: now[0], unix_now=lambda: 1e9, max_lag_s=0.25)
    now[0] += 0.1
    assert clock.due_s() == pytest.approx(1.0)
    clock.sim_s = clock.due_s()  # nothing more is due at the same instant
    now[0] += 5.0  # a stall: only max_lag_s of it is caught up
    clock.sim_s = clock.due_s()
    assert clock.sim_s == pytest.approx(1.0 + 2.5)
    assert clock.unix() == pytest.approx(1e9 + 3.5) and clock.time_boot_ms() == 3500
    assert clock.wall_s() == pytest.approx(5.1)
    with pytest.raises(ValueError):
        SimClock(0.0)


def test_param_table() -> None:
    table = ParamTable({"MPC_ACC_HOR": 4.0})
    assert table["MPC_ACC_HOR"] == 4.0 and table["MPC_XY_VEL_MAX"] == 12.0
    assert table.set("RTL_RETURN_ALT", 1e9) == 500.0
    assert table.set("RTL_RETURN_ALT", math.nan) == 500.0  # refused, unchanged
    assert table.name_at(table.index("COM_OF_LOSS_T")) == "COM_OF_LOSS_T"
    assert table.name_at(999) is None and not table.has("NOPE")
    with pytest.raises(KeyError):
        table.set("NOPE", 1.0)
    assert decode_param_id(b"MIS_TAKEOFF_ALT\x00") == "MIS_TAKEOFF_ALT"
    assert decode_param_id("ABCDEFGHIJKLMNOPQRS") == "ABCDEFGHIJKLMNOP"


def test_truth_writer_is_line_json_and_refuses_an_existing_file(tmp_path: Path) -> None:
    w = TruthWriter(tmp_path)
    w.write(1.5, "pulse", power_db=-50.0, rssi_db=math.nan, where=(1.0, math.inf))
    w.close()
    lines = (tmp_path / "truth.jsonl").read_text().splitlines()
    assert [json.loads(line) for line in lines] == [
        {"t": 1.5, "type": "pulse", "power_db": -50.0, "rssi_db": None, "where": [1.0, None]}]
    with pytest.raises(FileExistsError, match="its own --truth-dir"):
        TruthWriter(tmp_path)  # a second world never lands in the same file
    TruthWriter(None).write(0.0, "x")  # no directory: writes nothing, no error


def _item(cmd: int, p1: float, lat: float, lon: float) -> FenceItem:
    return FenceItem(cmd, 0, p1, lat, lon, 0.0)


def test_build_fence() -> None:
    def to_en(lat: float, lon: float) -> tuple[float, float]:
        return lon * 1000.0, lat * 1000.0

    square = [_item(FENCE_POLYGON_VERTEX_INCLUSION, 4, la, lo)
              for la, lo in ((0, 0), (0, 1), (1, 1), (1, 0))]
    fence = build_fence([_item(FENCE_RETURN_POINT, 0, 0.5, 0.5), *square,
                         _item(FENCE_CIRCLE_EXCLUSION, 50.0, 0.5, 0.5)], to_en)
    assert fence.allows(100.0, 100.0) and not fence.allows(500.0, 500.0)
    assert not fence.allows(1500.0, 500.0) and len(fence.items) == 6
    for bad in (square[:3], [*square[:3], _item(FENCE_CIRCLE_EXCLUSION, 5, 0, 0)],
                [_item(FENCE_CIRCLE_EXCLUSION, -1.0, 0, 0)], [_item(16, 0, 0, 0)]):
        with pytest.raises(ValueError):
            build_fence(bad, to_en)
