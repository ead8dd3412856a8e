"""Every record a real SITL flight writes -- the controller's and run.py's flight log, the
simulator's truth file -- is valid for its type in io/records.py and validates against the
JSON Schema documented in docs/schemas/, and the readers find nothing damaged in it.

(The experiment runner writes no JSON-lines records: its output is runs.csv and .npz series,
see docs/experiments.md.)
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import jsonschema
import pytest

from mexgen_gcs.io import records
from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.io.truthfile import read_truth_file

pytestmark = pytest.mark.e2e

SCHEMAS = Path(__file__).resolve().parents[2] / "docs" / "schemas"
PER_TYPE = 150
"""Records of each type checked against the JSON Schema (all are checked by the models)."""


def _check_against_schema(path: Path, schema_file: str) -> Counter[str]:
    validator = jsonschema.Draft202012Validator(json.loads((SCHEMAS / schema_file).read_text()))
    seen: Counter[str] = Counter()
    for line in path.read_text(encoding="utf-8").splitlines():
        obj = json.loads(line)
        seen[obj["type"]] += 1
        if seen[obj["type"]] <= PER_TYPE:
            errors = list(validator.iter_errors(obj))
            assert not errors, (obj["type"], [e.message for e in errors][:3])
    return seen


@pytest.mark.parametrize("which", ["demo_log", "pim_log"])
def test_flight_log_records_follow_the_documented_schema(
        which: str, request: pytest.FixtureRequest) -> None:
    log_dir: Path = request.getfixturevalue(which)
    log = read_flight_log(log_dir)
    assert not log.damage and not log.torn_last_line
    assert all(type(r) is not records.Record for r in log)  # every type is a listed one
    seen = _check_against_schema(log_dir / "flight.jsonl", "flight-log-v1.schema.json")
    assert sum(seen.values()) == len(log)
    for kind in ("mission", "telemetry", "detection", "radio", "estimate", "cloud", "plan",
                 "setpoint", "event", "result"):
        assert seen[kind] > 0, kind


@pytest.mark.parametrize("which", ["demo_log", "pim_log"])
def test_truth_records_follow_the_documented_schema(
        which: str, request: pytest.FixtureRequest) -> None:
    log_dir: Path = request.getfixturevalue(which)
    truth = read_truth_file(log_dir)
    assert not truth.damage and not truth.torn_last_line
    assert all(type(r) is not records.Record for r in truth.records)
    seen = _check_against_schema(log_dir / "truth.jsonl", "truth-v1.schema.json")
    assert sum(seen.values()) == len(truth.records)
    for kind in ("sim", "tag", "vehicle", "pulse", "event", "fence", "end"):
        assert seen[kind] > 0, kind
