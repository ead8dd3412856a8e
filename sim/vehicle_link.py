"""What the riding radios learn from any MAVLink vehicle: its clock, its pose, its flight state.

Frames: WGS84 from GLOBAL_POSITION_INT (lat/lon, ``alt`` AMSL, ``relative_alt`` above the
vehicle's home), compass heading ``hdg`` in degrees (0 north, clockwise); the caller maps them
into the mission's local ENU frame.

The vehicle's clock is its ``time_boot_ms``; its unix time is ``unix = boot_unix + boot_s``,
where ``boot_unix`` is the unix time at which that clock read zero, found from SYSTEM_TIME
samples (unix ``U``, boot ``B``): ``B = rate * U + c`` fitted by least squares over the first
samples spanning ``ANCHOR_SPAN_S`` of ``U``, ``boot_unix = -c / rate``, then fixed. On an
aircraft (and on the project's simulator) ``rate`` is 1 and ``boot_unix = U - B`` of any
sample; on PX4 SITL at speed factor K, SYSTEM_TIME's unix field is the host's wall clock while
``time_boot_ms`` is simulated (``rate`` ~0.98 K), and ``boot_unix`` is the host time at which
PX4 booted. Every observer of the vehicle then computes the same ``boot_unix`` whenever it
starts listening: exactly on an aircraft; on SITL within the error of extrapolating the fitted
rate back to boot (a SITL's rate wanders with the host's load; measured 0.1-0.2 s on PX4 at
K = 4). Without SYSTEM_TIME the host's clock anchors it (observer-dependent).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sim import px4_modes

#: SYSTEM_TIME values below this (10^9 s after the unix epoch) mean "not set".
MIN_VALID_UNIX_S = 1.0e9
#: Pose samples kept, vehicle seconds.
HISTORY_S = 60.0
#: The longest gap between two pose samples that is interpolated, vehicle seconds.
MAX_GAP_S = 2.0
#: SYSTEM_TIME samples needed to fit the clock: at least this many, spanning ANCHOR_SPAN_S of
#: their unix time (on SITL the host's seconds, which bound the rate's precision).
ANCHOR_MIN_SAMPLES = 5
ANCHOR_SPAN_S = 3.0


def fit_boot_unix(samples: list[tuple[float, float]]) -> tuple[float, float]:
    """(boot_unix, rate) from (unix_s, boot_s) samples: boot = rate * (unix - boot_unix)."""
    arr = np.asarray(samples, dtype=np.float64)
    u0 = float(arr[0, 0])
    du = arr[:, 0] - u0
    if np.ptp(du) == 0.0:
        return u0 - float(arr[0, 1]), 1.0
    rate, c = (float(v) for v in np.polyfit(du, arr[:, 1], 1))
    if not rate > 0.0:
        return u0 - float(arr[0, 1]), 1.0
    return u0 - c / rate, rate


@dataclass(frozen=True, slots=True)
class VehicleEndpoint:
    """``udpin:HOST:PORT`` (listen there) or ``udpout:HOST:PORT`` (send there first)."""

    mode: Literal["udpin", "udpout"]
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.mode}:{self.host}:{self.port}"


def parse_vehicle_url(text: str) -> VehicleEndpoint:
    """``udpin:0.0.0.0:14550``, ``udpout:127.0.0.1:18570`` (``//`` after the colon allowed)."""
    mode, sep, rest = text.partition(":")
    rest = rest.removeprefix("//")
    host, sep2, port = rest.rpartition(":")
    if (mode not in ("udpin", "udpout") or not sep or not sep2 or not host or not port.isdigit()
            or not 0 <= int(port) <= 65535 or (mode == "udpout" and int(port) == 0)):
        raise ValueError(f"expected udpin:HOST:PORT or udpout:HOST:PORT, e.g. "
                         f"udpin:0.0.0.0:14550; got {text!r}")
    return VehicleEndpoint(mode, host, int(port))  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class PoseSample:
    """The vehicle at ``boot_s`` (its time since boot, seconds)."""

    boot_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    """AMSL."""
    rel_alt_m: float
    """Above the vehicle's home."""
    yaw_deg: float
    v_north_m_s: float = 0.0
    v_east_m_s: float = 0.0
    v_down_m_s: float = 0.0


def _lerp_angle_deg(a: float, b: float, w: float) -> float:
    d = (b - a + 180.0) % 360.0 - 180.0
    return (a + w * d) % 360.0


class PoseHistory:
    """Recent pose samples in vehicle time, interpolated in between."""

    def __init__(self, keep_s: float = HISTORY_S) -> None:
        self._keep_s = keep_s
        self._times: deque[float] = deque()
        self._samples: deque[PoseSample] = deque()

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def latest_s(self) -> float | None:
        return self._times[-1] if self._times else None

    def add(self, sample: PoseSample) -> bool:
        """Append a newer sample (older or repeated ones are ignored: False)."""
        if self._times and sample.boot_s <= self._times[-1]:
            return False
        self._times.append(sample.boot_s)
        self._samples.append(sample)
        while self._times and self._times[0] < sample.boot_s - self._keep_s:
            self._times.popleft()
            self._samples.popleft()
        return True

    def at(self, boot_s: float) -> PoseSample | None:
        """The pose at ``boot_s`` by linear interpolation (nearest sample within 0.1 s at the
        ends); None outside the history or across a gap longer than MAX_GAP_S."""
        if not self._times:
            return None
        times = self._times
        i = bisect.bisect_left(times, boot_s)
        if i < len(times) and times[i] == boot_s:
            return self._samples[i]
        if i == 0 or i == len(times):
            j = 0 if i == 0 else len(times) - 1
            return self._samples[j] if abs(times[j] - boot_s) <= 0.1 else None
        a, b = self._samples[i - 1], self._samples[i]
        gap = b.boot_s - a.boot_s
        if gap > MAX_GAP_S:
            return None
        w = (boot_s - a.boot_s) / gap

        def lerp(x: float, y: float) -> float:
            return x + w * (y - x)

        return PoseSample(
            boot_s, lerp(a.lat_deg, b.lat_deg), lerp(a.lon_deg, b.lon_deg),
            lerp(a.alt_m, b.alt_m), lerp(a.rel_alt_m, b.rel_alt_m),
            _lerp_angle_deg(a.yaw_deg, b.yaw_deg, w), lerp(a.v_north_m_s, b.v_north_m_s),
            lerp(a.v_east_m_s, b.v_east_m_s), lerp(a.v_down_m_s, b.v_down_m_s))


_ARMED_FLAG = 128
_CUSTOM_MODE_FLAG = 1
_AUTOPILOT_PX4 = 12
_LANDED_NAMES = {0: "UNDEFINED", 1: "ON_GROUND", 2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
_LANDED_ON_GROUND = 1
_LANDED_IN_AIR = 2
_FLYING_REL_ALT_M = 1.0


class VehicleTrack:
    """The vehicle as its telemetry shows it. Feed every decoded message to ``handle``."""

    def __init__(self, sysid: int | None = None) -> None:
        self.sysid = sysid
        """The vehicle's system id: given, or the first autopilot heard."""
        self.offset_s: float | None = None
        """unix - boot seconds (= boot_unix), fixed once (see the module docstring)."""
        self.offset_source = ""
        self.rate: float | None = None
        """Fitted vehicle boot seconds per SYSTEM_TIME unix second."""
        self.system_time_samples = 0
        self._samples: list[tuple[float, float]] = []
        self.home: tuple[float, float, float] | None = None
        """The vehicle's home: lat, lon (degrees), alt (AMSL m)."""
        self.armed = False
        self.landed_state = 0
        self.has_flown = False
        self.poses = PoseHistory()
        self.last_boot_s: float | None = None
        self.mode = "UNKNOWN"
        """PX4 mode name from HEARTBEAT (custom_mode), or ``custom:N`` for other autopilots."""
        self.battery: float | None = None
        """Remaining charge, fraction (SYS_STATUS), None until reported."""
        self.gps_ok: bool | None = None
        """GPS_RAW_INT fix type 3D or better; None until reported."""
        self._yaw_deg = 0.0

    def handle(self, msg: Any) -> None:
        kind = msg.get_type()
        src = msg.get_srcSystem()
        if kind == "HEARTBEAT":
            if self.sysid is None and msg.autopilot != 8 and msg.get_srcComponent() == 1 \
                    and msg.type not in (6, 18):  # not INVALID, not a GCS or onboard computer
                self.sysid = src
            if src == self.sysid and msg.get_srcComponent() == 1:
                self.armed = bool(msg.base_mode & _ARMED_FLAG)
                self.mode = _mode_name(msg)
            return
        if self.sysid is None or src != self.sysid:
            return
        if kind == "SYSTEM_TIME":
            self._system_time(msg)
        elif kind == "GLOBAL_POSITION_INT":
            self._position(msg)
        elif kind == "HOME_POSITION":
            self.home = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
        elif kind == "SYS_STATUS":
            if 0 <= msg.battery_remaining <= 100:
                self.battery = msg.battery_remaining / 100.0
        elif kind == "GPS_RAW_INT":
            self.gps_ok = msg.fix_type >= 3
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state = int(msg.landed_state)
            if self.armed and self.landed_state == _LANDED_IN_AIR:
                self.has_flown = True

    def _system_time(self, msg: Any) -> None:
        unix_s, boot_s = msg.time_unix_usec / 1e6, msg.time_boot_ms / 1e3
        if unix_s < MIN_VALID_UNIX_S:
            return
        self.system_time_samples += 1
        if self.offset_s is not None:
            return
        if self._samples and boot_s <= self._samples[-1][1]:
            self._samples.clear()  # a reboot: start again
        self._samples.append((unix_s, boot_s))
        span = self._samples[-1][0] - self._samples[0][0]
        if len(self._samples) >= ANCHOR_MIN_SAMPLES and span >= ANCHOR_SPAN_S:
            self.offset_s, self.rate = fit_boot_unix(self._samples)
            self.offset_source = "SYSTEM_TIME"

    def _position(self, msg: Any) -> None:
        boot_s = msg.time_boot_ms / 1e3
        if msg.hdg != 65535:  # 65535: heading unknown, keep the last one
            self._yaw_deg = msg.hdg / 100.0
        yaw = self._yaw_deg
        sample = PoseSample(boot_s, msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3,
                            msg.relative_alt / 1e3, yaw, msg.vx / 100.0, msg.vy / 100.0,
                            msg.vz / 100.0)
        if not (math.isfinite(sample.lat_deg) and -90.0 <= sample.lat_deg <= 90.0):
            return
        if self.poses.add(sample):
            self.last_boot_s = boot_s
        if self.armed and sample.rel_alt_m > _FLYING_REL_ALT_M:
            self.has_flown = True

    def anchor_now(self, host_unix_s: float) -> None:
        """Out of patience: one SYSTEM_TIME sample (rate 1), else the host's clock at the
        latest vehicle time."""
        if self.offset_s is not None:
            return
        if self._samples:
            unix_s, boot_s = self._samples[-1]
            self.offset_s, self.rate, self.offset_source = unix_s - boot_s, 1.0, "SYSTEM_TIME"
        elif self.last_boot_s is not None:
            self.offset_s = host_unix_s - self.last_boot_s
            self.offset_source = "host"

    def unix_of(self, boot_s: float) -> float:
        assert self.offset_s is not None
        return boot_s + self.offset_s

    @property
    def landed_state_name(self) -> str:
        return _LANDED_NAMES.get(self.landed_state, str(self.landed_state))

    @property
    def landed_and_disarmed(self) -> bool:
        if self.armed:
            return False
        if self.landed_state:
            return self.landed_state == _LANDED_ON_GROUND
        latest = self.poses.latest_s
        pose = self.poses.at(latest) if latest is not None else None
        return pose is not None and pose.rel_alt_m < _FLYING_REL_ALT_M


def _mode_name(hb: Any) -> str:
    if hb.autopilot == _AUTOPILOT_PX4 and hb.base_mode & _CUSTOM_MODE_FLAG:
        try:
            return px4_modes.name(px4_modes.decode(int(hb.custom_mode)))
        except ValueError:
            pass
    return f"custom:{int(hb.custom_mode)}"
