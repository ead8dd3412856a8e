"""Wire format v1 codec: the contract fixtures (tests/fixtures/wire-v1, documented in
docs/wire-format.md), the JSON Schema, round trips, and fuzzing."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.errors import WireError
from mexgen_gcs.io.wire import (
    MAX_DATAGRAM_BYTES,
    REASONS,
    Detection,
    Heartbeat,
    decode,
    encode,
    encode_detection,
    encode_heartbeat,
)

REPO = Path(__file__).resolve().parents[2]


FIXTURES = REPO / "tests" / "fixtures" / "wire-v1"
SCHEMA = json.loads((REPO / "docs" / "schemas" / "wire-v1.schema.json").read_text())


def load_fixtures(name: str) -> list[dict[str, Any]]:
    rows = []
    for line in (FIXTURES / name).read_text(encoding="utf-8").splitlines():
        if line.strip():
            row = json.loads(line)
            row["bytes"] = (bytes.fromhex(row["payload_hex"]) if "payload_hex" in row
                            else row["payload"].encode("utf-8"))
            rows.append(row)
    return rows


VALID = load_fixtures("valid.jsonl")
INVALID = load_fixtures("invalid.jsonl")


def test_valid_fixtures_follow_the_json_schema() -> None:
    for row in VALID:
        jsonschema.validate(json.loads(row["payload"]), SCHEMA)


# what a JSON Schema of one object cannot say: bytes, size, duplicate keys, JSON syntax (NaN
# and Infinity are not JSON, though Python's parser reads them)
_NOT_IN_SCHEMA = {"not_utf8", "oversized", "duplicate_key", "bad_json", "empty"}


def test_invalid_fixtures_break_the_json_schema() -> None:
    checked = 0
    for row in INVALID:
        if row["reason"] in _NOT_IN_SCHEMA or row["reason"].endswith(("_nan", "_infinity")):
            continue
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(json.loads(row["payload"]), SCHEMA)
        checked += 1
    assert checked >= 10


@pytest.mark.parametrize(("obj", "valid"), [
    ({"v": 1, "type": "detection", "t": 1.0, "freq_hz": 150_100_000, "rssi_db": -50.0}, True),
    ({"v": 1, "type": "detection", "t": 1.0, "tag": "T1", "rssi_db": -50.0, "lat": 1.0}, False),
    ({"v": 1, "type": "detection", "t": 1.0, "tag": "T 1", "rssi_db": -50.0}, False),
    ({"v": 1, "type": "detection", "t": 1.0, "tag": "T1", "rssi_db": -50.0, "extra": 1}, True),
    ({"v": 1, "type": "heartbeat", "t": 1.0, "listening": ["T1", ""]}, False),
    ({"v": 1, "type": "heartbeat", "t": -1.0}, False),
    ({"v": 1, "type": "detection", "t": 1.0, "tag": "T1", "rssi_db": -50.0, "yaw_deg": 400},
     False),
])
def test_schema_and_codec_agree(obj: dict[str, Any], valid: bool) -> None:
    payload = json.dumps(obj).encode()
    if valid:
        jsonschema.validate(obj, SCHEMA)
        decode(payload)
    else:
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(obj, SCHEMA)
        with pytest.raises(WireError):
            decode(payload)


@pytest.mark.parametrize("row", VALID, ids=lambda r: r["payload"][:60])
def test_valid_fixtures_decode(row: dict[str, Any]) -> None:
    event = decode(row["bytes"])
    obj = json.loads(row["bytes"])
    assert event.t == obj["t"]
    if obj["type"] == "detection":
        assert isinstance(event, Detection)
        assert event.rssi_db == obj["rssi_db"]
        assert event.tag == obj.get("tag") and event.freq_hz == obj.get("freq_hz")
        assert event.lat == obj.get("lat") and event.yaw_deg == obj.get("yaw_deg")
    else:
        assert isinstance(event, Heartbeat)
        expected = obj.get("listening")
        assert event.listening == (tuple(expected) if expected is not None else None)
    assert decode(encode(event)) == event


@pytest.mark.parametrize("row", INVALID, ids=lambda r: r["reason"])
def test_invalid_fixtures_rejected_with_their_reason(row: dict[str, Any]) -> None:
    with pytest.raises(WireError) as info:
        decode(row["bytes"])
    assert info.value.reason == row["reason"]
    assert info.value.reason in REASONS


def test_fixture_reasons_are_all_known() -> None:
    assert {row["reason"] for row in INVALID} <= set(REASONS)


BASE = {"v": 1, "type": "detection", "t": 1763700000.25, "tag": "T1", "rssi_db": -48.2}


@pytest.mark.parametrize(("change", "reason"), [
    ({"v": True}, "wrong_version"),
    ({"v": 1.0}, "wrong_version"),
    ({"v": "1"}, "wrong_version"),
    ({"type": None}, "unknown_type"),
    ({"type": 3}, "unknown_type"),
    ({"t": True}, "time_wrong_type"),
    ({"t": None}, "time_wrong_type"),
    ({"t": -1.0}, "time_out_of_range"),
    ({"t": 10**400}, "time_out_of_range"),
    ({"rssi_db": False}, "rssi_wrong_type"),
    ({"rssi_db": 1e6}, "rssi_out_of_range"),
    ({"rssi_db": [1.0]}, "rssi_wrong_type"),
    ({"tag": ""}, "tag_invalid"),
    ({"tag": "a b"}, "tag_invalid"),
    ({"tag": "x" * 65}, "tag_invalid"),
    ({"tag": "\u0007bell"}, "tag_invalid"),
    ({"tag": None}, "tag_wrong_type"),
    ({"freq_hz": 150100000.0}, "freq_wrong_type"),
    ({"freq_hz": True}, "freq_wrong_type"),
    ({"freq_hz": "150100000"}, "freq_wrong_type"),
    ({"freq_hz": 0}, "freq_out_of_range"),
    ({"freq_hz": 10**30}, "freq_out_of_range"),
    ({"lat": 10.0}, "pose_incomplete"),
    ({"lon": 10.0}, "pose_incomplete"),
    ({"lat": 10.0, "lon": 181.0}, "lon_out_of_range"),
    ({"lat": "x", "lon": 1.0}, "lat_wrong_type"),
    ({"alt_m": 1e9}, "alt_out_of_range"),
    ({"yaw_deg": 400.0}, "yaw_out_of_range"),
    ({"yaw_deg": "north"}, "yaw_wrong_type"),
])
def test_field_rejections(change: dict[str, Any], reason: str) -> None:
    obj = {**BASE, **change}
    with pytest.raises(WireError) as info:
        decode(json.dumps(obj).encode())
    assert info.value.reason == reason
    assert reason in REASONS


@pytest.mark.parametrize(("text", "reason"), [
    ('{"v": 1, "type": "detection", "t": NaN, "tag": "T1", "rssi_db": -1}', "time_nan"),
    ('{"v": 1, "type": "detection", "t": Infinity, "tag": "T1", "rssi_db": -1}',
     "time_infinity"),
    ('{"v": 1, "type": "detection", "t": 1, "tag": "T1", "rssi_db": 1e999}', "rssi_infinity"),
    ('{"v": 1, "type": "detection", "t": 1, "tag": "T1", "rssi_db": -1, "lat": NaN, '
     '"lon": 1}', "lat_nan"),
    ('{"v": 1, "v": 1, "type": "detection", "t": 1, "tag": "T1", "rssi_db": -1}',
     "duplicate_key"),
    ('{"v": 1, "t": 1}', "missing_type"),
    ('{"v": 1, "type": "heartbeat"}', "missing_time"),
    ('{"v": 1, "type": "heartbeat", "t": 1, "listening": [1]}', "listening_item_wrong_type"),
    ('{"v": 1, "type": "heartbeat", "t": 1, "listening": [""]}', "listening_item_invalid"),
    ('"detection"', "not_object"),
    ("null", "not_object"),
    ("[" * 700 + "]" * 700, "not_object"),
    ("[" * 700 + "]" * 699, "bad_json"),
    ("\ufeff{}", "bad_json"),
    ("", "empty"),
], ids=lambda v: v[:30] if isinstance(v, str) else None)
def test_text_rejections(text: str, reason: str) -> None:
    with pytest.raises(WireError) as info:
        decode(text.encode("utf-8"))
    assert info.value.reason == reason


def test_unknown_keys_are_ignored() -> None:
    event = decode(json.dumps({**BASE, "snr_db": 12.0, "receiver": "rx1"}).encode())
    assert event == Detection(1763700000.25, "T1", None, -48.2)


def test_size_limit_is_exact() -> None:
    head = json.dumps({**BASE, "pad": ""})
    pad = "x" * (MAX_DATAGRAM_BYTES - len(head))
    exact = json.dumps({**BASE, "pad": pad}).encode()
    assert len(exact) == MAX_DATAGRAM_BYTES
    assert isinstance(decode(exact), Detection)
    with pytest.raises(WireError, match="oversized"):
        decode(json.dumps({**BASE, "pad": pad + "x"}).encode())


def test_encode_examples() -> None:
    payload = encode_detection(1763700000.25, -48.25, tag="T1", freq_hz=150100000)
    assert json.loads(payload) == {"v": 1, "type": "detection", "t": 1763700000.25, "tag": "T1",
                                   "freq_hz": 150100000, "rssi_db": -48.25}
    assert decode(encode_heartbeat(5.0)) == Heartbeat(5.0, None)
    assert decode(encode_heartbeat(5.0, ["T1", "T2"])) == Heartbeat(5.0, ("T1", "T2"))
    # numpy values are accepted and come back as plain Python numbers
    event = decode(encode_detection(np.float64(7.5), np.float32(-50.5), freq_hz=np.int64(150))
                   )
    assert event == Detection(7.5, None, 150, -50.5)
    assert type(event.freq_hz) is int


@pytest.mark.parametrize(("kwargs", "reason"), [
    ({"t": 1.0, "rssi_db": -1.0}, "missing_tag_and_freq"),
    ({"t": math.nan, "rssi_db": -1.0, "tag": "T1"}, "time_nan"),
    ({"t": 1.0, "rssi_db": math.inf, "tag": "T1"}, "rssi_infinity"),
    ({"t": 1.0, "rssi_db": "-1", "tag": "T1"}, "rssi_wrong_type"),
    ({"t": 1.0, "rssi_db": -1.0, "tag": "T 1"}, "tag_invalid"),
    ({"t": 1.0, "rssi_db": -1.0, "freq_hz": -5}, "freq_negative"),
    ({"t": 1.0, "rssi_db": -1.0, "freq_hz": 5.0}, "freq_wrong_type"),
    ({"t": 1.0, "rssi_db": -1.0, "tag": "T1", "lat": 1.0}, "pose_incomplete"),
    ({"t": 1.0, "rssi_db": -1.0, "tag": "T1", "lat": 91.0, "lon": 1.0}, "lat_out_of_range"),
    ({"t": True, "rssi_db": -1.0, "tag": "T1"}, "time_wrong_type"),
])
def test_encode_rejects_what_decode_rejects(kwargs: dict[str, Any], reason: str) -> None:
    with pytest.raises(WireError) as info:
        encode_detection(**kwargs)
    assert info.value.reason == reason


def test_encode_heartbeat_rejects() -> None:
    with pytest.raises(WireError, match="listening_not_list"):
        encode_heartbeat(1.0, "T1")  # type: ignore[arg-type]
    with pytest.raises(WireError, match="oversized"):
        encode_heartbeat(1.0, [f"T{i:04d}" for i in range(300)])


# -- property tests ----------------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)
tag_ids = st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=0x2FFF),
                  min_size=1, max_size=64).filter(lambda s: s.isprintable()
                                                  and not any(c.isspace() for c in s))


@st.composite
def detections(draw: st.DrawFn) -> Detection:
    tag = draw(st.none() | tag_ids)
    freq = draw(st.integers(1, 10**11)) if tag is None else draw(st.none() | st.integers(1, 10**11))
    has_pose = draw(st.booleans())
    return Detection(
        t=draw(st.floats(0.0, 1e11)),
        tag=tag,
        freq_hz=freq,
        rssi_db=draw(st.floats(-200.0, 100.0)),
        lat=draw(st.floats(-90.0, 90.0)) if has_pose else None,
        lon=draw(st.floats(-180.0, 180.0)) if has_pose else None,
        alt_m=draw(st.none() | st.floats(-1000.0, 100_000.0)),
        yaw_deg=draw(st.none() | st.floats(-360.0, 360.0)),
    )


@settings(max_examples=300, deadline=None)
@given(detections())
def test_detection_round_trip(event: Detection) -> None:
    payload = encode(event)
    assert len(payload) <= MAX_DATAGRAM_BYTES
    assert decode(payload) == event


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1e11), st.none() | st.lists(tag_ids, max_size=10).map(tuple))
def test_heartbeat_round_trip(t: float, listening: tuple[str, ...] | None) -> None:
    event = Heartbeat(t, listening)
    assert decode(encode(event)) == event


def _decode_never_raises_other(payload: bytes) -> None:
    try:
        event = decode(payload)
    except WireError as exc:
        assert exc.reason in REASONS
    else:
        assert isinstance(event, Detection | Heartbeat)
        assert decode(encode(event)) == event


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=2000))
def test_fuzz_arbitrary_bytes(payload: bytes) -> None:
    _decode_never_raises_other(payload)


json_values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=12,
)
field_names = st.sampled_from(["v", "type", "t", "tag", "freq_hz", "rssi_db", "lat", "lon",
                               "alt_m", "yaw_deg", "listening"]) | st.text(max_size=8)
plausible = {
    "v": st.just(1) | json_values,
    "type": st.sampled_from(["detection", "heartbeat"]) | json_values,
    "t": st.floats() | st.integers() | json_values,
    "tag": tag_ids | json_values,
    "freq_hz": st.integers() | json_values,
    "rssi_db": st.floats() | json_values,
    "listening": st.lists(tag_ids | json_values, max_size=4) | json_values,
}


@st.composite
def hostile_objects(draw: st.DrawFn) -> dict[str, Any]:
    keys = draw(st.lists(field_names, max_size=10, unique=True))
    return {k: draw(plausible.get(k, json_values)) for k in keys}


@settings(max_examples=1000, deadline=None)
@given(hostile_objects())
def test_fuzz_json_objects(obj: dict[str, Any]) -> None:
    _decode_never_raises_other(json.dumps(obj, allow_nan=True).encode("utf-8"))


@settings(max_examples=300, deadline=None)
@given(json_values)
def test_fuzz_any_json(value: Any) -> None:
    _decode_never_raises_other(json.dumps(value, allow_nan=True).encode("utf-8"))
