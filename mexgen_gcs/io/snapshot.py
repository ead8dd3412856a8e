"""Immutable mission snapshots, published a few times a second for the UI and progress lines.

The one interface between a mission and what shows it: the flight publishes them on a
``SnapshotBus`` (``mission.views`` builds them), and analysis rebuilds them from a flight log
for replay, so both live below the two.

Positions are WGS84 for display (lat/lon) plus local ENU metres about home where a map needs
them. Nothing in a snapshot refers back to live mission objects.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

from mexgen_gcs.io.records import Plan
from mexgen_gcs.io.vehicle import Telemetry


@dataclass(frozen=True, slots=True)
class TagView:
    tag_id: str
    freq_hz: int
    existence: float
    lat_deg: float
    lon_deg: float
    east_m: float
    north_m: float
    radius_m: float
    cov_pos_m2: tuple[float, float, float]
    """(var_e, cov_en, var_n) of the position estimate."""
    localised: bool
    localised_at_s: float | None
    detections_last_min: int
    detections_total: int
    last_rssi_db: float | None
    cloud_en_m: tuple[tuple[float, float], ...] = ()
    truth_en_m: tuple[float, float] | None = None
    reported: str | None = None
    """Why the tag was reported (reached, stalled, budget), None while it is worked on."""


@dataclass(frozen=True, slots=True)
class MissionSnapshot:
    t: float
    elapsed_s: float
    state: str
    """connecting | preflight | takeoff | searching | holding | returning | landed | done."""
    end_reason: str | None
    telemetry: Telemetry
    vehicle_en_m: tuple[float, float]
    track_en_m: tuple[tuple[float, float], ...]
    tags: tuple[TagView, ...]
    plan: Plan | None
    """The last planning decision, as logged."""
    next_plan_in_s: float
    radio_heartbeat_age_s: float
    radio_accepted: int
    radio_rejects: dict[str, int]
    warnings: tuple[str, ...]
    events: tuple[str, ...]
    method: str
    link_ok: bool
    area_en_m: tuple[tuple[float, float], ...] = field(default=())


class SnapshotBus:
    """Latest-value broadcast: publishers never block; a slow reader only misses snapshots."""

    def __init__(self) -> None:
        self._latest: MissionSnapshot | None = None
        self._queues: list[asyncio.Queue[MissionSnapshot]] = []

    @property
    def latest(self) -> MissionSnapshot | None:
        return self._latest

    def publish(self, snap: MissionSnapshot) -> None:
        self._latest = snap
        for q in self._queues:
            if q.full():
                q.get_nowait()  # keep only the newest
            q.put_nowait(snap)

    def subscribe(self) -> asyncio.Queue[MissionSnapshot]:
        q: asyncio.Queue[MissionSnapshot] = asyncio.Queue(maxsize=1)
        if self._latest is not None:
            q.put_nowait(self._latest)
        self._queues.append(q)
        return q

    def unsubscribe(self, q: asyncio.Queue[MissionSnapshot]) -> None:
        if q in self._queues:
            self._queues.remove(q)
