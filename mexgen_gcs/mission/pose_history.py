"""A short history of the vehicle's pose on the mission (vehicle) clock, to pose each detection
at its own timestamp instead of at its arrival.

Frame: local ENU metres about the mission home horizontally; ``up_m`` is the height above the
vehicle's own home; yaw is a compass heading in degrees. Samples arrive in time order (one per
position telemetry message, stamped on arrival); lookups interpolate position and height
linearly and yaw along the shortest arc. Appending is O(1) amortised, lookups O(log n).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Pose:
    t: float
    east_m: float
    north_m: float
    up_m: float
    yaw_deg: float


class PoseHistory:
    """The last ``span_s`` vehicle seconds of poses (at most ``max_samples``)."""

    def __init__(self, span_s: float = 30.0, max_samples: int = 4000) -> None:
        self.span_s = span_s
        self.max_samples = max_samples
        self._t: list[float] = []
        self._poses: list[Pose] = []
        self._start = 0  # index of the oldest kept sample (lists are compacted now and then)

    def __len__(self) -> int:
        return len(self._t) - self._start

    def add(self, pose: Pose) -> None:
        """Append a sample; one older than the newest is ignored (arrival order is time order)."""
        if not all(map(math.isfinite, (pose.t, pose.east_m, pose.north_m, pose.up_m,
                                       pose.yaw_deg))):
            return
        if len(self) and pose.t < self._t[-1]:
            return
        self._t.append(pose.t)
        self._poses.append(pose)
        while len(self) > self.max_samples or (
                len(self) > 2 and pose.t - self._t[self._start] > self.span_s):
            self._start += 1
        if self._start > 1024 and self._start > len(self._t) // 2:
            del self._t[: self._start], self._poses[: self._start]
            self._start = 0

    @property
    def span(self) -> tuple[float, float] | None:
        """(oldest, newest) sample times, or None when empty."""
        return (self._t[self._start], self._t[-1]) if len(self) else None

    def at(self, t: float, tolerance_s: float) -> Pose | None:
        """The pose at vehicle time `t`: interpolated between the samples around it; the
        nearest end sample if `t` is outside the history by at most `tolerance_s`; else None."""
        if not len(self) or not math.isfinite(t):
            return None
        t0, t1 = self._t[self._start], self._t[-1]
        if t <= t0:
            return self._poses[self._start] if t0 - t <= tolerance_s else None
        if t >= t1:
            return self._poses[-1] if t - t1 <= tolerance_s else None
        i = bisect.bisect_right(self._t, t, lo=self._start) - 1  # t_i <= t < t_{i+1}
        a, b = self._poses[i], self._poses[i + 1]
        f = (t - a.t) / (b.t - a.t) if b.t > a.t else 0.0
        dyaw = (b.yaw_deg - a.yaw_deg + 180.0) % 360.0 - 180.0
        return Pose(t, a.east_m + f * (b.east_m - a.east_m),
                    a.north_m + f * (b.north_m - a.north_m), a.up_m + f * (b.up_m - a.up_m),
                    (a.yaw_deg + f * dyaw) % 360.0)
