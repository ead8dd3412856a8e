"""A flight log read into arrays for analysis: telemetry, the receiver's track, detections,
per-tag estimates, plans, events and the result.

Frame: local ENU metres about the mission home (x east, y north, z up), as the log's estimate,
detection and plan records already are; telemetry's WGS84 positions are converted with the
mission's local frame. Headings are compass degrees (0 north, clockwise). Times are unix
seconds of the mission clock (sim time for a sped-up SITL flight).

The log is read by ``io.flightlog.read_flight_log`` (a torn last line is skipped; an unknown or
newer format version raises ``LogFormatError``). The mission is rebuilt from the header's
resolved mission (falling back to the mission file text) with the one config schema.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from mexgen_gcs.config import Mission, parse_mission
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.errors import ConfigError, LogFormatError
from mexgen_gcs.io.flightlog import FlightLog, read_flight_log

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

STAGES = ("predict", "measure", "update", "reward", "total")
"""Planner timing keys in a plan record's ``timing_ms``."""

_TELEMETRY_GAP_S = 1.5
"""Telemetry points closer than this to a detection pose are left out of the track."""
_MAX_PULSE_SKEW_S = 5.0
"""A detection's pose is timed by its pulse time unless that is this far from its arrival."""


def _num(value: Any) -> float:
    """A logged number; null (NaN/inf when written) and non-numbers become NaN."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)


def _nums(values: Iterable[Any]) -> FloatArray:
    return np.array([_num(v) for v in values], dtype=np.float64)


@dataclass(frozen=True, slots=True)
class Track:
    """Time-ordered receiver poses (K,): the flight path as the GCS knew it."""

    t: FloatArray
    east_m: FloatArray
    north_m: FloatArray
    up_m: FloatArray
    yaw_deg: FloatArray
    """NaN where the source had no heading."""

    def __len__(self) -> int:
        return int(self.t.size)

    def distance_m(self) -> float:
        """Horizontal length of the path, metres."""
        if self.t.size < 2:
            return 0.0
        return float(np.hypot(np.diff(self.east_m), np.diff(self.north_m)).sum())

    def position_at(self, t: FloatArray | float) -> FloatArray:
        """(..., 3) ENU position linearly interpolated at t (clamped to the ends)."""
        if self.t.size == 0:
            raise LogFormatError("the log has no vehicle position to interpolate")
        tt = np.asarray(t, dtype=np.float64)
        return np.stack([np.interp(tt, self.t, self.east_m), np.interp(tt, self.t, self.north_m),
                         np.interp(tt, self.t, self.up_m)], axis=-1)

    def velocity_at(self, t: float, half_window_s: float = 1.0) -> FloatArray:
        """(2,) horizontal velocity [east, north] m/s by central differences over a window."""
        a, b = self.position_at(np.array([t - half_window_s, t + half_window_s]))
        lo = max(t - half_window_s, float(self.t[0]))
        hi = min(t + half_window_s, float(self.t[-1]))
        span = hi - lo
        if span <= 1e-6:
            return np.zeros(2)
        return (b[:2] - a[:2]) / span

    def yaw_at(self, t: float) -> float:
        """Compass heading (deg) of the nearest pose that has one; 0 if none has."""
        ok = np.isfinite(self.yaw_deg)
        if not ok.any():
            return 0.0
        ts = self.t[ok]
        i = int(np.clip(np.searchsorted(ts, t), 1, ts.size - 1)) if ts.size > 1 else 0
        if ts.size > 1 and abs(ts[i - 1] - t) <= abs(ts[i] - t):
            i -= 1
        return float(self.yaw_deg[ok][i])

    def resampled(self, step_s: float) -> Track:
        """The track at a regular time step (time-weighting for heat maps)."""
        if self.t.size < 2:
            return self
        tt = np.arange(self.t[0], self.t[-1] + 1e-9, step_s)
        pos = self.position_at(tt)
        return Track(tt, pos[:, 0], pos[:, 1], pos[:, 2], np.full(tt.size, np.nan))


@dataclass(frozen=True, slots=True)
class Telemetry:
    """Logged telemetry (K,): WGS84 plus ENU from the mission frame."""

    t: FloatArray
    lat_deg: FloatArray
    lon_deg: FloatArray
    east_m: FloatArray
    north_m: FloatArray
    rel_alt_m: FloatArray
    v_east_m_s: FloatArray
    v_north_m_s: FloatArray
    yaw_deg: FloatArray
    battery_percent: FloatArray
    armed: BoolArray
    in_air: BoolArray
    connected: BoolArray
    mode: tuple[str, ...]

    def index_at(self, t: float) -> int | None:
        """Index of the last record at or before t (None before the first)."""
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        return i if i >= 0 else None


@dataclass(frozen=True, slots=True)
class Detections:
    """Detection records (K,) in log order."""

    t: FloatArray
    """Arrival time at the GCS."""
    t_pulse: FloatArray
    """The receiver's pulse time (NaN if absent)."""
    tag: NDArray[np.str_]
    rssi_db: FloatArray
    rx_enu_m: FloatArray
    """(K, 3) receiver east/north/up at the pulse."""
    rx_yaw_deg: FloatArray

    def of_tag(self, tag_id: str) -> NDArray[np.bool_]:
        return self.tag == tag_id

    def pose_times(self) -> FloatArray:
        """When each detection's pose was taken: the pulse time unless it is skewed."""
        tp = self.t_pulse
        ok = np.isfinite(tp) & (np.abs(tp - self.t) <= _MAX_PULSE_SKEW_S)
        return np.where(ok, tp, self.t)


@dataclass(frozen=True, slots=True)
class TagSeries:
    """One tag's estimate records (K,), one per pulse period."""

    tag_id: str
    t: FloatArray
    existence: FloatArray
    east_m: FloatArray
    north_m: FloatArray
    v_east_m_s: FloatArray
    v_north_m_s: FloatArray
    cov_pos_m2: FloatArray
    """(K, 2, 2)."""
    radius_m: FloatArray
    localised: BoolArray
    update: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.t.size)

    def position_at(self, t: FloatArray | float) -> FloatArray:
        """(..., 2) estimated position interpolated at t (clamped to the ends)."""
        tt = np.asarray(t, dtype=np.float64)
        return np.stack([np.interp(tt, self.t, self.east_m), np.interp(tt, self.t, self.north_m)],
                        axis=-1)

    def index_at(self, t: float) -> int | None:
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        return i if i >= 0 else None


@dataclass(frozen=True, slots=True)
class PlanRecord:
    """One logged planning decision."""

    t: float
    method: str
    targets: tuple[str, ...]
    headings_deg: tuple[float, ...]
    rewards: tuple[float | None, ...]
    """None where the action was pruned."""
    chosen_heading_deg: float
    timing_ms: Mapping[str, float]
    vehicle_en_m: tuple[float, float]
    all_pruned: bool


@dataclass(frozen=True)
class FlightData:
    """Everything the analysis reads from one flight log."""

    log: FlightLog
    mission: Mission
    frame: LocalFrame
    area: SearchArea
    telemetry: Telemetry
    track: Track
    detections: Detections
    estimates: dict[str, TagSeries]
    clouds: dict[str, list[tuple[float, FloatArray]]]
    plans: list[PlanRecord]
    events: list[dict[str, Any]]
    errors: list[dict[str, Any]]
    radio_heartbeats: int
    result: dict[str, Any] | None
    t_start: float
    t_end: float
    t_airborne: float | None
    """When the filter cadence started (the mission's time zero for ``after_s``)."""
    extra_counts: dict[str, int] = field(default_factory=dict)

    @property
    def path(self) -> Path:
        """The flight.jsonl file."""
        return self.log.path

    @property
    def log_dir(self) -> Path:
        return self.log.path.parent

    @property
    def header(self) -> dict[str, Any]:
        return self.log.header

    @property
    def method(self) -> str:
        return str(self.header.get("method") or self.mission.planner.method)

    @property
    def seed(self) -> int | None:
        seed = self.header.get("seed")
        return seed if isinstance(seed, int) else None

    @property
    def tag_ids(self) -> tuple[str, ...]:
        return self.mission.tag_ids

    @property
    def torn_last_line(self) -> bool:
        return self.log.torn_last_line

    def events_of(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e.get("kind") == kind]

    def since_airborne(self, t: Any) -> Any:
        """Seconds since airborne (since the log start if it never got airborne); t may be
        a float or an array."""
        return t - (self.t_airborne if self.t_airborne is not None else self.t_start)


def resolve_log_file(path: str | os.PathLike[str]) -> Path:
    """`flight.jsonl` for a log directory or the file itself."""
    p = Path(path)
    return p / "flight.jsonl" if p.is_dir() else p


def mission_from_header(header: Mapping[str, Any], where: str) -> Mission:
    """Rebuild the flown mission from the log header: the resolved mission dict first (what
    flew, overrides included), else the mission file text. LogFormatError if neither parses."""
    problems: list[str] = []
    resolved = header.get("mission")
    if isinstance(resolved, Mapping):
        try:
            return parse_mission(yaml.safe_dump(dict(resolved), sort_keys=False),
                                 source=f"{where} (mission record)")
        except ConfigError as exc:
            problems.append(str(exc))
    text = header.get("mission_text")
    if isinstance(text, str) and text.strip():
        try:
            return parse_mission(text, source=f"{where} (mission_text)")
        except ConfigError as exc:
            problems.append(str(exc))
    detail = "; ".join(problems) if problems else "the mission record has no mission"
    raise LogFormatError(f"{where}: cannot rebuild the mission from the log header: {detail}")


def load_flight(path: str | os.PathLike[str]) -> FlightData:
    """Read a flight log (directory or flight.jsonl) into arrays. Raises LogFormatError."""
    log = read_flight_log(resolve_log_file(path))
    mission = mission_from_header(log.header, str(log.path))
    frame = mission.local_frame()
    by_type: dict[str, list[dict[str, Any]]] = {}
    for rec in log.records:
        by_type.setdefault(str(rec.get("type")), []).append(rec)
    telemetry = _telemetry(by_type.get("telemetry", []), frame)
    detections = _detections(by_type.get("detection", []))
    estimates = _estimates(by_type.get("estimate", []), mission.tag_ids)
    clouds: dict[str, list[tuple[float, FloatArray]]] = {t: [] for t in mission.tag_ids}
    for rec in by_type.get("cloud", []):
        pts = np.asarray([[_num(a), _num(b)] for a, b in rec.get("en_m") or []], dtype=np.float64)
        clouds.setdefault(str(rec.get("tag")), []).append((_num(rec["t"]), pts.reshape(-1, 2)))
    plans = [_plan(r) for r in by_type.get("plan", [])]
    plans.sort(key=lambda p: p.t)
    events = by_type.get("event", [])
    results = by_type.get("result", [])
    result = results[-1] if results else None
    times = [_num(r["t"]) for r in log.records if math.isfinite(_num(r["t"]))]
    t_start = _num(log.header["t"])
    t_end = max(times) if times else t_start
    data = FlightData(
        log=log, mission=mission, frame=frame, area=mission.search_area(), telemetry=telemetry,
        track=_track(telemetry, detections), detections=detections, estimates=estimates,
        clouds=clouds, plans=plans, events=events, errors=by_type.get("error", []),
        radio_heartbeats=len(by_type.get("radio", [])), result=result, t_start=t_start,
        t_end=t_end, t_airborne=_t_airborne(result, events, estimates, mission),
        extra_counts={k: len(v) for k, v in by_type.items()})
    return data


def _telemetry(recs: list[dict[str, Any]], frame: LocalFrame) -> Telemetry:
    recs = sorted(recs, key=lambda r: _num(r["t"]))
    lat = _nums(r.get("lat") for r in recs)
    lon = _nums(r.get("lon") for r in recs)
    east = np.full(lat.size, np.nan)
    north = np.full(lat.size, np.nan)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.any():
        e, n, _ = frame.to_enu(lat[ok], lon[ok], frame.alt0_m)
        east[ok], north[ok] = e, n
    return Telemetry(
        t=_nums(r["t"] for r in recs), lat_deg=lat, lon_deg=lon, east_m=east, north_m=north,
        rel_alt_m=_nums(r.get("rel_alt_m") for r in recs),
        v_east_m_s=_nums(r.get("v_east_m_s") for r in recs),
        v_north_m_s=_nums(r.get("v_north_m_s") for r in recs),
        yaw_deg=_nums(r.get("yaw_deg") for r in recs),
        battery_percent=_nums(r.get("battery_percent") for r in recs),
        armed=np.array([bool(r.get("armed")) for r in recs], dtype=bool),
        in_air=np.array([bool(r.get("in_air")) for r in recs], dtype=bool),
        connected=np.array([bool(r.get("connected")) for r in recs], dtype=bool),
        mode=tuple(str(r.get("mode")) for r in recs))


def _detections(recs: list[dict[str, Any]]) -> Detections:
    rx = np.full((len(recs), 3), np.nan)
    for i, r in enumerate(recs):
        v = r.get("rx_en_m")
        if isinstance(v, list) and len(v) == 3:
            rx[i] = [_num(x) for x in v]
    return Detections(
        t=_nums(r["t"] for r in recs), t_pulse=_nums(r.get("t_pulse") for r in recs),
        tag=np.array([str(r.get("tag")) for r in recs], dtype=np.str_).reshape(-1),
        rssi_db=_nums(r.get("rssi_db") for r in recs), rx_enu_m=rx,
        rx_yaw_deg=_nums(r.get("rx_yaw_deg") for r in recs))


def _estimates(recs: list[dict[str, Any]], tag_ids: tuple[str, ...]) -> dict[str, TagSeries]:
    per: dict[str, list[dict[str, Any]]] = {t: [] for t in tag_ids}
    for r in recs:
        per.setdefault(str(r.get("tag")), []).append(r)
    out: dict[str, TagSeries] = {}
    for tid, rows in per.items():
        rows.sort(key=lambda r: _num(r["t"]))
        cov = np.full((len(rows), 2, 2), np.nan)
        for i, r in enumerate(rows):
            c = r.get("cov_pos_m2")
            if isinstance(c, list) and len(c) == 2:
                cov[i] = [[_num(x) for x in row] for row in c]
        out[tid] = TagSeries(
            tag_id=tid, t=_nums(r["t"] for r in rows),
            existence=_nums(r.get("existence") for r in rows),
            east_m=_nums(r.get("east_m") for r in rows),
            north_m=_nums(r.get("north_m") for r in rows),
            v_east_m_s=_nums(r.get("v_east_m_s") for r in rows),
            v_north_m_s=_nums(r.get("v_north_m_s") for r in rows), cov_pos_m2=cov,
            radius_m=_nums(r.get("radius_m") for r in rows),
            localised=np.array([bool(r.get("localised")) for r in rows], dtype=bool),
            update=tuple(str(r.get("update")) for r in rows))
    return out


def _plan(r: dict[str, Any]) -> PlanRecord:
    timing = r.get("timing_ms") or {}
    ven = r.get("vehicle_en_m") or [math.nan, math.nan]
    return PlanRecord(
        t=_num(r["t"]), method=str(r.get("method")),
        targets=tuple(str(x) for x in r.get("targets") or ()),
        headings_deg=tuple(_num(h) for h in r.get("headings_deg") or ()),
        rewards=tuple(None if x is None else _num(x) for x in r.get("rewards") or ()),
        chosen_heading_deg=_num(r.get("chosen_heading_deg")),
        timing_ms={str(k): _num(v) for k, v in timing.items()},
        vehicle_en_m=(_num(ven[0]), _num(ven[1])), all_pruned=bool(r.get("all_pruned")))


def _track(tel: Telemetry, det: Detections) -> Track:
    """Receiver poses from detections (exact pulse poses) filled in with telemetry where no
    detection pose is near, time-ordered."""
    d_ok = np.all(np.isfinite(det.rx_enu_m), axis=1)
    d_t = det.pose_times()[d_ok]
    d_pos = det.rx_enu_m[d_ok]
    d_yaw = det.rx_yaw_deg[d_ok]
    t_ok = np.isfinite(tel.east_m) & np.isfinite(tel.north_m)
    t_t = tel.t[t_ok]
    if d_t.size and t_t.size:
        sorted_d = np.sort(d_t)
        j = np.clip(np.searchsorted(sorted_d, t_t), 1, sorted_d.size - 1) if sorted_d.size > 1 \
            else np.zeros(t_t.size, dtype=int)
        near = np.minimum(np.abs(sorted_d[j] - t_t), np.abs(sorted_d[np.maximum(j - 1, 0)] - t_t))
        keep = near > _TELEMETRY_GAP_S
    else:
        keep = np.ones(t_t.size, dtype=bool)
    up = np.where(np.isfinite(tel.rel_alt_m), tel.rel_alt_m, 0.0)[t_ok][keep]
    t_all = np.concatenate([d_t, t_t[keep]])
    e_all = np.concatenate([d_pos[:, 0], tel.east_m[t_ok][keep]])
    n_all = np.concatenate([d_pos[:, 1], tel.north_m[t_ok][keep]])
    u_all = np.concatenate([d_pos[:, 2], up])
    y_all = np.concatenate([d_yaw, tel.yaw_deg[t_ok][keep]])
    order = np.argsort(t_all, kind="stable")
    return Track(t_all[order], e_all[order], n_all[order], u_all[order], y_all[order])


def _t_airborne(result: dict[str, Any] | None, events: list[dict[str, Any]],
                estimates: dict[str, TagSeries], mission: Mission) -> float | None:
    """The mission's time zero: exactly t - after_s of a localisation in the result, else the
    offboard start, else one pulse period before the first estimate."""
    if result is not None:
        for info in (result.get("localised") or {}).values():
            if isinstance(info, Mapping):
                t, after = _num(info.get("t")), _num(info.get("after_s"))
                if math.isfinite(t) and math.isfinite(after):
                    return t - after
    for e in events:
        if e.get("kind") == "offboard_started":
            return _num(e["t"])
    firsts = [float(s.t[0]) for s in estimates.values() if len(s)]
    if firsts:
        return min(firsts) - mission.receiver.pulse_period_s
    return None
