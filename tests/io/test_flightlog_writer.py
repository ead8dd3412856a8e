"""The flight-log writer when the disk fails: a failed record is undone, counted, raised."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest

from mexgen_gcs.config import load_mission
from mexgen_gcs.io.flightlog import FlightLogWriter, read_flight_log

DEMO = Path(__file__).resolve().parents[2] / "missions" / "demo.yaml"


class FailingFile:
    """A raw file that writes `good` bytes of the next record and then fails (disk full)."""

    def __init__(self, real, fail_after_bytes: int) -> None:
        self.real = real
        self.budget = fail_after_bytes

    def write(self, data) -> int:
        if self.budget <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        n = min(len(data), self.budget)
        self.budget -= n
        return self.real.write(bytes(data[:n]))

    def __getattr__(self, name):
        return getattr(self.real, name)


def test_disk_full_mid_record_leaves_no_torn_line(tmp_path: Path) -> None:
    w = FlightLogWriter(tmp_path, load_mission(DEMO))
    w.write("event", kind="tick", i=1)
    size = (tmp_path / "flight.jsonl").stat().st_size
    real = w._file
    w._file = FailingFile(real, fail_after_bytes=7)  # 7 bytes of the next record, then full
    with pytest.raises(OSError, match="No space"):
        w.write("event", kind="tick", i=2)
    assert w.lost_records == 1 and w.records == 2
    assert (tmp_path / "flight.jsonl").stat().st_size == size  # the torn part was cut off
    w._file = real  # space again: writing goes on after the last complete record
    w.write("event", kind="tick", i=3)
    w.close()
    log = read_flight_log(tmp_path / "flight.jsonl")
    assert [r.get("i") for r in log.records] == [None, 1, 3] and not log.torn_last_line
