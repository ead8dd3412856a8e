"""PX4 flight modes as MAVLink ``custom_mode`` values.

PX4 packs its mode into HEARTBEAT.custom_mode as ``(sub_mode << 24) | (main_mode << 16)``
and sets MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in base_mode. DO_SET_MODE carries param1 = base
mode (custom flag set, 1 or 129), param2 = main mode, param3 = sub mode (AUTO only).
"""

from __future__ import annotations

from enum import IntEnum


class MainMode(IntEnum):
    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE = 8


class AutoSubMode(IntEnum):
    NONE = 0
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    RTGS = 7
    FOLLOW_TARGET = 8
    PRECLAND = 9


PX4Mode = tuple[MainMode, AutoSubMode]

HOLD: PX4Mode = (MainMode.AUTO, AutoSubMode.LOITER)
TAKEOFF: PX4Mode = (MainMode.AUTO, AutoSubMode.TAKEOFF)
LAND: PX4Mode = (MainMode.AUTO, AutoSubMode.LAND)
RTL: PX4Mode = (MainMode.AUTO, AutoSubMode.RTL)
MISSION: PX4Mode = (MainMode.AUTO, AutoSubMode.MISSION)
OFFBOARD: PX4Mode = (MainMode.OFFBOARD, AutoSubMode.NONE)
POSCTL: PX4Mode = (MainMode.POSCTL, AutoSubMode.NONE)
ALTCTL: PX4Mode = (MainMode.ALTCTL, AutoSubMode.NONE)

_NAMES: dict[PX4Mode, str] = {
    HOLD: "HOLD", TAKEOFF: "TAKEOFF", LAND: "LAND", RTL: "RTL", MISSION: "MISSION",
    OFFBOARD: "OFFBOARD", POSCTL: "POSCTL", ALTCTL: "ALTCTL",
    (MainMode.MANUAL, AutoSubMode.NONE): "MANUAL",
    (MainMode.ACRO, AutoSubMode.NONE): "ACRO",
    (MainMode.STABILIZED, AutoSubMode.NONE): "STABILIZED",
    (MainMode.RATTITUDE, AutoSubMode.NONE): "RATTITUDE",
    (MainMode.AUTO, AutoSubMode.READY): "READY",
    (MainMode.AUTO, AutoSubMode.RTGS): "RTGS",
    (MainMode.AUTO, AutoSubMode.FOLLOW_TARGET): "FOLLOW_TARGET",
    (MainMode.AUTO, AutoSubMode.PRECLAND): "PRECLAND",
}


def encode(mode: PX4Mode) -> int:
    """custom_mode word for HEARTBEAT."""
    main, sub = mode
    return (int(sub) << 24) | (int(main) << 16)


def decode(custom_mode: int) -> PX4Mode:
    """Inverse of ``encode``; raises ValueError for values PX4 does not define."""
    main = (custom_mode >> 16) & 0xFF
    sub = (custom_mode >> 24) & 0xFF
    return from_ids(main, sub)


def from_ids(main: int, sub: int) -> PX4Mode:
    """Mode from DO_SET_MODE params (main, sub); sub is ignored unless main is AUTO."""
    main_mode = MainMode(main)
    sub_mode = AutoSubMode(sub) if main_mode is MainMode.AUTO else AutoSubMode.NONE
    if main_mode is MainMode.AUTO and sub_mode is AutoSubMode.NONE:
        raise ValueError("AUTO needs a sub mode")
    return main_mode, sub_mode


def name(mode: PX4Mode) -> str:
    return _NAMES.get(mode, f"{mode[0].name}/{mode[1].name}")
