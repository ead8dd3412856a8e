"""The simulated autopilot's parameter table (a small subset of PX4's, same names, types,
units and defaults as PX4 SITL).

Values are kept as float; on the wire each parameter has PX4's type: FLOAT as
MAV_PARAM_TYPE_REAL32, INT32 as MAV_PARAM_TYPE_INT32 encoded bytewise in PARAM_VALUE's float
field (PX4's encoding, which MAVSDK expects from a PX4 autopilot). Unknown names are not
answered, as PX4 does, so a client times out on them.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Literal

PARAM_ID_LEN = 16


@dataclass(frozen=True, slots=True)
class ParamSpec:
    name: str
    default: float
    min_value: float
    max_value: float
    doc: str
    kind: Literal["float", "int"] = "float"


#: PX4 defaults unless noted. Ranges clamp PARAM_SET values (PX4 clamps too).
SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.0, 500.0, "takeoff altitude above home, m"),
    ParamSpec("MPC_XY_VEL_MAX", 12.0, 0.0, 20.0, "max horizontal speed, m/s"),
    ParamSpec("MPC_XY_CRUISE", 5.0, 0.0, 20.0, "cruise speed in auto modes (RTL, goto), m/s"),
    ParamSpec("MPC_ACC_HOR", 3.0, 0.1, 15.0,
              "max horizontal acceleration, m/s^2 (sim: set from the mission's max_accel)"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0, "max climb rate, m/s"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0, "max descent rate, m/s"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.2, 4.0, "final landing descent rate, m/s"),
    ParamSpec("MPC_LAND_ALT2", 2.0, 0.0, 100.0, "below this height land at MPC_LAND_SPEED, m"),
    ParamSpec("RTL_RETURN_ALT", 30.0, 0.0, 500.0, "RTL return height above home, m"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.0, 60.0, "offboard setpoint loss timeout, s (wall)"),
    ParamSpec("COM_OBL_RC_ACT", 0.0, 0.0, 7.0,
              "offboard loss action: 0 position, 1 altitude, 2 stabilized (these need RC, "
              "else NAV_RCL_ACT), 3 return, 4 land, 5 hold, 6 terminate, 7 disarm", "int"),
    ParamSpec("NAV_RCL_ACT", 2.0, 1.0, 6.0,
              "RC loss action, also the offboard-loss fallback without RC: 1 hold, 2 return, "
              "3 land", "int"),
    ParamSpec("NAV_DLL_ACT", 2.0, 0.0, 6.0,
              "data link (GCS heartbeat) loss action: 0 disabled, 1 hold, 2 return, 3 land, "
              "5 terminate, 6 disarm (PX4's Gazebo SITL airframes set 2; PX4 SIH and the "
              "firmware default are 0); reported, not simulated", "int"),
    ParamSpec("COM_DL_LOSS_T", 10.0, 5.0, 300.0, "data link loss timeout, s", "int"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, -1.0, 20.0,
              "auto-disarm if no takeoff within this after arming, s (wall); <= 0 off"),
    ParamSpec("COM_DISARM_LAND", 2.0, -1.0, 20.0, "auto-disarm after landing, s; < 0 off"),
    ParamSpec("BAT_LOW_THR", 0.15, 0.12, 0.5, "low battery warning, fraction"),
    ParamSpec("BAT_CRIT_THR", 0.07, 0.05, 0.5, "critical battery: return to launch, fraction"),
    ParamSpec("BAT_EMERGEN_THR", 0.05, 0.03, 0.5, "emergency battery: land now, fraction"),
    ParamSpec("GF_ACTION", 2.0, 0.0, 5.0,
              "geofence breach action: 0 none, 1 warn, 2 hold, 3 return, 5 land", "int"),
    ParamSpec("GF_MAX_HOR_DIST", 0.0, 0.0, 10000.0,
              "max horizontal distance from home, m (0 off); reported, not simulated"),
    ParamSpec("GF_MAX_VER_DIST", 0.0, 0.0, 10000.0,
              "max height above home, m (0 off); reported, not simulated"),
)


class ParamTable:
    """Name -> float value, with PX4's index order for PARAM_VALUE."""

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._specs = {s.name: s for s in SPECS}
        self._names = [s.name for s in SPECS]
        self._values = {s.name: s.default for s in SPECS}
        for key, value in (overrides or {}).items():
            self.set(key, value)

    def __len__(self) -> int:
        return len(self._names)

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def names(self) -> list[str]:
        return list(self._names)

    def index(self, name: str) -> int:
        return self._names.index(name)

    def name_at(self, index: int) -> str | None:
        return self._names[index] if 0 <= index < len(self._names) else None

    def kind(self, name: str) -> Literal["float", "int"]:
        return self._specs[name].kind

    def has(self, name: str) -> bool:
        return name in self._specs

    def set(self, name: str, value: float) -> float:
        """Set a parameter; non-finite values are refused (value unchanged), others clamped.

        Returns the stored value. Raises KeyError for unknown names.
        """
        spec = self._specs[name]
        if math.isfinite(value):
            self._values[name] = min(spec.max_value, max(spec.min_value, float(value)))
        return self._values[name]


def decode_param_id(raw: str | bytes) -> str:
    """MAVLink param_id (16 chars, NUL padded, maybe not terminated) -> clean name."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return raw.split("\x00", 1)[0][:PARAM_ID_LEN]


def int_to_wire(value: int) -> float:
    """An INT32 parameter's bytes as PARAM_VALUE's float field (PX4's bytewise encoding)."""
    return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])


def int_from_wire(value: float) -> int:
    """The INT32 carried bytewise in a float field (PARAM_SET / PARAM_VALUE)."""
    return int(struct.unpack("<i", struct.pack("<f", value))[0])


def parse_param_flag(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` for ``python -m sim --param``; ValueError naming the problem."""
    name, sep, raw = text.partition("=")
    names = [s.name for s in SPECS]
    if not sep or name not in names:
        raise ValueError(f"expected NAME=VALUE with NAME one of {', '.join(names)}; got {text!r}")
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"expected a number after {name}=; got {raw!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number after {name}=; got {raw!r}")
    return name, value
