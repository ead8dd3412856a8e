"""Every record a real flight writes validates against the documented JSON Schema
(docs/schemas/): the controller's flight log and the simulator's truth file of a whole `sitl`
demo flight (the session's `demo_log`), line by line."""

from __future__ import annotations

import json
from pathlib import Path

from jsonschema import Draft202012Validator

SCHEMAS = Path(__file__).resolve().parents[2] / "docs" / "schemas"


def _validator(name: str) -> Draft202012Validator:
    return Draft202012Validator(json.loads((SCHEMAS / name).read_text(encoding="utf-8")))


def _invalid(path: Path, validator: Draft202012Validator) -> tuple[int, list[str]]:
    lines = path.read_text(encoding="utf-8").splitlines()
    bad = [f"{path.name}:{i}: {e.message}" for i, line in enumerate(lines, 1)
           for e in validator.iter_errors(json.loads(line))]
    return len(lines), bad


def test_every_flight_log_record_validates(demo_log: Path) -> None:
    n, bad = _invalid(demo_log / "flight.jsonl", _validator("flight-log-v1.schema.json"))
    assert n > 500 and not bad, bad[:5]


def test_every_truth_record_validates(demo_log: Path) -> None:
    n, bad = _invalid(demo_log / "truth.jsonl", _validator("truth-v1.schema.json"))
    assert n > 500 and not bad, bad[:5]


def test_the_schema_refuses_a_broken_record() -> None:
    v = _validator("flight-log-v1.schema.json")
    assert not v.is_valid({"type": "plan", "t": "soon"})
