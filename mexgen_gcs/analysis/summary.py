"""The numbers of a flight report: mission totals, per-tag results and planner timing.

Frame: local ENU metres about home for east_m/north_m; WGS84 degrees for lat/lon. Times:
``*_after_s`` are seconds since airborne (the mission's time zero, as in the tag_localised
events); other times are unix seconds of the mission clock.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np

from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.series import STAGES
from mexgen_gcs.analysis.truth import Truth

#: event kinds that are failsafes or faults worth listing (besides safety events with an
#: action and error records)
NOTABLE_EVENTS = frozenset({
    "planner_overrun", "planner_error", "geofence_not_accepted", "rtl_failed",
    "landing_not_confirmed", "preflight_failed", "flight_error", "mission_error",
    "offboard_resumed", "resume_failed", "setpoint_failed", "detection_unused",
    "command_dropped", "operator_command",
})


@dataclass(frozen=True, slots=True)
class TagSummary:
    tag_id: str
    freq_hz: int
    detections: int
    mean_rssi_db: float | None
    max_rssi_db: float | None
    localised: bool
    localised_after_s: float | None
    """From the tag_localised event (seconds since airborne)."""
    localised_t: float | None
    """Unix time of the pulse at which the tag was localised."""
    localised_east_m: float | None
    localised_north_m: float | None
    localised_lat_deg: float | None
    localised_lon_deg: float | None
    localised_radius_m: float | None
    final_t: float | None
    final_east_m: float | None
    final_north_m: float | None
    final_lat_deg: float | None
    final_lon_deg: float | None
    final_radius_m: float | None
    """Uncertainty radius at the mission's localisation confidence."""
    final_sigma_major_m: float | None
    """1-sigma semi-major axis of the position covariance."""
    final_existence: float | None
    error_at_localisation_m: float | None
    """Distance from the estimate at localisation to the truth at that moment."""
    final_error_m: float | None
    """Distance from the final estimate to the truth at that moment."""
    tracking_rms_error_m: float | None
    """Root mean square distance between estimate and truth over all estimate records (the
    object-following metric)."""
    inside_claimed_radius: bool | None = None
    """Was the truth inside the radius claimed at localisation? None without truth or
    without a localisation."""
    inside_final_radius: bool | None = None
    """Was the truth inside the final estimate's radius (localised or not)? None without
    truth or without an estimate."""
    reported_reason: str | None = None
    """Why the tag was reported (reached, stalled, budget; the result record's reports), None
    if it was not (or the log predates reporting)."""
    reported_after_s: float | None = None
    reported_radius_m: float | None = None


@dataclass(frozen=True, slots=True)
class StageTiming:
    method: str
    stage: str
    plans: int
    median_ms: float
    p95_ms: float
    max_ms: float


@dataclass(frozen=True, slots=True)
class SafetyEvent:
    t: float
    after_s: float
    kind: str
    detail: str


@dataclass(frozen=True, slots=True)
class MissionTotals:
    name: str
    kind: str
    method: str
    methods_used: tuple[str, ...]
    seed: int | None
    start_utc: str
    duration_s: float
    airborne_s: float | None
    distance_flown_m: float
    end_reason: str
    exit_code: int | None
    complete: bool
    """The log ends with its result record."""
    torn_last_line: bool
    damaged_records: dict[str, list[int]]
    """Damaged records of the log that were skipped: reason -> line numbers."""
    tags_total: int
    tags_localised: int
    detections: int
    heartbeats: int
    plans: int
    radio_rejects: dict[str, int]
    software: dict[str, Any]


@dataclass(frozen=True, slots=True)
class FlightSummary:
    log_file: str
    totals: MissionTotals
    tags: tuple[TagSummary, ...]
    timing: tuple[StageTiming, ...]
    safety_events: tuple[SafetyEvent, ...]
    has_truth: bool
    truth_damaged_records: dict[str, list[int]]
    """Damaged records of the truth file that were skipped: reason -> line numbers."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def tag(self, tag_id: str) -> TagSummary:
        for t in self.tags:
            if t.tag_id == tag_id:
                return t
        raise KeyError(tag_id)


def _opt(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def summarise(flight: FlightData, truth: Truth | None = None) -> FlightSummary:
    """Compute the report's numbers from a flight (and the ground truth, if given)."""
    return FlightSummary(
        log_file=str(flight.path), totals=mission_totals(flight),
        tags=tuple(tag_summary(flight, tid, truth) for tid in flight.tag_ids),
        timing=planner_timing(flight), safety_events=safety_events(flight),
        has_truth=truth is not None,
        truth_damaged_records=dict(truth.damage.lines) if truth is not None else {})


def mission_totals(flight: FlightData) -> MissionTotals:
    result = flight.result
    mission_end = flight.events_of("mission_end")
    if result is not None:
        end_reason = str(result.get("end_reason"))
        exit_code: int | None = int(result.get("exit_code", 1))
        duration = float(result.get("duration_s") or (flight.t_end - flight.t_start))
        rejects = {str(k): int(v) for k, v in (result.get("rejects") or {}).items()}
    else:
        end_reason = (str(mission_end[-1].get("reason")) + " (log ends before the result)"
                      if mission_end else "unknown: the log ends without a result (crash?)")
        exit_code = None
        duration = flight.t_end - flight.t_start
        rejects = {}
    landed = flight.events_of("landed_and_disarmed")
    airborne_s = None
    if flight.t_airborne is not None:
        airborne_s = (float(landed[-1]["t"]) if landed else flight.t_end) - flight.t_airborne
    localised = sum(1 for tid in flight.tag_ids if _localised_event(flight, tid) is not None
                    or bool(flight.estimates[tid].localised.any()))
    methods = tuple(dict.fromkeys(p.method for p in flight.plans)) or (flight.method,)
    start = datetime.fromtimestamp(flight.t_start, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    return MissionTotals(
        name=flight.mission.name, kind=flight.mission.kind, method=flight.method,
        methods_used=methods, seed=flight.seed, start_utc=start, duration_s=duration,
        airborne_s=airborne_s, distance_flown_m=flight.track.distance_m(),
        end_reason=end_reason, exit_code=exit_code, complete=result is not None,
        torn_last_line=flight.torn_last_line, damaged_records=dict(flight.damage.lines),
        tags_total=len(flight.tag_ids),
        tags_localised=localised, detections=int(flight.detections.t.size),
        heartbeats=flight.radio_heartbeats, plans=len(flight.plans), radio_rejects=rejects,
        software=dict(flight.header.get("versions") or {}))


def _localised_event(flight: FlightData, tag_id: str) -> dict[str, Any] | None:
    for e in flight.events_of("tag_localised"):
        if e.get("tag") == tag_id:
            return e
    return None


def tag_summary(flight: FlightData, tag_id: str, truth: Truth | None) -> TagSummary:
    det = flight.detections
    sel = det.of_tag(tag_id)
    rssi = det.rssi_db[sel]
    rssi = rssi[np.isfinite(rssi)]
    series = flight.estimates[tag_id]
    event = _localised_event(flight, tag_id)
    loc_i: int | None = None
    if series.localised.any():
        loc_i = int(np.argmax(series.localised))
    after_s = None
    if event is not None and isinstance(event.get("after_s"), int | float):
        after_s = float(event["after_s"])
    elif loc_i is not None:
        after_s = float(flight.since_airborne(float(series.t[loc_i])))
    frame = flight.frame

    def geo(e: float, n: float) -> tuple[float | None, float | None]:
        if not (math.isfinite(e) and math.isfinite(n)):
            return None, None
        lat, lon, _ = frame.to_geodetic(e, n, 0.0)
        return float(lat), float(lon)

    loc_fields: dict[str, Any] = dict.fromkeys(
        ("t", "e", "n", "lat", "lon", "r", "err"))
    if loc_i is not None:
        e, n = float(series.east_m[loc_i]), float(series.north_m[loc_i])
        t = float(series.t[loc_i])
        lat, lon = geo(e, n)
        loc_fields.update(t=t, e=e, n=n, lat=lat, lon=lon, r=_opt(float(series.radius_m[loc_i])),
                          err=truth.error_m(tag_id, t, e, n) if truth is not None else None)
    fin: dict[str, Any] = dict.fromkeys(("t", "e", "n", "lat", "lon", "r", "sig", "q", "err"))
    if len(series):
        e, n, t = float(series.east_m[-1]), float(series.north_m[-1]), float(series.t[-1])
        lat, lon = geo(e, n)
        cov = series.cov_pos_m2[-1]
        sig = (float(math.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0)))
               if np.all(np.isfinite(cov)) else None)
        fin.update(t=t, e=_opt(e), n=_opt(n), lat=lat, lon=lon,
                   r=_opt(float(series.radius_m[-1])), sig=sig,
                   q=_opt(float(series.existence[-1])),
                   err=truth.error_m(tag_id, t, e, n) if truth is not None else None)
    rms = None
    if truth is not None and tag_id in truth.tags and len(series):
        te = truth.tags[tag_id].position_at(series.t)
        d2 = (series.east_m - te[:, 0]) ** 2 + (series.north_m - te[:, 1]) ** 2
        d2 = d2[np.isfinite(d2)]
        rms = float(np.sqrt(d2.mean())) if d2.size else None
    return TagSummary(
        tag_id=tag_id, freq_hz=flight.mission.tag(tag_id).freq_hz, detections=int(sel.sum()),
        mean_rssi_db=float(rssi.mean()) if rssi.size else None,
        max_rssi_db=float(rssi.max()) if rssi.size else None,
        localised=loc_i is not None or event is not None, localised_after_s=after_s,
        localised_t=loc_fields["t"], localised_east_m=loc_fields["e"],
        localised_north_m=loc_fields["n"], localised_lat_deg=loc_fields["lat"],
        localised_lon_deg=loc_fields["lon"], localised_radius_m=loc_fields["r"],
        final_t=fin["t"], final_east_m=fin["e"], final_north_m=fin["n"],
        final_lat_deg=fin["lat"], final_lon_deg=fin["lon"], final_radius_m=fin["r"],
        final_sigma_major_m=fin["sig"], final_existence=fin["q"],
        error_at_localisation_m=loc_fields["err"], final_error_m=fin["err"],
        tracking_rms_error_m=rms,
        inside_claimed_radius=None if loc_fields["err"] is None or loc_fields["r"] is None
        else bool(loc_fields["err"] <= loc_fields["r"]),
        inside_final_radius=None if fin["err"] is None or fin["r"] is None
        else bool(fin["err"] <= fin["r"]),
        **_reported(flight, tag_id))


def _reported(flight: FlightData, tag_id: str) -> dict[str, Any]:
    """The result record's report of a tag: reason, seconds after airborne, radius."""
    reports = flight.result.get("reports") if flight.result is not None else None
    rep = (reports or {}).get(tag_id)
    if rep is None:
        return {}
    return {"reported_reason": str(rep.reason), "reported_after_s": float(rep.after_s),
            "reported_radius_m": _opt(float(rep.radius_m)) if rep.radius_m is not None
            else None}


def planner_timing(flight: FlightData) -> tuple[StageTiming, ...]:
    """Median, 95th percentile and maximum wall time per planner stage and method (ms)."""
    out: list[StageTiming] = []
    methods = dict.fromkeys(p.method for p in flight.plans)
    for method in methods:
        plans = [p for p in flight.plans if p.method == method]
        for stage in STAGES:
            v = np.array([p.timing_ms.get(stage, math.nan) for p in plans], dtype=np.float64)
            v = v[np.isfinite(v)]
            if v.size == 0:
                continue
            out.append(StageTiming(method, stage, int(v.size), float(np.median(v)),
                                   float(np.percentile(v, 95)), float(v.max())))
    return tuple(out)


def safety_events(flight: FlightData) -> tuple[SafetyEvent, ...]:
    """Failsafes and faults: safety decisions with an action, notable events, error records."""
    out: list[SafetyEvent] = []
    skip = {"t", "type", "kind"}
    records = sorted([*flight.events, *flight.errors], key=lambda r: float(r["t"]))
    for rec in records:
        kind = str(rec.get("kind"))
        is_error = rec.get("type") == "error"
        if kind == "safety":  # actions, and the return to normal after one
            if rec.get("action") in (None, "none") and rec.get("reason") == "ok" and (
                    not out or out[-1].kind != "safety"):
                continue
        elif not is_error and kind not in NOTABLE_EVENTS:
            continue
        t = float(rec["t"])
        detail = ", ".join(f"{k}={v}" for k, v in rec.items() if k not in skip)
        out.append(SafetyEvent(t, float(flight.since_airborne(t)),
                               ("error: " if is_error else "") + kind, detail))
    out.sort(key=lambda e: e.t)
    return tuple(out)
