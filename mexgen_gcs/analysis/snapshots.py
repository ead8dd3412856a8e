"""MissionSnapshot objects rebuilt from a flight log, for replaying a flight in the terminal UI
(the same immutable views the live mission publishes).

Frame: WGS84 for display plus local ENU metres about home, as in ``io.snapshot``. The
tags show the recorded estimates; the replay's comparison of another planner method is added
to the events and, when it disagrees with the recorded choice, to the warnings.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.replay import ReplayStep
from mexgen_gcs.analysis.truth import Truth
from mexgen_gcs.io.records import Plan
from mexgen_gcs.io.snapshot import MissionSnapshot, TagView
from mexgen_gcs.io.vehicle import Telemetry

TRACK_POINTS = 600
EVENT_LINES = 20

_STATE_AFTER = (  # event kind -> mission state from then on
    ("vehicle_ready", "preflight"), ("takeoff", "takeoff"), ("offboard_started", "searching"),
    ("mission_end", "returning"), ("rtl_commanded", "returning"),
    ("landed_and_disarmed", "landed"),
)


def _event_line(flight: FlightData, rec: dict[str, Any]) -> str:
    fields = " ".join(f"{k}={v}" for k, v in rec.items() if k not in ("t", "type", "kind"))
    return f"{float(rec['t']) - flight.t_start:7.1f}s {rec.get('kind')}" + (
        f" {fields}" if fields else "")


def build_snapshots(flight: FlightData, steps: Sequence[ReplayStep] = (),
                    truth: Truth | None = None, step_s: float = 1.0) -> list[MissionSnapshot]:
    """One snapshot every ``step_s`` of mission time from the log start to its end, plus one
    at every recorded plan and event. The last one has state ``done``."""
    times = np.arange(flight.t_start, flight.t_end + 1e-9, step_s)
    marks = [p.t for p in flight.plans] + [float(e["t"]) for e in flight.events]
    times = np.unique(np.concatenate([times, marks, [flight.t_end]]))
    builder = _Builder(flight, steps, truth)
    snaps = [builder.at(float(t)) for t in times]
    if snaps:
        last = snaps[-1]
        snaps[-1] = dataclasses.replace(last, state="done")
    return snaps


class _Builder:
    def __init__(self, flight: FlightData, steps: Sequence[ReplayStep],
                 truth: Truth | None) -> None:
        self.f = flight
        self.truth = truth
        self.steps = sorted(steps, key=lambda s: s.t)
        self.step_t = np.array([s.t for s in self.steps])
        self.plan_t = np.array([p.t for p in flight.plans])
        det = flight.detections
        self.det_t = {tid: np.sort(det.t[det.of_tag(tid)]) for tid in flight.tag_ids}
        self.det_rssi = {}
        for tid in flight.tag_ids:
            sel = det.of_tag(tid)
            order = np.argsort(det.t[sel], kind="stable")
            self.det_rssi[tid] = det.rssi_db[sel][order]
        self.all_det_t = np.sort(det.t)
        self.radio_t = np.array(sorted(float(r["t"]) for r in flight.log.of_type("radio")))
        self.events = sorted(flight.events + flight.errors, key=lambda r: float(r["t"]))
        self.event_t = np.array([float(r["t"]) for r in self.events])
        self.loc_event = {str(e.get("tag")): e for e in flight.events_of("tag_localised")}
        self.cloud_t = {tid: np.array([c[0] for c in flight.clouds.get(tid, [])])
                        for tid in flight.tag_ids}
        self.end_reason = (str(flight.result.get("end_reason")) if flight.result else None)
        self.end_t = next((float(e["t"]) for e in flight.events_of("mission_end")), math.inf)
        self.area = tuple((float(x), float(y)) for x, y in flight.area.vertices_m.tolist())
        self.track_xy = np.column_stack([flight.track.east_m, flight.track.north_m])

    def _state(self, t: float) -> str:
        state = "connecting"
        for kind, after in _STATE_AFTER:
            if any(float(e["t"]) <= t for e in self.f.events_of(kind)):
                state = after
        return state

    def _telemetry(self, t: float) -> Telemetry:
        f = self.f
        tel = f.telemetry
        i = tel.index_at(t)
        frame = f.frame
        track = f.track
        if len(track):
            e, n, u = (float(x) for x in track.position_at(t))
            lat, lon, _ = frame.to_geodetic(e, n, 0.0)
            lat_f, lon_f = float(lat), float(lon)
            v = track.velocity_at(t)
            yaw = track.yaw_at(t)
        else:
            lat_f = lon_f = u = math.nan
            v = np.zeros(2)
            yaw = 0.0
        if i is None:
            return Telemetry(lat_deg=lat_f, lon_deg=lon_f, rel_alt_m=u,
                             abs_alt_m=frame.alt0_m + u, yaw_deg=yaw)
        return Telemetry(
            connected=bool(tel.connected[i]), lat_deg=lat_f, lon_deg=lon_f,
            abs_alt_m=frame.alt0_m + u, rel_alt_m=u, v_north_m_s=float(v[1]),
            v_east_m_s=float(v[0]), yaw_deg=yaw, armed=bool(tel.armed[i]),
            in_air=bool(tel.in_air[i]), landed_state="IN_AIR" if tel.in_air[i] else "ON_GROUND",
            flight_mode=tel.mode[i], battery_percent=float(tel.battery_percent[i]),
            global_position_ok=math.isfinite(lat_f), home_position_ok=True, armable=True,
            home_lat_deg=frame.lat0_deg, home_lon_deg=frame.lon0_deg,
            home_abs_alt_m=frame.alt0_m)

    def _tag(self, tid: str, t: float) -> TagView:
        f = self.f
        series = f.estimates[tid]
        j = series.index_at(t)
        dt = self.det_t[tid]
        k = int(np.searchsorted(dt, t, side="right"))
        recent = k - int(np.searchsorted(dt, t - 60.0, side="left"))
        ev = self.loc_event.get(tid)
        loc_at = (float(ev["after_s"]) if ev is not None and float(ev["t"]) <= t
                  and isinstance(ev.get("after_s"), int | float) else None)
        ct = self.cloud_t[tid]
        c = int(np.searchsorted(ct, t, side="right")) - 1
        cloud: tuple[tuple[float, float], ...] = ()
        if c >= 0:
            cloud = tuple((float(x), float(y)) for x, y in f.clouds[tid][c][1].tolist())
        truth_en = None
        if self.truth is not None and tid in self.truth.tags:
            te, tn = self.truth.tags[tid].position_at(t)
            truth_en = (float(te), float(tn))
        freq = f.mission.tag(tid).freq_hz
        last_rssi = float(self.det_rssi[tid][k - 1]) if k > 0 else None
        if j is None:
            return TagView(tid, freq, math.nan, math.nan, math.nan, math.nan, math.nan,
                           math.inf, (math.nan, math.nan, math.nan), False, None, recent, k,
                           last_rssi, cloud, truth_en)
        e, n = float(series.east_m[j]), float(series.north_m[j])
        lat, lon, _ = f.frame.to_geodetic(e, n, 0.0)
        cov = series.cov_pos_m2[j]
        return TagView(
            tag_id=tid, freq_hz=freq, existence=float(series.existence[j]), lat_deg=float(lat),
            lon_deg=float(lon), east_m=e, north_m=n, radius_m=float(series.radius_m[j]),
            cov_pos_m2=(float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])),
            localised=bool(series.localised[: j + 1].any()), localised_at_s=loc_at,
            detections_last_min=recent, detections_total=k, last_rssi_db=last_rssi,
            cloud_en_m=cloud, truth_en_m=truth_en)

    def _plan(self, t: float) -> tuple[Plan | None, float]:
        """The plan in force at t and the time to the next one (0 after the last)."""
        i = int(np.searchsorted(self.plan_t, t, side="right")) - 1
        if i < 0:
            return None, 0.0
        next_t = float(self.plan_t[i + 1]) if i + 1 < self.plan_t.size else math.inf
        return self.f.plans[i], max(next_t - t, 0.0) if math.isfinite(next_t) else 0.0

    def at(self, t: float) -> MissionSnapshot:
        f = self.f
        tel = self._telemetry(t)
        k = int(np.searchsorted(f.track.t, t, side="right"))
        track = tuple((float(x), float(y)) for x, y in self.track_xy[max(0, k - TRACK_POINTS):k])
        vehicle = track[-1] if track else (0.0, 0.0)
        plan, next_plan_in_s = self._plan(t)
        n_ev = int(np.searchsorted(self.event_t, t, side="right"))
        lines = [_event_line(f, e) for e in self.events[max(0, n_ev - EVENT_LINES):n_ev]]
        warnings: list[str] = []
        s = int(np.searchsorted(self.step_t, t, side="right")) - 1
        if s >= 0:
            st = self.steps[s]
            lines.append(f"{st.t - f.t_start:7.1f}s replay: recorded {st.recorded_method} "
                         f"{st.recorded_heading_deg:.0f} deg, {st.method} "
                         f"{st.method_heading_deg:.0f} deg")
            if not st.method_agrees:
                warnings.append(f"REPLAY: {st.method} would fly {st.method_heading_deg:.0f} deg "
                                f"(recorded {st.recorded_heading_deg:.0f} deg)")
        r = int(np.searchsorted(self.radio_t, t, side="right")) - 1
        hb_age = t - float(self.radio_t[r]) if r >= 0 else math.inf
        return MissionSnapshot(
            t=t, elapsed_s=t - f.t_start, state=self._state(t),
            end_reason=self.end_reason if t >= self.end_t else None, telemetry=tel,
            vehicle_en_m=vehicle, track_en_m=track,
            tags=tuple(self._tag(tid, t) for tid in f.tag_ids), plan=plan,
            next_plan_in_s=next_plan_in_s, radio_heartbeat_age_s=hb_age,
            radio_accepted=int(np.searchsorted(self.all_det_t, t, side="right")),
            radio_rejects={}, warnings=tuple(warnings), events=tuple(lines[-EVENT_LINES:]),
            method=plan.method if plan is not None else f.method, link_ok=tel.connected,
            area_en_m=self.area)
