"""The scripted pilot takeover (fault ``pilot_takeover``): what the pilot does, what the GCS did.

At the fault's ``at_s`` the pilot flips the RC mode switch to ``mode`` (POSCTL or ALTCTL with the
sticks centred: the vehicle brakes and holds); ``land_after_s`` later to LAND. PX4 keeps
obeying GCS commands while the pilot has the RC (a DO_SET_MODE still changes the mode) and
ignores offboard setpoints outside OFFBOARD; so does the simulator. This module counts what the
ground station sent after the takeover, so that a test can assert that it stopped.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from sim import px4_modes as modes
from sim.faults import Fault

_PILOT_MODES = {"POSCTL": modes.POSCTL, "ALTCTL": modes.ALTCTL}


def command_name(command: int) -> str:
    """MAV_CMD name without its prefix, e.g. ``DO_SET_MODE``; the number if unknown."""
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else str(command)


def pilot_mode(fault: Fault) -> modes.PX4Mode:
    return _PILOT_MODES[fault.mode]


@dataclass
class TakeoverLog:
    """GCS traffic after the takeover, relative to the vehicle's counters at the takeover."""

    fault: Fault
    commands_at_start: int
    setpoints_at_start: int
    landed_by_pilot: bool = False
    by_command: Counter[str] = field(default_factory=Counter)

    def note_command(self, command: int) -> str:
        name = command_name(command)
        self.by_command[name] += 1
        return name

    def counts(self, stats: dict[str, int]) -> dict[str, Any]:
        """Fields for the truth records: commands and setpoints received since the takeover."""
        return {
            "commands_after_takeover": stats["rx_commands"] - self.commands_at_start,
            "setpoints_after_takeover": stats["rx_setpoints"] - self.setpoints_at_start,
            "command_names_after_takeover": dict(sorted(self.by_command.items())),
        }


NO_TAKEOVER: dict[str, Any] = {
    "commands_after_takeover": None,
    "setpoints_after_takeover": None,
    "command_names_after_takeover": None,
}
