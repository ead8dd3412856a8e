"""The typed record definitions: the documented schemas and tables are generated from them and
in sync; each record type accepts what its writer writes and calls anything else damaged;
unknown format versions are refused with a message; the truth reader tolerates damage."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from mexgen_gcs.errors import LogFormatError
from mexgen_gcs.io import record_docs, records
from mexgen_gcs.io.logread import NOT_A_RECORD, NOT_JSON, NOT_UTF8, parse_record
from mexgen_gcs.io.truthfile import TruthTail, read_truth_file

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"

PLAN: dict[str, Any] = {
    "t": 5.0, "type": "plan", "method": "mexgen", "targets": ["T1"],
    "headings_deg": [0.0, 45.0], "rewards": [0.5, None], "chosen_heading_deg": 45.0,
    "timing_ms": {"total": 12.5}, "vehicle_en_m": [1.0, 2.0], "all_pruned": False}
SIM_HEADER: dict[str, Any] = {
    "t": 1000.0, "type": "sim", "mission": "demo", "seed": 7, "speedup": 20.0,
    "start_unix": 1000.0, "wall_start_unix": 1000.0, "sysid": 1,
    "home": {"lat_deg": -34.9, "lon_deg": 138.6, "alt_m": 0.0},
    "mavlink": ["127.0.0.1", 14540], "radio": ["127.0.0.1", 14600],
    "listen": ["127.0.0.1", 14541],
    "tags": [{"id": "T1", "freq_hz": 150100000, "motion": "static", "x_m": 1.0, "y_m": 2.0}],
    "faults": [], "mission_text": "version: 1\n"}
TAG = {"t": 1001.0, "type": "tag", "tag": "T1", "motion": "static", "x_m": 1.0, "y_m": 2.0,
       "vx_m_s": 0.0, "vy_m_s": 0.0, "mode": 0}


def _line(obj: Any) -> bytes:
    return json.dumps(obj).encode()


def test_schemas_and_docs_are_generated_and_in_sync() -> None:
    """docs/schemas/*.json and the tables in docs/*.md are what records.py generates
    (`python -m mexgen_gcs.io.record_docs` rewrites them)."""
    expected = record_docs.expected_files(DOCS)
    assert {p.name for p in expected} >= {"flight-log-v1.schema.json", "truth-v1.schema.json",
                                          "flight-log.md", "truth-file.md"}
    for path, content in expected.items():
        assert path.read_text(encoding="utf-8") == content, f"{path} is out of date"
    assert record_docs.main(["--docs", str(DOCS), "--check"]) == 0


def test_every_record_type_is_documented() -> None:
    text = (DOCS / "flight-log.md").read_text(encoding="utf-8")
    for model in records.FLIGHT_RECORDS:
        name = model.model_fields["type"].annotation.__args__[0]
        assert f"### `{name}`" in text
    truth = (DOCS / "truth-file.md").read_text(encoding="utf-8")
    for model in records.TRUTH_RECORDS:
        assert f"### `{model.model_fields['type'].annotation.__args__[0]}`" in truth


@pytest.mark.parametrize(("record", "model"), [
    (PLAN, records.Plan),
    ({"t": 1.0, "type": "statustext", "severity": "warning", "text": "Low battery"},
     records.StatusText),
    ({"t": 1.0, "type": "event", "kind": "tag_localised", "tag": "T1", "after_s": 12.5},
     records.Event),
    ({"t": 1.0, "type": "detection", "tag": "T1", "rssi_db": -40.0, "t_pulse": 0.9,
      "freq_hz": None, "used": False, "why": "no pose at t_pulse"}, records.Detection),
    ({"t": 1.0, "type": "something_new", "x": 1}, records.Record),
])
def test_valid_records_parse_to_their_type(record: dict[str, Any], model: type) -> None:
    rec = parse_record(_line(record), records.FLIGHT_ADAPTER)
    assert type(rec) is model
    assert rec.to_dict() | {} == {**rec.to_dict(), **record}
    schema = json.loads((DOCS / "schemas" / "flight-log-v1.schema.json").read_text())
    if model is not records.Record:
        jsonschema.validate(record, schema)


@pytest.mark.parametrize(("line", "reason"), [
    (b'{"t": NaN, "type": "event", "kind": "x"}', NOT_A_RECORD),
    (b'{"t": null, "type": "event", "kind": "x"}', NOT_A_RECORD),
    (b'{"t": "yesterday", "type": "event", "kind": "x"}', NOT_A_RECORD),
    (b'{"type": "event", "kind": "x"}', NOT_A_RECORD),
    (b'{"t": 1.0, "kind": "x"}', NOT_A_RECORD),
    (b"[1, 2, 3]", NOT_A_RECORD),
    (b'{"t": 1.0, "type": "plan"}', "invalid plan record"),
    (_line({**PLAN, "headings_deg": "north"}), "invalid plan record"),
    (_line({**PLAN, "all_pruned": "no"}), "invalid plan record"),
    (b'{"t": 1.0, "type": "statustext", "severity": "loud", "text": "x"}',
     "invalid statustext record"),
    (b'{"t": 1.0, "type": "estimate", "tag": "T1", "existence": 1.5}', "invalid estimate record"),
    (b'{"t": 1.0, "type": "plan", "method": "pim"', NOT_JSON),
    (b"[" * 100_000, NOT_JSON),
    (b"\x00\xff\xfe random bytes", NOT_UTF8),
])
def test_damaged_records_are_named_by_reason(line: bytes, reason: str) -> None:
    assert parse_record(line, records.FLIGHT_ADAPTER) == reason


def test_json_schema_rejects_what_the_models_reject() -> None:
    schema = json.loads((DOCS / "schemas" / "flight-log-v1.schema.json").read_text())
    bad = {k: v for k, v in PLAN.items() if k != "chosen_heading_deg"}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
    assert parse_record(_line(bad), records.FLIGHT_ADAPTER) == "invalid plan record"


def _truth(tmp_path: Path, *lines: bytes) -> Path:
    path = tmp_path / "truth.jsonl"
    path.write_bytes(b"".join(line + b"\n" for line in lines))
    return path


def test_truth_file_damage_is_skipped_and_counted(tmp_path: Path) -> None:
    path = _truth(tmp_path, _line(SIM_HEADER), _line(TAG), b"\x07\x08 garbage",
                  _line({**TAG, "x_m": "far"}), _line({**TAG, "t": 1002.0, "x_m": 3.0}))
    truth = read_truth_file(path)
    assert [r.get("x_m") for r in truth.tags()] == [1.0, 3.0]
    assert truth.damage.lines == {NOT_JSON: [3], "invalid tag record": [4]}
    assert truth.header.format_version == 1 and truth.header.format == records.TRUTH_FORMAT


@pytest.mark.parametrize(("header", "message"), [
    ({**SIM_HEADER, "format_version": 2}, r"truth file format_version 2 is newer than this "
                                          r"mexgen-gcs reads \(1\); upgrade mexgen-gcs"),
    ({**SIM_HEADER, "format_version": "1"}, "unknown truth file format_version '1'"),
    ({**SIM_HEADER, "format": "other"}, "not a simulator truth file"),
    ({**SIM_HEADER, "seed": "seven"}, r"the 'sim' header record \(the first line\) is damaged"),
])
def test_truth_file_of_unknown_version_or_bad_header_is_refused(
        tmp_path: Path, header: dict[str, Any], message: str) -> None:
    with pytest.raises(LogFormatError, match=message):
        read_truth_file(_truth(tmp_path, _line(header), _line(TAG)))


def test_truth_file_of_only_damage_is_refused(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match="nothing usable after the 'sim' header"):
        read_truth_file(_truth(tmp_path, _line(SIM_HEADER), b"{", b"[]"))


def test_truth_tail_reads_complete_lines_as_they_come(tmp_path: Path) -> None:
    path = tmp_path / "truth.jsonl"
    tail = TruthTail(path)
    assert tail.read_new() == []
    path.write_bytes(_line(SIM_HEADER) + b"\n" + _line(TAG)[:10])
    assert [r.type for r in tail.read_new()] == ["sim"]
    with path.open("ab") as fh:
        fh.write(_line(TAG)[10:] + b"\nnot json\n")
    assert [r.type for r in tail.read_new()] == ["tag"]
    assert tail.damage.lines == {NOT_JSON: [3]} and tail.read_new() == []
