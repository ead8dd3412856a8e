"""The Clock port: mission time in unix seconds, and sleeping on it.

The mission runs on the VEHICLE's clock. A real aircraft's clock runs at wall speed, but a
simulated autopilot run faster than real time does not (PX4 SITL at speed factor K runs about
0.96 K, the project's simulator exactly K), so the mission measures it: ``VehicleClock`` takes
the autopilot's SYSTEM_TIME (MAVSDK ``telemetry.unix_epoch_time``), stamps each sample with
``time.monotonic()`` on arrival and fits ``vehicle = offset + rate * monotonic``: the rate by
least squares over a sliding window, the offset through the upper envelope of the newest two
samples (an arrival is only ever late, so one late sample does not drag the clock back; a
simulated clock that stalls under CPU load drops time in steps, PX4 lockstep SITL runs at
whatever rate the CPU allows: the newest samples say where it is now). Re-planning, the
filter cadence, time limits, timeouts and every logged ``t`` then live on one time base with
the detections' own timestamps.

Which vehicle time: SYSTEM_TIME carries two clocks, ``time_unix_usec`` and ``time_boot_ms``.
On an aircraft both run at wall speed; on PX4 SITL at speed factor K the unix field is the
HOST's wall clock while ``time_boot_ms`` runs at the simulated rate (measured 3.90-3.92x at
K = 4, 9.42-9.52x at K = 10). The vehicle's time is therefore ``boot_unix + time_boot_ms``
(:class:`BootAnchor`), ``boot_unix`` being the unix time at which the boot clock read zero,
fitted once from the first pairs spanning 2 s (``boot = rate (unix - boot_unix)``): exactly
``unix - boot`` on an aircraft, the host time PX4 booted at on SITL. Every observer (the GCS,
radios riding on the vehicle's telemetry) computes the same ``boot_unix`` whenever it starts
listening. Without ``time_boot_ms`` (a MAVSDK without MAVLink-direct) the unix field is used.

``rate`` is vehicle seconds per wall second; ``sleep(dt)`` sleeps ``dt / rate`` wall seconds.
Durations are always measured on ``time.monotonic`` (never ``time.time``, which can jump):
``time.time`` is read once, to anchor the wall fallback in unix time.
"""

from __future__ import annotations

import asyncio
import collections
import math
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

#: SYSTEM_TIME values below this (10^9 s after the unix epoch) mean "not set" (no GPS time yet).
MIN_VALID_UNIX_S = 1.0e9


def fit_boot_unix(samples: list[tuple[float, float]]) -> tuple[float, float]:
    """(boot_unix, rate) from (unix_s, boot_s) pairs: boot = rate * (unix - boot_unix)."""
    arr = np.asarray(samples, dtype=np.float64)
    u0 = float(arr[0, 0])
    du = arr[:, 0] - u0
    if np.ptp(du) == 0.0:
        return u0 - float(arr[0, 1]), 1.0
    rate, c = (float(v) for v in np.polyfit(du, arr[:, 1], 1))
    if not rate > 0.0:
        return u0 - float(arr[0, 1]), 1.0
    return u0 - c / rate, rate


class BootAnchor:
    """The vehicle's time from SYSTEM_TIME pairs: ``boot_unix + time_boot_ms / 1000`` (see the
    module docstring). ``add`` takes a pair with its arrival time and returns the vehicle-time
    samples ``(vehicle_s, arrival)`` it makes available: none until ``min_samples`` valid pairs
    span ``span_s`` of unix time, then every pair held so far (so the clock fit gets them all
    at once), then one per pair. A boot clock that goes back (a reboot) starts over."""

    def __init__(self, min_samples: int = 3, span_s: float = 2.0) -> None:
        self.min_samples = min_samples
        self.span_s = span_s
        self.boot_unix_s: float | None = None
        self.rate = 1.0
        self._pairs: list[tuple[float, float, float]] = []  # unix, boot, arrival

    def add(self, unix_s: float, boot_s: float, arrival: float = 0.0
            ) -> list[tuple[float, float]]:
        if not (math.isfinite(boot_s) and boot_s >= 0.0):
            return []
        if self._pairs and boot_s < self._pairs[-1][1]:  # rebooted
            self._pairs.clear()
            self.boot_unix_s = None
        if self.boot_unix_s is None:
            if not (math.isfinite(unix_s) and unix_s >= MIN_VALID_UNIX_S):
                return []
            self._pairs.append((unix_s, boot_s, arrival))
            if (len(self._pairs) < self.min_samples
                    or self._pairs[-1][0] - self._pairs[0][0] < self.span_s):
                return []
            self.boot_unix_s, self.rate = fit_boot_unix([(u, b) for u, b, _ in self._pairs])
            held, self._pairs = self._pairs, self._pairs[-1:]
            return [(self.boot_unix_s + b, m) for _, b, m in held]
        self._pairs = [(unix_s, boot_s, arrival)]
        return [(self.boot_unix_s + boot_s, arrival)]


class Clock(Protocol):
    @property
    def rate(self) -> float:
        """Mission (vehicle) seconds per wall second."""
        ...

    def now(self) -> float:
        """Mission time, unix seconds."""
        ...

    def wall_seconds(self, seconds: float) -> float:
        """Wall seconds that `seconds` of mission time take."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Sleep for `seconds` of mission time."""
        ...


class WallClock:
    """Real time: unix time anchored once, then advanced by ``time.monotonic``."""

    rate = 1.0

    def __init__(self, monotonic: Callable[[], float] = time.monotonic,
                 unix: Callable[[], float] = time.time) -> None:
        self._monotonic = monotonic
        self._mono0 = monotonic()
        self._unix0 = unix()

    def now(self) -> float:
        return self._unix0 + (self._monotonic() - self._mono0)

    def wall_seconds(self, seconds: float) -> float:
        return max(seconds, 0.0)

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0))


class VehicleClock:
    """The vehicle's clock estimated from its time messages (see the module docstring).

    ``fixed_rate``: a known rate (``--time-scale K``); then only the offset is fitted.
    ``window_s`` wall seconds of samples fit the rate; the offset goes through the upper
    envelope of the last ``anchor_samples`` (arrivals are only ever late; 1 = the newest).
    Before
    the first sample the clock is the wall clock (at ``fixed_rate`` if given) and ``source``
    says so; once ``min_samples`` spanning ``min_span_s`` wall seconds have arrived it is
    ``synced``. A sample further from the fit than ``jump_s`` vehicle seconds or two wall
    seconds' worth (the vehicle set its clock, or rebooted; not a late arrival on a busy
    machine) restarts the window. ``now()`` never steps back by less than that (fit noise), so
    successive readings are ordered.
    """

    def __init__(
        self,
        *,
        fixed_rate: float | None = None,
        window_s: float = 20.0,
        max_samples: int = 120,
        anchor_samples: int = 2,
        min_samples: int = 3,
        min_span_s: float = 1.0,
        jump_s: float = 30.0,
        monotonic: Callable[[], float] = time.monotonic,
        unix: Callable[[], float] = time.time,
    ) -> None:
        if fixed_rate is not None and not (math.isfinite(fixed_rate) and fixed_rate > 0.0):
            raise ValueError(f"the time scale must be a number > 0; found {fixed_rate}")
        self.fixed_rate = fixed_rate
        self.window_s = window_s
        self.min_samples = max(1 if fixed_rate is not None else 2, min_samples)
        self.min_span_s = 0.0 if fixed_rate is not None else min_span_s
        self.jump_s = jump_s
        self.anchor_samples = anchor_samples
        self._monotonic = monotonic
        self._mono0 = monotonic()
        self._unix0 = unix()
        self._samples: collections.deque[tuple[float, float]] = collections.deque(
            maxlen=max_samples)
        self._rate = fixed_rate if fixed_rate is not None else 1.0
        self._offset = self._unix0 - self._rate * self._mono0  # vehicle = offset + rate * mono
        self._last_now = -math.inf
        self.samples_total = 0
        self.samples_rejected = 0
        self.restarts = 0
        self.residual_rms_s = math.nan
        self._synced = False

    # -- state -------------------------------------------------------------------------------

    @property
    def rate(self) -> float:
        return self._rate

    @property
    def synced(self) -> bool:
        """Enough vehicle samples for the fit (else the clock is the wall fallback)."""
        return self._synced

    @property
    def source(self) -> str:
        """'vehicle' once synced; 'syncing' with too few samples for a rate (offset from the
        vehicle, rate assumed); 'wall' before any sample (the wall clock, at the fixed rate
        if one was given)."""
        return "vehicle" if self._synced else "syncing" if self._samples else "wall"

    def describe(self) -> dict[str, float | int | str]:
        """The fit, for an event record."""
        return {"source": self.source, "rate": round(self._rate, 5),
                "samples": len(self._samples), "fixed_rate": self.fixed_rate or 0.0,
                "residual_rms_s": round(self.residual_rms_s, 4)
                if math.isfinite(self.residual_rms_s) else -1.0,
                "restarts": self.restarts, "rejected": self.samples_rejected}

    # -- input -------------------------------------------------------------------------------

    def observe(self, vehicle_unix_s: float, mono_s: float | None = None) -> bool:
        """One vehicle time sample (unix seconds) received at monotonic `mono_s` (default:
        now). Returns False for a sample that is not a usable time (ignored, counted)."""
        m = self._monotonic() if mono_s is None else float(mono_s)
        v = float(vehicle_unix_s)
        self.samples_total += 1
        if not (math.isfinite(v) and v >= MIN_VALID_UNIX_S and math.isfinite(m)):
            self.samples_rejected += 1
            return False
        if self._samples and (m <= self._samples[-1][0] or
                              (self._synced and abs(v - self._predict(m)) > self._jump())):
            if m <= self._samples[-1][0]:  # out of order arrival stamp: keep the older one
                self.samples_rejected += 1
                return False
            self.restarts += 1
            self._samples.clear()
            self._synced = False
        self._samples.append((m, v))
        while self._samples and m - self._samples[0][0] > self.window_s:
            self._samples.popleft()
        self._fit()
        return True

    def _fit(self) -> None:
        arr = np.asarray(self._samples, dtype=np.float64)
        m, v = arr[:, 0], arr[:, 1]
        m_ref = m[-1]
        span = float(m[-1] - m[0])
        if self.fixed_rate is not None:
            rate = self.fixed_rate
        elif len(arr) >= self.min_samples and span >= self.min_span_s:
            dm = m - m.mean()
            rate = float(np.dot(dm, v - v.mean()) / np.dot(dm, dm))
            if not (math.isfinite(rate) and rate > 0.0):
                return
        else:
            rate = self._rate  # too few samples for a rate yet: offset only
        at_ref = v - rate * (m - m_ref)  # each sample's vehicle time at m_ref
        self.residual_rms_s = float(np.std(at_ref))
        self._rate = rate
        self._offset = float(np.max(at_ref[-self.anchor_samples:])) - rate * m_ref
        self._synced = len(arr) >= self.min_samples and span >= self.min_span_s

    def _jump(self) -> float:
        return max(self.jump_s, 2.0 * self._rate)

    def _predict(self, mono_s: float) -> float:
        return self._offset + self._rate * mono_s

    # -- output ------------------------------------------------------------------------------

    def now(self) -> float:
        t = float(self._predict(self._monotonic()))
        if self._last_now - self._jump() < t < self._last_now:
            return self._last_now  # fit noise: never step back
        self._last_now = t
        return t

    def wall_seconds(self, seconds: float) -> float:
        """Wall seconds that `seconds` of vehicle time take."""
        return max(seconds, 0.0) / self._rate

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(self.wall_seconds(seconds))
