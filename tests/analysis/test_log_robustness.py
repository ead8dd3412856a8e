"""Damaged and foreign logs: a log torn mid-line (a crash) is analysed; a newer or unknown
format version, or a file that is not a flight log, gets a clear message and exit 2."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from mexgen_gcs.analysis import load_flight
from mexgen_gcs.analysis.cli import cmd_analyze, cmd_replay
from mexgen_gcs.cli import main
from mexgen_gcs.errors import LogFormatError

pytestmark = pytest.mark.e2e


def _copy(log: Path, dest: Path) -> Path:
    dest.mkdir()
    for name in ("flight.jsonl", "truth.jsonl"):
        shutil.copy(log / name, dest / name)
    return dest


def test_log_torn_mid_line_is_analysed(demo_log: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    log = _copy(demo_log, tmp_path / "torn")
    data = (log / "flight.jsonl").read_bytes()
    cut = int(len(data) * 0.6)
    while data[cut - 1:cut] == b"\n" or data[cut:cut + 1] == b"\n":
        cut += 7  # land strictly inside a line
    (log / "flight.jsonl").write_bytes(data[:cut])
    flight = load_flight(log)
    assert flight.torn_last_line and flight.result is None
    assert len(flight.log) == data[:cut].count(b"\n")
    out = tmp_path / "report"
    assert main(["analyze", str(log), "--out", str(out)]) == 0
    assert "torn line" in capsys.readouterr().err
    md = (out / "report.md").read_text()
    assert "torn (partial) line" in md and "log ends without a result" in md
    summary = json.loads((out / "summary.json").read_text())
    assert summary["totals"]["complete"] is False and summary["totals"]["exit_code"] is None


def _with_header(log: Path, dest: Path, **changes: Any) -> Path:
    dest.mkdir()
    lines = (log / "flight.jsonl").read_text().splitlines(keepends=True)
    head = json.loads(lines[0])
    head.update(changes)
    (dest / "flight.jsonl").write_text(json.dumps(head) + "\n" + "".join(lines[1:]))
    return dest


def test_newer_format_version_is_refused_clearly(demo_log: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str],
                                                 make_args: Any) -> None:
    log = _with_header(demo_log, tmp_path / "v99", format_version=99)
    with pytest.raises(LogFormatError, match="format_version 99 is newer"):
        load_flight(log)
    assert main(["analyze", str(log), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "format_version 99 is newer" in err and "upgrade mexgen-gcs" in err
    assert not (tmp_path / "out").exists()
    assert cmd_replay(make_args(log=str(log))) == 2
    assert "format_version 99" in capsys.readouterr().err


def test_unknown_format_and_foreign_files_are_refused(demo_log: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str],
                                                      make_args: Any) -> None:
    log = _with_header(demo_log, tmp_path / "vx", format_version="one")
    assert cmd_analyze(make_args(log=str(log))) == 2
    assert "unknown flight log format_version" in capsys.readouterr().err
    other = tmp_path / "notes.jsonl"
    other.write_text('{"hello": "world"}\n')
    assert cmd_analyze(make_args(log=str(other))) == 2
    assert "not a mexgen flight log" in capsys.readouterr().err
    assert cmd_analyze(make_args(log=str(tmp_path / "missing"))) == 2
    assert "no such flight log" in capsys.readouterr().err
    assert cmd_analyze(make_args(log=str(demo_log), truth=str(other))) == 2
    assert "not a simulator truth file" in capsys.readouterr().err


def test_header_without_a_readable_mission_is_refused(demo_log: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str],
                                                     make_args: Any) -> None:
    log = _with_header(demo_log, tmp_path / "nomission", mission={"version": 1},
                       mission_text="version: 1\n")
    assert cmd_analyze(make_args(log=str(log))) == 2
    assert "cannot rebuild the mission" in capsys.readouterr().err
