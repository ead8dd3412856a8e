"""The flight-log sink writes on a thread of its own and forces the file to disk on the
mission's ``log.fsync_every_s`` (mission.logsink)."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.mission.logsink import MissionLog
from tests.mission.fake_flight import make_mission


class _Disk:
    def __init__(self) -> None:
        self.lines: list[tuple[str, dict[str, Any]]] = []
        self.syncs: list[int] = []  # records written at each sync
        self.threads: set[str] = set()

    def write(self, type: str, **fields: Any) -> None:
        self.threads.add(threading.current_thread().name)
        self.lines.append((type, fields))

    def sync(self) -> None:
        self.syncs.append(len(self.lines))


def test_records_are_written_by_the_sink_thread_in_order():
    disk = _Disk()
    sink = MissionLog(disk)
    for i in range(50):
        assert sink.write("event", t=float(i), kind="k")
    sink.close()
    assert [f["t"] for _, f in disk.lines] == [float(i) for i in range(50)]
    assert disk.threads == {"flight-log"}
    assert disk.syncs == []  # fsync off (None)
    assert sink.write("event", t=99.0, kind="after")  # after close: written directly
    assert disk.lines[-1][1]["t"] == 99.0


def test_fsync_after_every_record_or_at_most_every_period():
    every = _Disk()
    sink = MissionLog(every, fsync_every_s=0.0)
    for i in range(5):
        sink.write("event", t=float(i), kind="k")
    sink.close()
    assert every.syncs == [1, 2, 3, 4, 5]

    now = [0.0]
    periodic = _Disk()
    sink = MissionLog(periodic, fsync_every_s=1.0, monotonic=lambda: now[0])
    for i in range(10):  # 10 records over 2.25 s of the (injected) clock
        now[0] = 0.25 * i
        sink.write("event", t=float(i), kind="k")
        sink.flush()
    sink.close()
    assert periodic.syncs[:2] == [5, 9] and periodic.syncs[-1] == 10  # and the last at close


def test_a_value_that_cannot_be_logged_raises_in_the_writer():
    sink = MissionLog(_Disk())
    with pytest.raises(TypeError):
        sink.write("event", t=1.0, kind=object())
    sink.close()


def test_the_mission_setting_defaults_to_one_second_and_is_checked():
    assert make_mission().log.fsync_every_s == 1.0
    assert make_mission({"log.fsync_every_s": None}).log.fsync_every_s is None
    with pytest.raises(ConfigError, match="fsync_every_s"):
        make_mission({"log.fsync_every_s": -1})
