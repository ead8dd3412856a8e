"""Damaged logs, as after a bad block on a companion computer's SD card: 1 % of the lines of a
real SITL flight log (and of its truth file) are damaged anywhere after the header -- random
bytes, truncated JSON, valid JSON of the wrong shape -- and `analyze` and `replay` give exactly
the report and the table of the same log without those lines, and say how many records they
skipped and why. A log that is all garbage is refused with exit 2 and a message.
"""

from __future__ import annotations

import json
import math
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mexgen_gcs.cli import main

pytestmark = pytest.mark.e2e


def _random_bytes(line: bytes, rng: np.random.Generator) -> bytes:
    junk = rng.integers(0, 256, size=max(8, len(line)), dtype=np.uint8).tobytes()
    return junk.replace(b"\n", b"\x00")


def _truncated(line: bytes, rng: np.random.Generator) -> bytes:
    return line[: int(rng.integers(1, len(line) - 1))]


def _nan_time(line: bytes, rng: np.random.Generator) -> bytes:
    return json.dumps({**json.loads(line), "t": math.nan}).encode()  # 'NaN': JSON, not a number


def _fields_lost(line: bytes, rng: np.random.Generator) -> bytes:
    rec = json.loads(line)
    return json.dumps({"t": rec["t"], "type": rec["type"]}).encode()  # a plan without its fields


def _wrong_type(line: bytes, rng: np.random.Generator) -> bytes:
    rec = json.loads(line)
    key = next(k for k in rec if k not in ("t", "type"))
    return json.dumps({**rec, key: {"nested": ["wrong"]}}).encode()


DAMAGE: tuple[Callable[[bytes, np.random.Generator], bytes], ...] = (
    _random_bytes, _truncated, _nan_time, _fields_lost, _wrong_type)


def _damage(src: Path, damaged: Path, without: Path, rng: np.random.Generator) -> list[int]:
    """Write `damaged` (1 % of the lines after the first damaged in place, each way in turn)
    and `without` (the same lines removed); return the damaged line numbers (1-based)."""
    lines = src.read_bytes().split(b"\n")
    assert lines[-1] == b""
    lines = lines[:-1]
    n = max(5, round(0.01 * len(lines)))
    chosen = sorted(int(i) for i in rng.choice(np.arange(1, len(lines)), size=n, replace=False))
    out = list(lines)
    for k, i in enumerate(chosen):
        out[i] = DAMAGE[k % len(DAMAGE)](lines[i], rng)
    damaged.write_bytes(b"".join(line + b"\n" for line in out))
    keep = [line for i, line in enumerate(lines) if i not in set(chosen)]
    without.write_bytes(b"".join(line + b"\n" for line in keep))
    return [i + 1 for i in chosen]


@pytest.fixture(scope="module")
def damaged_pair(demo_log: Path, pim_log: Path,
                 tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """For each real log: a damaged copy and a copy without the damaged lines."""
    rng = np.random.default_rng(16)
    base = tmp_path_factory.mktemp("damaged")
    out: dict[str, Any] = {}
    for name, log in (("demo", demo_log), ("pim", pim_log)):
        bad, clean = base / f"{name}-damaged", base / f"{name}-without"
        bad.mkdir()
        clean.mkdir()
        out[name] = {"damaged": bad, "without": clean,
                     "lines": _damage(log / "flight.jsonl", bad / "flight.jsonl",
                                      clean / "flight.jsonl", rng),
                     "truth_lines": _damage(log / "truth.jsonl", bad / "truth.jsonl",
                                            clean / "truth.jsonl", rng)}
    return out


def _skipped(err: str, path: Path) -> int:
    match = re.search(rf"note: {re.escape(str(path))}: (\d+) damaged records? skipped: ", err)
    assert match is not None, err
    return int(match.group(1))


def test_analyze_reports_a_damaged_log_like_the_log_without_those_lines(
        damaged_pair: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    case = damaged_pair["demo"]
    assert main(["analyze", str(case["without"]), "--out", str(tmp_path / "a")]) == 0
    capsys.readouterr()
    assert main(["analyze", str(case["damaged"]), "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert _skipped(err, case["damaged"] / "flight.jsonl") == len(case["lines"]) >= 10
    assert _skipped(err, case["damaged"] / "truth.jsonl") == len(case["truth_lines"]) >= 10
    for reason in ("not UTF-8", "not JSON", "not a record", "invalid "):
        assert reason in err
    a = json.loads((tmp_path / "a" / "summary.json").read_text())
    b = json.loads((tmp_path / "b" / "summary.json").read_text())
    damaged = b["totals"].pop("damaged_records")
    assert sorted(x for lines in damaged.values() for x in lines) == case["lines"]
    truth_damaged = b.pop("truth_damaged_records")
    assert sorted(x for lines in truth_damaged.values() for x in lines) == case["truth_lines"]
    assert a["totals"].pop("damaged_records") == {} and a.pop("truth_damaged_records") == {}
    for s in (a, b):
        s.pop("log_file")
    assert a == b
    assert a["totals"]["plans"] > 10 and a["totals"]["detections"] > 500
    md = (tmp_path / "b" / "report.md").read_text()
    assert f"{len(case['lines'])} damaged records skipped" in md
    assert "Damaged log records | none" in (tmp_path / "a" / "report.md").read_text()


def test_replay_of_a_damaged_log_matches_the_log_without_those_lines(
        damaged_pair: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    case = damaged_pair["pim"]
    assert main(["replay", str(case["without"]), "--headless", "--method", "mexgen"]) == 0
    table_a = capsys.readouterr().out
    assert main(["replay", str(case["damaged"]), "--headless", "--method", "mexgen"]) == 0
    captured = capsys.readouterr()
    assert captured.out == table_a and "chose the recorded heading in" in table_a
    assert _skipped(captured.err, case["damaged"] / "flight.jsonl") == len(case["lines"])


def _garbage(path: Path, lines: int, rng: np.random.Generator) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"".join(_random_bytes(b"x" * 80, rng) + b"\n" for _ in range(lines)))
    return path


@pytest.mark.parametrize("command", ["analyze", "replay"])
def test_a_log_of_garbage_is_refused(command: str, demo_log: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(3)
    garbage = _garbage(tmp_path / "garbage" / "flight.jsonl", 2000, rng)
    assert main([command, str(garbage.parent)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{garbage}: not a mexgen flight log" in err[0], err
    # the header survived, nothing after it did
    header = (demo_log / "flight.jsonl").read_bytes().split(b"\n", 1)[0] + b"\n"
    only = tmp_path / "only-header" / "flight.jsonl"
    shutil.copytree(garbage.parent, only.parent)
    only.write_bytes(header + garbage.read_bytes())
    assert main([command, str(only.parent)]) == 2
    err = capsys.readouterr().err
    assert "nothing usable after the mission record: 2000 damaged records skipped" in err
    assert not (only.parent / "report").exists()
