"""A flight log read into arrays for analysis: telemetry, the receiver's track, detections,
per-tag estimates, plans, events and the result.

Frame: local ENU metres about the mission home (x east, y north, z up), as the log's estimate,
detection and plan records already are; telemetry's WGS84 positions are converted with the
mission's local frame. Headings are compass degrees (0 north, clockwise). Times are unix
seconds of the mission clock (sim time for a sped-up SITL flight).

The log is read by ``io.flightlog.read_flight_log`` into the typed records of ``io.records``
(damaged records and a torn last line are skipped and counted in ``damage``; an unknown or newer
format version raises ``LogFormatError``). The mission is rebuilt from the header's
resolved mission (falling back to the mission file text) with the one config schema.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from mexgen_gcs.analysis.series import (
    Detections,
    TagSeries,
    Telemetry,
    Track,
    num,
    nums,
)
from mexgen_gcs.config import Mission, parse_mission
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.errors import ConfigError, LogFormatError
from mexgen_gcs.io import records as rec
from mexgen_gcs.io.flightlog import FlightLog, read_flight_log
from mexgen_gcs.io.logread import Damage
from mexgen_gcs.io.records import MissionHeader, Result

FloatArray = NDArray[np.float64]

_TELEMETRY_GAP_S = 1.5
"""Telemetry points closer than this to a detection pose are left out of the track."""


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
    plans: list[rec.Plan]
    events: list[dict[str, Any]]
    """Event records as dicts: `t`, `type`, `kind` plus free fields."""
    errors: list[dict[str, Any]]
    radio_heartbeats: int
    result: Result | None
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
    def header(self) -> MissionHeader:
        return self.log.header

    @property
    def damage(self) -> Damage:
        """Damaged records of the log that were skipped, by reason and line."""
        return self.log.damage

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


def mission_from_header(header: MissionHeader | Mapping[str, Any], where: str) -> Mission:
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
    by_type: dict[str, list[Any]] = {}
    for record in log.records:
        by_type.setdefault(record.type, []).append(record)
    telemetry = _telemetry(by_type.get("telemetry", []), frame)
    detections = _detections(by_type.get("detection", []))
    estimates = _estimates(by_type.get("estimate", []), mission.tag_ids)
    clouds: dict[str, list[tuple[float, FloatArray]]] = {t: [] for t in mission.tag_ids}
    for c in by_type.get("cloud", []):
        pts = np.asarray([[num(e), num(n)] for e, n in c.en_m], dtype=np.float64)
        clouds.setdefault(c.tag, []).append((c.t, pts.reshape(-1, 2)))
    plans: list[rec.Plan] = sorted(by_type.get("plan", []), key=lambda p: p.t)
    events = [e.to_dict() for e in by_type.get("event", [])]
    results: list[Result] = by_type.get("result", [])
    result = results[-1] if results else None
    t_start = log.header.t
    t_end = max((r.t for r in log.records), default=t_start)
    data = FlightData(
        log=log, mission=mission, frame=frame, area=mission.search_area(), telemetry=telemetry,
        track=_track(telemetry, detections), detections=detections, estimates=estimates,
        clouds=clouds, plans=plans, events=events,
        errors=[e.to_dict() for e in by_type.get("error", [])],
        radio_heartbeats=len(by_type.get("radio", [])), result=result, t_start=t_start,
        t_end=t_end, t_airborne=_t_airborne(result, events, estimates, mission),
        extra_counts={k: len(v) for k, v in by_type.items()})
    return data


def _telemetry(recs: list[rec.Telemetry], frame: LocalFrame) -> Telemetry:
    recs = sorted(recs, key=lambda r: r.t)
    lat = nums(r.lat for r in recs)
    lon = nums(r.lon for r in recs)
    east = np.full(lat.size, np.nan)
    north = np.full(lat.size, np.nan)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.any():
        e, n, _ = frame.to_enu(lat[ok], lon[ok], frame.alt0_m)
        east[ok], north[ok] = e, n
    return Telemetry(
        t=nums(r.t for r in recs), lat_deg=lat, lon_deg=lon, east_m=east, north_m=north,
        rel_alt_m=nums(r.rel_alt_m for r in recs),
        v_east_m_s=nums(r.v_east_m_s for r in recs),
        v_north_m_s=nums(r.v_north_m_s for r in recs),
        yaw_deg=nums(r.yaw_deg for r in recs),
        battery_percent=nums(r.battery_percent for r in recs),
        armed=np.array([r.armed for r in recs], dtype=bool),
        in_air=np.array([r.in_air for r in recs], dtype=bool),
        connected=np.array([r.connected for r in recs], dtype=bool),
        mode=tuple(r.mode for r in recs))


def _detections(recs: list[rec.Detection]) -> Detections:
    rx = np.full((len(recs), 3), np.nan)
    for i, r in enumerate(recs):
        if r.rx_en_m is not None:
            rx[i] = [num(x) for x in r.rx_en_m]
    return Detections(
        t=nums(r.t for r in recs), t_pulse=nums(r.t_pulse for r in recs),
        tag=np.array([r.tag for r in recs], dtype=np.str_).reshape(-1),
        rssi_db=nums(r.rssi_db for r in recs), rx_enu_m=rx,
        rx_yaw_deg=nums(r.rx_yaw_deg for r in recs))


def _estimates(recs: list[rec.Estimate], tag_ids: tuple[str, ...]) -> dict[str, TagSeries]:
    per: dict[str, list[rec.Estimate]] = {t: [] for t in tag_ids}
    for r in recs:
        per.setdefault(r.tag, []).append(r)
    out: dict[str, TagSeries] = {}
    for tid, rows in per.items():
        rows.sort(key=lambda r: r.t)
        cov = np.array([[[num(x) for x in row] for row in r.cov_pos_m2] for r in rows],
                       dtype=np.float64).reshape(len(rows), 2, 2)
        out[tid] = TagSeries(
            tag_id=tid, t=nums(r.t for r in rows),
            existence=nums(r.existence for r in rows),
            east_m=nums(r.east_m for r in rows),
            north_m=nums(r.north_m for r in rows),
            v_east_m_s=nums(r.v_east_m_s for r in rows),
            v_north_m_s=nums(r.v_north_m_s for r in rows), cov_pos_m2=cov,
            radius_m=nums(r.radius_m for r in rows),
            localised=np.array([r.localised for r in rows], dtype=bool),
            update=tuple(r.update for r in rows))
    return out


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


def _t_airborne(result: Result | None, events: list[dict[str, Any]],
                estimates: dict[str, TagSeries], mission: Mission) -> float | None:
    """The mission's time zero: exactly t - after_s of a localisation in the result, else the
    offboard start, else one pulse period before the first estimate."""
    if result is not None:
        for info in result.localised.values():
            return info.t - info.after_s
    for e in events:
        if e.get("kind") == "offboard_started":
            return float(e["t"])
    firsts = [float(s.t[0]) for s in estimates.values() if len(s)]
    if firsts:
        return min(firsts) - mission.receiver.pulse_period_s
    return None
