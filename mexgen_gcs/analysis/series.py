"""Array containers for a flight log's records: the receiver's track, telemetry, detections,
per-tag estimate series and plan records.

Frame: local ENU metres about the mission home (x east, y north, z up); headings are compass
degrees (0 north, clockwise); times are unix seconds of the mission clock.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.errors import LogFormatError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

STAGES = ("predict", "measure", "update", "reward", "total")
"""Planner timing keys in a plan record's ``timing_ms``."""

_MAX_PULSE_SKEW_S = 60.0
"""A detection's pose is timed by its pulse time unless that is this far from its arrival
(more than the receiver's clock-skew limit allows; at a high time scale a busy GCS takes
seconds of vehicle time to process a datagram)."""


def num(value: Any) -> float:
    """A logged number; null (NaN/inf when written) and non-numbers become NaN."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)


def nums(values: Iterable[Any]) -> FloatArray:
    return np.array([num(v) for v in values], dtype=np.float64)


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
        """When each detection's pose was taken: its pulse time (the GCS poses every detection
        at its own pulse time, from the datagram's pose or its pose history, both on the
        vehicle's clock); the arrival only where the pulse time is missing or absurdly far
        (a log of a GCS that posed detections at arrival)."""
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
