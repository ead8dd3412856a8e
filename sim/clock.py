"""Simulated time versus wall time.

The simulator runs physics, tag motion and radio pulses on *sim time*, which advances
``speedup`` times faster than the wall clock. Everything that measures how quickly the ground
station reacts (MAVLink heartbeats, telemetry rates, the offboard-setpoint loss timeout, the
pre-flight auto-disarm, link-drop durations) stays on the *wall clock*, because the GCS and
MAVSDK measure those on theirs.

Timestamps the simulator publishes (MAVLink ``time_boot_ms``, SYSTEM_TIME, datagram ``t``,
truth records) are sim time mapped to unix seconds: ``unix = start_unix + sim_elapsed``, so a
ground station that takes its clock from the vehicle sees one consistent time base.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class SimClock:
    """Sim time that follows the wall clock scaled by ``speedup``.

    ``advance()`` is called by the tick loop; it returns how much sim time is due. If the
    process stalls (a slow machine, a debugger), at most ``max_lag_s`` of wall time is caught
    up and the rest is dropped, so sim time slows down instead of jumping.
    """

    def __init__(
        self,
        speedup: float = 1.0,
        *,
        monotonic: Callable[[], float] = time.monotonic,
        unix_now: Callable[[], float] = time.time,
        max_lag_s: float = 0.25,
    ) -> None:
        if not speedup > 0.0:
            raise ValueError(f"speedup must be > 0, got {speedup}")
        self.speedup = float(speedup)
        self._monotonic = monotonic
        self._wall0 = monotonic()
        self.start_unix = unix_now()
        self.sim_s = 0.0
        """Elapsed sim seconds since start (the physics has been integrated up to here)."""
        self._max_lag_s = max_lag_s
        self._last_wall = self._wall0
        self._due_s = 0.0

    def wall_s(self) -> float:
        """Elapsed wall seconds since start (monotonic)."""
        return self._monotonic() - self._wall0

    def due_s(self) -> float:
        """The sim time that is due now (the tick loop integrates ``sim_s`` up to it).

        Wall time between two calls beyond ``max_lag_s`` is dropped (sim time slows down).
        """
        now = self._monotonic()
        wall_dt = min(now - self._last_wall, self._max_lag_s)
        self._last_wall = now
        self._due_s = max(self._due_s + max(wall_dt, 0.0) * self.speedup, self.sim_s)
        return self._due_s

    def unix_of(self, sim_s: float) -> float:
        """Unix seconds of a sim time."""
        return self.start_unix + sim_s

    def unix(self) -> float:
        """Unix seconds of the current sim time."""
        return self.start_unix + self.sim_s

    def time_boot_ms(self) -> int:
        """MAVLink ``time_boot_ms`` (uint32) of the current sim time."""
        return round(self.sim_s * 1000.0) & 0xFFFFFFFF
