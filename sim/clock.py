"""Simulated time versus wall time.

The simulator runs physics, tag motion and radio pulses on *sim time*, which advances
``speedup`` times faster than the wall clock. Everything that measures how quickly the ground
station reacts (MAVLink heartbeats, telemetry rates, the offboard-setpoint loss timeout, the
pre-flight auto-disarm, link-drop durations) stays on the *wall clock*, because the GCS and
MAVSDK measure those on theirs.

Timestamps the simulator publishes (MAVLink ``time_boot_ms``, SYSTEM_TIME, datagram ``t``,
truth records) are sim time mapped to unix seconds: ``unix = start_unix + sim_elapsed``, so a
ground station that takes its clock from the vehicle sees one consistent time base.

Imperfections of a real SITL autopilot, on request: ``rate_error`` makes sim time run at
``speedup * (1 + rate_error)`` (PX4 SIH at speed factor K runs about 0.98 K), and
``system_time="host"`` makes SYSTEM_TIME carry the host's wall clock in ``time_unix_usec``
while ``time_boot_ms`` stays sim time, as PX4 SITL does (its CLOCK_REALTIME is the host's).
"""

from __future__ import annotations

import time
from collections.abc import Callable

SYSTEM_TIME_SOURCES = ("sim", "host")


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
        rate_error: float = 0.0,
        system_time: str = "sim",
        monotonic: Callable[[], float] = time.monotonic,
        unix_now: Callable[[], float] = time.time,
        max_lag_s: float = 0.25,
    ) -> None:
        if not speedup > 0.0:
            raise ValueError(f"speedup must be > 0, got {speedup}")
        if not -0.5 <= rate_error <= 0.5:
            raise ValueError(f"rate_error must be in [-0.5, 0.5], got {rate_error}")
        if system_time not in SYSTEM_TIME_SOURCES:
            raise ValueError(f"system_time must be one of {SYSTEM_TIME_SOURCES}")
        self.speedup = float(speedup)
        """The nominal speed-up K (telemetry rates scale with it)."""
        self.rate = self.speedup * (1.0 + rate_error)
        """Sim seconds per wall second: K, or K * (1 + rate_error)."""
        self.system_time = system_time
        self._unix_now = unix_now
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
        self._due_s = max(self._due_s + max(wall_dt, 0.0) * self.rate, self.sim_s)
        return self._due_s

    def unix_of(self, sim_s: float) -> float:
        """Unix seconds of a sim time."""
        return self.start_unix + sim_s

    def unix(self) -> float:
        """Unix seconds of the current sim time."""
        return self.start_unix + self.sim_s

    def system_time_unix(self) -> float:
        """SYSTEM_TIME.time_unix_usec / 1e6: sim unix time, or the host's clock ("host")."""
        return self._unix_now() if self.system_time == "host" else self.unix()

    def time_boot_ms(self) -> int:
        """MAVLink ``time_boot_ms`` (uint32) of the current sim time."""
        return round(self.sim_s * 1000.0) & 0xFFFFFFFF
