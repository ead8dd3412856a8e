"""Flight log writer and reader: round trip, crash tolerance and format checks, on real files."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.config import dump_resolved, load_mission
from mexgen_gcs.errors import LogFormatError
from mexgen_gcs.io import records
from mexgen_gcs.io.flightlog import (
    FORMAT,
    FORMAT_VERSION,
    LOG_FILE,
    FlightLogWriter,
    new_log_dir,
    read_flight_log,
)
from mexgen_gcs.io.jsonl import JsonlWriter, to_jsonable

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "missions" / "demo.yaml"


@pytest.fixture(scope="module")
def mission():
    return load_mission(DEMO)


TELEMETRY = dict(lat=-34.92, lon=138.60, rel_alt_m=np.float32(50.5), v_north_m_s=1.0,
                 v_east_m_s=0.0, yaw_deg=90.0, mode="OFFBOARD", armed=True, in_air=True,
                 battery_percent=np.nan, connected=True)


def test_round_trip(tmp_path: Path, mission) -> None:
    log_dir = tmp_path / "flight-1"
    clock = iter(float(t) for t in range(100, 200))
    with FlightLogWriter(log_dir, mission, seed=5, method="pim", clock=lambda: next(clock)) as w:
        w.write("telemetry", **TELEMETRY)
        w.write("estimate", tag="T1", existence=np.float64(0.75), east_m=1.0, north_m=2.0,
                v_east_m_s=np.nan, v_north_m_s=np.inf, cov_pos_m2=np.eye(2), radius_m=30.0,
                localised=False, update="detection", ess=np.int64(2000), extra_field=[1, 2])
        w.write("event", t=123.5, kind="note", text="explicit time")
    assert (log_dir / LOG_FILE).exists()
    log = read_flight_log(log_dir)
    assert not log.torn_last_line and log.skipped_lines == 0 and not log.damage
    assert [r["type"] for r in log] == ["mission", "telemetry", "estimate", "event"]
    assert [r.t for r in log] == [100.0, 101.0, 102.0, 123.5]
    head = log.header
    assert head["format"] == FORMAT and head["format_version"] == FORMAT_VERSION
    assert head.mission == dump_resolved(mission)
    assert head.mission_path == str(DEMO)
    assert head.mission_text == DEMO.read_text(encoding="utf-8")
    assert head.seed == 5 and head.method == "pim"
    assert set(head.versions) == {"mexgen_gcs", "numpy", "mavsdk", "pymavlink", "python"}
    assert head.versions["numpy"] == np.__version__
    est = next(log.of_type("estimate"))
    assert isinstance(est, records.Estimate)
    assert (est.east_m, est.north_m, est.v_east_m_s, est.v_north_m_s) == (1.0, 2.0, None, None)
    assert est.cov_pos_m2 == ((1.0, 0.0), (0.0, 1.0)) and est.existence == 0.75
    assert est.ess == 2000 and est["extra_field"] == [1, 2] and "extra_field" in est
    tel = next(log.of_type("telemetry"))
    assert tel["rel_alt_m"] == 50.5 and tel.battery_percent is None
    assert next(log.of_type("event")).get("text") == "explicit time"
    # one JSON object per line
    lines = (log_dir / LOG_FILE).read_text(encoding="utf-8").splitlines()
    assert len(lines) == 4 and all(json.loads(line)["type"] for line in lines)


def test_method_defaults_to_the_missions(tmp_path: Path, mission) -> None:
    with FlightLogWriter(tmp_path / "f", mission) as w:
        assert w.records == 1
    head = read_flight_log(tmp_path / "f" / LOG_FILE).header
    assert head["method"] == "mexgen" and head["seed"] is None


def test_records_reach_the_file_before_close(tmp_path: Path, mission) -> None:
    """Flushed per record: another reader sees every record while the writer is open."""
    w = FlightLogWriter(tmp_path / "f", mission, fsync=True)
    w.write("event", kind="one")
    assert [r["type"] for r in read_flight_log(tmp_path / "f")] == ["mission", "event"]
    w.close()
    assert w.closed
    with pytest.raises(ValueError, match="closed"):
        w.write("event", kind="late")


def test_refuses_to_overwrite(tmp_path: Path, mission) -> None:
    FlightLogWriter(tmp_path / "f", mission).close()
    with pytest.raises(FileExistsError):
        FlightLogWriter(tmp_path / "f", mission)


@pytest.mark.long  # a Python subprocess
def test_crash_mid_flight_loses_at_most_the_last_line(tmp_path: Path) -> None:
    """A real process writes records and is killed; the log reads back without the torn tail."""
    log_dir = tmp_path / "crash"
    script = textwrap.dedent(f"""
        import os
        from mexgen_gcs.config import load_mission
        from mexgen_gcs.io.flightlog import FlightLogWriter
        w = FlightLogWriter({str(log_dir)!r}, load_mission({str(DEMO)!r}))
        for i in range(50):
            w.write("event", kind="tick", i=i)
        w._file.write(b'{{"t": 1.0, "type": "event", "kind": "tick", "i": 5')  # half a record
        w._file.flush()
        os._exit(9)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=120)
    assert proc.returncode == 9, proc.stderr.decode()
    log = read_flight_log(log_dir)
    assert log.torn_last_line and log.skipped_lines == 1
    assert [r.get("i") for r in log.of_type("event")] == list(range(50))


def test_torn_last_line_variants(tmp_path: Path, mission) -> None:
    with FlightLogWriter(tmp_path / "f", mission) as w:
        w.write("event", kind="complete")
    path = tmp_path / "f" / LOG_FILE
    good = path.read_bytes()
    # a complete last record without its newline still counts
    path.write_bytes(good.rstrip(b"\n"))
    log = read_flight_log(path)
    assert len(log) == 2 and not log.torn_last_line
    # a multi-byte character cut in half
    path.write_bytes(good + '{"t": 2, "type": "event", "kind": "é'.encode()[:-1])
    log = read_flight_log(path)
    assert len(log) == 2 and log.torn_last_line


def test_damage_before_the_last_line_is_skipped_and_counted(tmp_path: Path, mission) -> None:
    with FlightLogWriter(tmp_path / "f", mission) as w:
        w.write("event", kind="one")
    path = tmp_path / "f" / LOG_FILE
    path.write_bytes(path.read_bytes() + b"{broken\n" + b'{"t": 3, "type": "event"}\n'
                     + b'{"t": 4, "type": "event", "kind": "two"}\n')
    log = read_flight_log(path)
    assert [r.get("kind") for r in log.of_type("event")] == ["one", "two"]
    assert log.damage.lines == {"not JSON": [3], "invalid event record": [4]}
    assert log.skipped_lines == 2 and not log.torn_last_line
    assert log.damage.describe() == ("2 damaged records skipped: 1 not JSON (line 3); "
                                      "1 invalid event record (line 4)")


def test_nothing_but_damage_after_the_header_is_refused(tmp_path: Path, mission) -> None:
    FlightLogWriter(tmp_path / "f", mission).close()
    path = tmp_path / "f" / LOG_FILE
    path.write_bytes(path.read_bytes() + b"\x00\xff garbage\n" * 3 + b'{"t": NaN}\n')
    with pytest.raises(LogFormatError, match=r"nothing usable after the mission record: 4 "
                       r"damaged records skipped: 3 not UTF-8 \(lines 2, 3, 4\); 1 not a "
                       r"record"):
        read_flight_log(path)


def test_a_damaged_header_is_refused(tmp_path: Path, mission) -> None:
    with FlightLogWriter(tmp_path / "f", mission) as w:
        w.write("event", kind="one")
    path = tmp_path / "f" / LOG_FILE
    head, rest = path.read_bytes().split(b"\n", 1)
    record = json.loads(head)
    del record["mission"]
    path.write_bytes(json.dumps(record).encode() + b"\n" + rest)
    with pytest.raises(LogFormatError, match=r"the mission record \(the first line\) is "
                       r"damaged \(invalid mission record\)"):
        read_flight_log(path)


def _write_lines(path: Path, *records: object) -> Path:
    path.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    return path


def test_newer_format_version(tmp_path: Path) -> None:
    path = _write_lines(tmp_path / "f.jsonl", {"t": 1, "type": "mission", "format": FORMAT,
                                               "format_version": FORMAT_VERSION + 1})
    with pytest.raises(LogFormatError, match=r"format_version 2 is newer .* upgrade mexgen-gcs"):
        read_flight_log(path)


@pytest.mark.parametrize("records", [
    ({"t": 1, "type": "mission", "format": "other-log", "format_version": 1},),
    ({"t": 1, "type": "mission", "format_version": 1},),
    ({"t": 1, "type": "telemetry"},),
    ({"hello": "world"},),
    ([1, 2, 3],),
])
def test_not_a_flight_log(tmp_path: Path, records: tuple[object, ...]) -> None:
    path = _write_lines(tmp_path / "f.jsonl", *records)
    with pytest.raises(LogFormatError, match="not a mexgen flight log"):
        read_flight_log(path)


@pytest.mark.parametrize("version", [None, "1", 0, True, 1.0])
def test_unknown_format_version(tmp_path: Path, version: object) -> None:
    path = _write_lines(tmp_path / "f.jsonl", {"t": 1, "type": "mission", "format": FORMAT,
                                               "format_version": version})
    with pytest.raises(LogFormatError, match="unknown flight log format_version"):
        read_flight_log(path)


def test_missing_empty_and_binary(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match="no such flight log"):
        read_flight_log(tmp_path / "none")
    (tmp_path / "empty.jsonl").write_bytes(b"")
    with pytest.raises(LogFormatError, match="empty"):
        read_flight_log(tmp_path / "empty.jsonl")
    (tmp_path / "bin.jsonl").write_bytes(os.urandom(64).replace(b"\n", b"") + b"\n" + b"x")
    with pytest.raises(LogFormatError):
        read_flight_log(tmp_path / "bin.jsonl")


def test_to_jsonable() -> None:
    @dataclass
    class Point:
        x: float
        tags: tuple[str, ...]

    value = {"a": (1, np.float32(2.5)), "b": {np.int16(3)}, "c": Point(math.nan, ("T1",)),
             "d": np.array([[np.nan]]), "e": Path("x/y"), "f": -math.inf, "g": np.bool_(True)}
    assert to_jsonable(value) == {"a": [1, 2.5], "b": [3], "c": {"x": None, "tags": ["T1"]},
                                  "d": [[None]], "e": "x/y", "f": None, "g": True}
    with pytest.raises(TypeError, match="cannot write a object"):
        to_jsonable(object())


def test_jsonl_writer_for_other_files(tmp_path: Path) -> None:
    with JsonlWriter(tmp_path / "deep" / "truth.jsonl", clock=lambda: 9.0) as w:
        w.write("tags", tags=[{"id": "T1", "east_m": np.float64(1.5)}])
    lines = (tmp_path / "deep" / "truth.jsonl").read_text(encoding="utf-8").splitlines()
    assert json.loads(lines[0]) == {"t": 9.0, "type": "tags",
                                    "tags": [{"id": "T1", "east_m": 1.5}]}


def test_writer_checks_each_record_against_its_documented_type(tmp_path: Path) -> None:
    """A record its type does not allow is counted (by the reason a reader gives) and still
    written; the mission's log sink says so once per record type; valid records pass."""
    from mexgen_gcs.mission.logsink import MissionLog

    with JsonlWriter(tmp_path / "f.jsonl", clock=lambda: 1.0,
                     records=records.FLIGHT_ADAPTER) as w:
        said: list[str] = []
        sink = MissionLog(w, on_loss=said.append)
        assert sink.write("event", kind="armed")
        assert sink.write("plan", method="pim")  # no headings, rewards, ...
        assert sink.write("plan", method="pim")
        assert sink.write("future_type", anything=1)  # unknown types are kept, not invalid
        sink.close()  # written by the sink's thread: drained here
    assert dict(w.invalid) == {"invalid plan record": 2} and w.records == 4
    assert len(said) == 1 and "'plan' record does not match" in said[0]
    assert len((tmp_path / "f.jsonl").read_text().splitlines()) == 4


def test_new_log_dir_is_unique(tmp_path: Path) -> None:
    a = new_log_dir(tmp_path, "demo mission", clock=lambda: 0.0)
    b = new_log_dir(tmp_path, "demo mission", clock=lambda: 0.0)
    assert a != b and a.is_dir() and b.is_dir()
    assert a.name.endswith("-demo_mission") and b.name.endswith("-demo_mission-1")
