"""The vehicle's own view of a flight, from the `.tlog` beside flight.jsonl (io.mavlink_tap):
who was on the link, the autopilot's mode timeline, how many positions it sent, the commands
it received and what it answered, its STATUSTEXTs.

Read with pymavlink's log reader (the tlog's big-endian microsecond timestamps are wall-clock
unix seconds at arrival). A damaged tail is read as far as it goes. Positions are WGS84 (degE7
and mm in the messages); times are seconds since the tlog's first message.
"""

from __future__ import annotations

import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

M = mavutil.mavlink


@dataclass
class VehicleLink:
    path: str
    messages: int = 0
    duration_s: float = 0.0
    by_type: Counter[str] = field(default_factory=Counter)
    systems: dict[str, str] = field(default_factory=dict)
    """'sysid/compid' -> what its HEARTBEAT says it is (autopilot, GCS, ...)."""
    modes: list[tuple[float, str, bool]] = field(default_factory=list)
    """(s since start, PX4 mode, armed) each time the autopilot's mode or arming changed."""
    positions: int = 0
    max_rel_alt_m: float | None = None
    commands: Counter[str] = field(default_factory=Counter)
    """'COMMAND from sysid' -> count, for COMMAND_LONG / COMMAND_INT to the autopilot."""
    denied: Counter[str] = field(default_factory=Counter)
    """Commands the autopilot answered with anything but ACCEPTED, by 'COMMAND RESULT'."""
    statustexts: list[tuple[float, str]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"path": self.path, "messages": self.messages,
                "duration_s": round(self.duration_s, 3), "by_type": dict(self.by_type),
                "systems": self.systems, "modes": self.modes, "positions": self.positions,
                "max_rel_alt_m": self.max_rel_alt_m, "commands": dict(self.commands),
                "denied": dict(self.denied), "statustexts": self.statustexts}


def _name(enum: str, value: int) -> str:
    entry = M.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else str(value)


def _short(enum_name: str, prefix: str) -> str:
    return enum_name.removeprefix(prefix)


def read_vehicle_link(path: str | os.PathLike[str], autopilot_sysid: int | None = None
                      ) -> VehicleLink:
    """Summarise a tlog. The autopilot is `autopilot_sysid`, else the first system that sends
    a non-GCS HEARTBEAT or a GLOBAL_POSITION_INT."""
    link = VehicleLink(str(path))
    reader = mavutil.mavlink_connection(str(Path(path)), dialect="common")
    t0: float | None = None
    last_mode: tuple[str, bool] | None = None
    try:
        while True:
            try:
                msg = reader.recv_match()
            except Exception:
                break
            if msg is None:
                break
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            t = float(getattr(msg, "_timestamp", 0.0))
            t0 = t if t0 is None else t0
            link.messages += 1
            link.duration_s = t - t0
            link.by_type[kind] += 1
            src = msg.get_srcSystem()
            if kind == "HEARTBEAT":
                key = f"{src}/{msg.get_srcComponent()}"
                if key not in link.systems:
                    what = _short(_name("MAV_TYPE", msg.type), "MAV_TYPE_")
                    firmware = _short(_name("MAV_AUTOPILOT", msg.autopilot), "MAV_AUTOPILOT_")
                    link.systems[key] = f"{what}, {firmware}"
                if msg.type == M.MAV_TYPE_GCS:
                    continue
                if autopilot_sysid is None:
                    autopilot_sysid = src
                if src != autopilot_sysid:
                    continue
                mode = str(mavutil.interpret_px4_mode(msg.base_mode, msg.custom_mode))
                armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
                if (mode, armed) != last_mode:
                    link.modes.append((round(t - t0, 3), mode, armed))
                    last_mode = (mode, armed)
            elif kind == "GLOBAL_POSITION_INT" and src == (autopilot_sysid or src):
                autopilot_sysid = src  # only a vehicle sends its position
                link.positions += 1
                alt = msg.relative_alt / 1000.0
                link.max_rel_alt_m = alt if link.max_rel_alt_m is None else max(
                    link.max_rel_alt_m, alt)
            elif kind in ("COMMAND_LONG", "COMMAND_INT") and (
                    autopilot_sysid is None or msg.target_system == autopilot_sysid):
                name = _short(_name("MAV_CMD", msg.command), "MAV_CMD_")
                link.commands[f"{name} from {src}"] += 1
            elif kind == "COMMAND_ACK" and src == autopilot_sysid and (
                    msg.result != M.MAV_RESULT_ACCEPTED):
                name = _short(_name("MAV_CMD", msg.command), "MAV_CMD_")
                link.denied[f"{name} {_short(_name('MAV_RESULT', msg.result), 'MAV_RESULT_')}"] += 1
            elif kind == "STATUSTEXT" and src == autopilot_sysid:
                link.statustexts.append((round(t - t0, 3), str(msg.text).rstrip("\x00 \t")))
    finally:
        reader.close()
    return link
