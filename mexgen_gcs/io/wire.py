"""Detection wire format v1: codec for the UDP datagrams a radio receiver sends the GCS.

One UTF-8 JSON object per datagram, at most 1400 bytes (docs/wire-format.md, a contract):

- detection: ``{"v": 1, "type": "detection", "t": <unix s>, "tag": "<id>", "freq_hz": <int>,
  "rssi_db": <float>}`` with at least one of ``tag``/``freq_hz``, and optionally the receiver
  pose at the pulse: ``lat``, ``lon`` (degrees WGS84, together), ``alt_m`` (AMSL), ``yaw_deg``
  (compass heading, 0 = north, clockwise; NED-style heading, not an ENU angle).
- heartbeat: ``{"v": 1, "type": "heartbeat", "t": <unix s>, "listening": ["<id>", ...]}``,
  ``listening`` absent = all tags.

`decode` checks syntax and value ranges only; what needs the mission (known tags, frequency
tolerance, allowed sources, clock skew) is the receiver's job. Every rejection is a WireError
whose `reason` is a stable counter key (see REASONS). Keys this version does not know are
ignored, so senders may add diagnostics. `encode_*` refuse whatever `decode` would refuse, so
anything encoded here decodes to an equal value.
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import dataclass
from typing import Any

from mexgen_gcs.errors import WireError

VERSION = 1
MAX_DATAGRAM_BYTES = 1400
MAX_TAG_ID_CHARS = 64
RSSI_RANGE_DB = (-200.0, 100.0)
FREQ_MAX_HZ = 100_000_000_000

#: Every reason `decode` can give, for counters and documentation.
REASONS: tuple[str, ...] = (
    "empty", "oversized", "not_utf8", "bad_json", "duplicate_key", "not_object",
    "missing_version", "wrong_version", "missing_type", "unknown_type",
    "missing_time", "time_wrong_type", "time_nan", "time_infinity", "time_out_of_range",
    "missing_rssi", "rssi_wrong_type", "rssi_nan", "rssi_infinity", "rssi_out_of_range",
    "missing_tag_and_freq", "tag_wrong_type", "tag_invalid",
    "freq_wrong_type", "freq_negative", "freq_out_of_range",
    "lat_wrong_type", "lat_nan", "lat_infinity", "lat_out_of_range",
    "lon_wrong_type", "lon_nan", "lon_infinity", "lon_out_of_range",
    "alt_wrong_type", "alt_nan", "alt_infinity", "alt_out_of_range",
    "yaw_wrong_type", "yaw_nan", "yaw_infinity", "yaw_out_of_range",
    "pose_incomplete", "listening_not_list", "listening_item_wrong_type",
    "listening_item_invalid",
)

# field -> (reason prefix, lowest, highest)
_RANGES: dict[str, tuple[str, float, float]] = {
    "t": ("time", 0.0, 1e11),
    "rssi_db": ("rssi", *RSSI_RANGE_DB),
    "lat": ("lat", -90.0, 90.0),
    "lon": ("lon", -180.0, 180.0),
    "alt_m": ("alt", -1000.0, 100_000.0),
    "yaw_deg": ("yaw", -360.0, 360.0),
}


@dataclass(frozen=True, slots=True)
class Detection:
    """A detected pulse. `t` unix seconds; pose fields None when the receiver did not send it."""

    t: float
    tag: str | None
    freq_hz: int | None
    rssi_db: float
    lat: float | None = None
    lon: float | None = None
    alt_m: float | None = None
    yaw_deg: float | None = None

    @property
    def has_position(self) -> bool:
        return self.lat is not None and self.lon is not None


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """The receiver is alive; `listening` = tags it listened for (None = all)."""

    t: float
    listening: tuple[str, ...] | None = None


# -- decode ------------------------------------------------------------------------------

def decode(payload: bytes) -> Detection | Heartbeat:
    """Parse one datagram. Raises WireError(reason) for anything that is not valid v1."""
    if not payload:
        raise WireError("empty", "zero-length datagram")
    if len(payload) > MAX_DATAGRAM_BYTES:
        raise WireError("oversized", f"{len(payload)} bytes > {MAX_DATAGRAM_BYTES}")
    try:
        text = bytes(payload).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise WireError("not_utf8", f"byte {exc.start} is not UTF-8") from None
    try:
        obj = json.loads(text, object_pairs_hook=_no_duplicates)
    except _DuplicateKeyError as exc:
        raise WireError("duplicate_key", str(exc)) from None
    except (ValueError, RecursionError) as exc:
        raise WireError("bad_json", str(exc)[:100]) from None
    if not isinstance(obj, dict):
        raise WireError("not_object", f"top level is a {type(obj).__name__}")
    if "v" not in obj:
        raise WireError("missing_version", "no 'v' key")
    v = obj["v"]
    if type(v) is not int or v != VERSION:
        raise WireError("wrong_version", f"v = {_short(v)}, expected {VERSION}")
    if "type" not in obj:
        raise WireError("missing_type", "no 'type' key")
    kind = obj["type"]
    if kind == "detection":
        return _decode_detection(obj)
    if kind == "heartbeat":
        return _decode_heartbeat(obj)
    raise WireError("unknown_type", f"type = {_short(kind)}")


class _DuplicateKeyError(ValueError):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKeyError(f"key {key[:20]!r} appears twice")
        out[key] = value
    return out


def _decode_detection(obj: dict[str, Any]) -> Detection:
    t = _number(obj, "t", required=True)
    if "rssi_db" not in obj:
        raise WireError("missing_rssi", "no 'rssi_db' key")
    rssi_db = _number(obj, "rssi_db", required=True)
    tag = _tag(obj["tag"], "tag") if "tag" in obj else None
    freq_hz = _freq(obj["freq_hz"]) if "freq_hz" in obj else None
    if tag is None and freq_hz is None:
        raise WireError("missing_tag_and_freq", "a detection needs 'tag' or 'freq_hz'")
    lat, lon = _number(obj, "lat"), _number(obj, "lon")
    if (lat is None) != (lon is None):
        raise WireError("pose_incomplete", "'lat' and 'lon' come together")
    assert t is not None and rssi_db is not None
    return Detection(t, tag, freq_hz, rssi_db, lat, lon, _number(obj, "alt_m"),
                     _number(obj, "yaw_deg"))


def _decode_heartbeat(obj: dict[str, Any]) -> Heartbeat:
    t = _number(obj, "t", required=True)
    assert t is not None
    if "listening" not in obj:
        return Heartbeat(t, None)
    listening = obj["listening"]
    if not isinstance(listening, list):
        raise WireError("listening_not_list", f"listening is a {type(listening).__name__}")
    return Heartbeat(t, tuple(_tag(item, "listening_item") for item in listening))


def _number(obj: dict[str, Any], key: str, *, required: bool = False) -> float | None:
    prefix = _RANGES[key][0]
    if key not in obj:
        if required:
            raise WireError(f"missing_{prefix}", f"no {key!r} key")
        return None
    return check_number(obj[key], key)


def check_number(value: Any, key: str) -> float:
    """A finite float in the field's range, or WireError(<prefix>_wrong_type/_nan/...)."""
    prefix, lo, hi = _RANGES[key]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise WireError(f"{prefix}_wrong_type", f"{key} = {_short(value)} is not a number")
    try:
        x = float(value)
    except OverflowError:
        raise WireError(f"{prefix}_out_of_range", f"{key} is too large") from None
    if math.isnan(x):
        raise WireError(f"{prefix}_nan", f"{key} is NaN")
    if math.isinf(x):
        raise WireError(f"{prefix}_infinity", f"{key} is infinite")
    if not lo <= x <= hi:
        raise WireError(f"{prefix}_out_of_range", f"{key} = {x!r} outside [{lo:g}, {hi:g}]")
    return x


def _tag(value: Any, prefix: str) -> str:
    if not isinstance(value, str):
        raise WireError(f"{prefix}_wrong_type", f"{prefix} = {_short(value)} is not a string")
    if not 0 < len(value) <= MAX_TAG_ID_CHARS or not value.isprintable() or \
            any(c.isspace() for c in value):
        reason = "tag_invalid" if prefix == "tag" else "listening_item_invalid"
        raise WireError(reason, f"{_short(value)} is not a tag id (1-{MAX_TAG_ID_CHARS} "
                        "printable characters, no spaces)")
    return value


def _freq(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise WireError("freq_wrong_type", f"freq_hz = {_short(value)} is not an integer")
    f = int(value)
    if f < 0:
        raise WireError("freq_negative", f"freq_hz = {f}")
    if not 0 < f <= FREQ_MAX_HZ:
        raise WireError("freq_out_of_range", f"freq_hz = {_short(f)} outside 1..{FREQ_MAX_HZ}")
    return f


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


# -- encode ------------------------------------------------------------------------------

def encode_detection(
    t: float,
    rssi_db: float,
    tag: str | None = None,
    freq_hz: int | None = None,
    lat: float | None = None,
    lon: float | None = None,
    alt_m: float | None = None,
    yaw_deg: float | None = None,
) -> bytes:
    """One detection datagram. Raises WireError for anything decode would reject."""
    obj: dict[str, Any] = {"v": VERSION, "type": "detection", "t": check_number(t, "t")}
    if tag is not None:
        obj["tag"] = _tag(tag, "tag")
    if freq_hz is not None:
        obj["freq_hz"] = _freq(freq_hz)
    if tag is None and freq_hz is None:
        raise WireError("missing_tag_and_freq", "a detection needs tag or freq_hz")
    obj["rssi_db"] = check_number(rssi_db, "rssi_db")
    if (lat is None) != (lon is None):
        raise WireError("pose_incomplete", "lat and lon come together")
    for key, value in (("lat", lat), ("lon", lon), ("alt_m", alt_m), ("yaw_deg", yaw_deg)):
        if value is not None:
            obj[key] = check_number(value, key)
    return _dump(obj)


def encode_heartbeat(t: float, listening: tuple[str, ...] | list[str] | None = None) -> bytes:
    """One heartbeat datagram; `listening` None = all tags."""
    obj: dict[str, Any] = {"v": VERSION, "type": "heartbeat", "t": check_number(t, "t")}
    if listening is not None:
        if isinstance(listening, str):
            raise WireError("listening_not_list", "listening must be a list of tag ids")
        obj["listening"] = [_tag(item, "listening_item") for item in listening]
    return _dump(obj)


def encode(event: Detection | Heartbeat) -> bytes:
    """Encode a decoded event again (decode(encode(e)) == e)."""
    if isinstance(event, Heartbeat):
        return encode_heartbeat(event.t, event.listening)
    return encode_detection(event.t, event.rssi_db, event.tag, event.freq_hz, event.lat,
                            event.lon, event.alt_m, event.yaw_deg)


def _dump(obj: dict[str, Any]) -> bytes:
    payload = json.dumps(obj, separators=(",", ":"), allow_nan=False).encode("utf-8")
    if len(payload) > MAX_DATAGRAM_BYTES:
        raise WireError("oversized", f"{len(payload)} bytes > {MAX_DATAGRAM_BYTES}")
    return payload
