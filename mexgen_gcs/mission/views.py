"""Views of a running mission: the published snapshot, the headless progress line and the
final result. Pure functions of the mission's state object (``MissionContext``).

Frames: ENU metres about home for the map, WGS84 for display positions.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mexgen_gcs.io.snapshot import MissionSnapshot, TagView
from mexgen_gcs.mission.state import SETUP_REFUSED, SUCCESS, MissionResult

if TYPE_CHECKING:
    from mexgen_gcs.mission.context import MissionContext


def progress_line(c: MissionContext) -> str:
    tel = c.vehicle.hub.latest
    done = len(c.core.localised)
    return (f"[{c.clock.now() - c.t_start:6.0f}s] {c.state.value:<10} "
            f"mode={tel.flight_mode} "
            f"alt={tel.rel_alt_m:5.1f}m speed={tel.ground_speed_m_s:4.1f}m/s "
            f"bat={tel.battery_percent:4.0f}% localised={done}/{len(c.core.tag_ids)} "
            f"heading={c.heading_deg if c.heading_deg is not None else '-'}")


def build_snapshot(c: MissionContext) -> MissionSnapshot:
    t = c.clock.now()
    tel = c.vehicle.hub.latest
    truth = c.truth() if c.truth is not None else {}
    tags = []
    for spec in c.mission.tags:
        tid = spec.id
        est = c.core.filters[tid].estimate()
        lat, lon, _ = c.frame.to_geodetic(est.mean[0], est.mean[1])
        loc = c.core.localised.get(tid)
        recent = sum(1 for x in c.det_times[tid] if t - x <= 60.0)
        cloud = c.core.particle_cloud(tid, 150)
        tags.append(TagView(
            tag_id=tid, freq_hz=spec.freq_hz, existence=est.existence, lat_deg=float(lat),
            lon_deg=float(lon), east_m=float(est.mean[0]), north_m=float(est.mean[1]),
            radius_m=est.radius_m,
            cov_pos_m2=(float(est.cov_pos[0, 0]), float(est.cov_pos[0, 1]),
                        float(est.cov_pos[1, 1])),
            localised=loc is not None,
            reported=(rep.reason if (rep := c.core.reported.get(tid)) is not None else None),
            localised_at_s=None if loc is None else loc.t - (c.t_airborne or c.t_start),
            detections_last_min=recent, detections_total=c.core.detections[tid],
            last_rssi_db=c.core.last_rssi_db.get(tid),
            cloud_en_m=tuple(map(tuple, cloud.tolist())), truth_en_m=truth.get(tid)))
    e, n, _ = c.frame.to_enu(tel.lat_deg, tel.lon_deg, tel.abs_alt_m)
    warnings = []
    if not tel.connected or c.vehicle.hub.age_s() > c.mission.safety.link_loss_timeout_s:
        warnings.append("VEHICLE LINK LOST")
    hb_age = t - c.last_heartbeat_t
    if hb_age > c.mission.receiver.heartbeat_timeout_s:
        warnings.append("RADIO SILENT")
    if math.isfinite(tel.battery_percent) and (
            tel.battery_percent < c.mission.safety.battery_rtl_percent + 10):
        warnings.append(f"BATTERY {tel.battery_percent:.0f}%")
    if c.hold_reason:
        warnings.append(f"HOLD: {c.hold_reason}")
    if c.takeover is not None and not c.commander.in_control:
        warnings.append(f"AUTOPILOT HAS CONTROL: {c.takeover.mode}")
    if c.log.lost:
        warnings.append(f"FLIGHT LOG: {c.log.lost} RECORDS LOST")
    if len(c.track) and c.area.distance_outside_m(np.array(c.track[-1])) > 0:
        warnings.append("OUTSIDE SEARCH AREA")
    warnings.extend(c.standing_warnings.values())
    stats = c.receiver.stats()
    return MissionSnapshot(
        t=t, elapsed_s=t - c.t_start, state=c.state.value,
        end_reason=None if c.end_reason is None else c.end_reason.value,
        telemetry=tel, vehicle_en_m=(float(e), float(n)), track_en_m=tuple(c.track),
        tags=tuple(tags), plan=c.last_plan,
        next_plan_in_s=max(c.next_plan_t - t, 0.0), radio_heartbeat_age_s=hb_age,
        radio_accepted=stats.accepted, radio_rejects=dict(stats.rejects),
        warnings=tuple(warnings), events=tuple(c.events)[-20:], method=c.method,
        link_ok=tel.connected, area_en_m=tuple(map(tuple, c.area.vertices_m.tolist())))


def build_result(c: MissionContext) -> MissionResult:
    reason = c.end_reason or "aborted"
    ok = reason in SUCCESS and c.landed_ok and c.error is None
    localised = {}
    for tid, rec in c.core.localised.items():
        lat, lon, _ = c.frame.to_geodetic(rec.estimate.mean[0], rec.estimate.mean[1])
        localised[tid] = {"t": rec.t, "after_s": rec.t - (c.t_airborne or c.t_start),
                          "lat": float(lat), "lon": float(lon),
                          "east_m": float(rec.estimate.mean[0]),
                          "north_m": float(rec.estimate.mean[1]),
                          "radius_m": rec.estimate.radius_m}
    unresolved = {}
    for tid, est in c.core.estimates().items():
        if tid in localised:
            continue
        lat, lon, _ = c.frame.to_geodetic(est.mean[0], est.mean[1])
        unresolved[tid] = {"lat": float(lat), "lon": float(lon), "east_m": float(est.mean[0]),
                           "north_m": float(est.mean[1]), "radius_m": float(est.radius_m),
                           "existence": float(est.existence)}
    t0 = c.t_airborne or c.t_start
    reports = {tid: {"reason": rep.reason, "after_s": rep.t - t0,
                     "radius_m": float(rep.estimate.radius_m), "worked_s": rep.worked_s,
                     "radius_over_time": radius_over_time(c.core.radius_log[tid], t0, rep.t)}
               for tid, rep in c.core.reported.items()} if c.mission.kind == "localise" else {}
    takeover = None
    if c.takeover is not None:
        tk = c.takeover
        takeover = {"t": tk.t, "mode": tk.mode, "armed": tk.armed, "reason": tk.reason,
                    "phase": tk.phase}
    counters = dict(c.counters)
    counters["log_records_lost"] = c.log.lost
    counters["faults"] = c.faults
    commands = c.commander.summary()
    counters["setpoints"] = commands["setpoints"]
    counters["setpoints_withheld"] = commands["setpoints_withheld"]
    counters.update({f"sent_{k}": v for k, v in commands["sent"].items()})
    counters.update({f"withheld_{k}": v for k, v in commands["withheld"].items()})
    return MissionResult(
        end_reason=str(reason), exit_code=0 if ok else 2 if reason in SETUP_REFUSED else 1,
        localised=localised,
        unresolved=unresolved, reports=reports,
        duration_s=c.clock.now() - c.t_start,
        rejects=dict(getattr(c.receiver, "rejects", {})), events=list(c.events),
        error=c.error, takeover=takeover, counters=counters)


RADIUS_EVERY_S = 10.0
"""Spacing of the radius-over-time samples in the result record."""


def radius_over_time(log: list[tuple[float, float]], t0: float,
                     t_report: float) -> list[list[float | None]]:
    """[after_s, radius_m] every ``RADIUS_EVERY_S`` of a tag's (t, radius) log, plus the
    report's own sample and the last one; radii rounded to 0.1 m, null if not finite."""
    out: list[list[float | None]] = []
    next_t = -math.inf
    for i, (t, r) in enumerate(log):
        if t >= next_t or t == t_report or i == len(log) - 1:
            out.append([round(t - t0, 1), round(r, 1) if math.isfinite(r) else None])
            if t >= next_t:
                next_t = t + RADIUS_EVERY_S
    return out
