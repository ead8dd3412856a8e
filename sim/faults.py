"""The fault schedule: from the mission's ``sim.faults`` plus ``--fault`` flags.

Each fault starts at ``at_s`` of sim time. Durations are sim seconds, except ``link_drop``,
whose duration is wall seconds: it exists to exercise the ground station's link-loss
handling, and MAVSDK and the GCS measure link loss on the wall clock.

Kinds and their fields:
- ``link_drop(duration_s)``: no MAVLink is sent or accepted.
- ``gps_loss(duration_s)``: no GPS fix (GPS_RAW_INT fix 0, health bit clear, no
  GLOBAL_POSITION_INT, arming refused, receiver pose left out of datagrams).
- ``battery_sag(percent)``: the remaining charge drops by ``percent`` points at once.
- ``radio_silence(duration_s)``: the receiver sends nothing, heartbeats included.
- ``detection_dropout(duration_s, probability)``: each detection is lost with ``probability``.
- ``clutter(duration_s, rate_per_s)``: extra spurious detections at ``rate_per_s`` (sim).
- ``clock_offset(offset_s)``: from ``at_s`` on, datagram timestamps are shifted by ``offset_s``.
- ``clock_drift(ppm)``: from ``at_s`` on, the receiver's clock runs ``ppm`` parts per million
  fast (negative: slow): datagram timestamps gain ``ppm * 1e-6 * (t - at_s)`` (sim seconds).
- ``pilot_takeover(mode, land_after_s)``: a pilot with an RC transmitter switches the vehicle to
  ``mode`` (POSCTL or ALTCTL, sticks centred: it brakes and holds) and, ``land_after_s`` sim
  seconds later, to LAND (it lands and disarms). Offboard setpoints are ignored in between,
  as PX4 ignores them outside OFFBOARD; GCS commands are still obeyed, as PX4 obeys them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, fields
from typing import Any

KINDS: dict[str, tuple[str, ...]] = {
    "link_drop": ("duration_s",),
    "gps_loss": ("duration_s",),
    "battery_sag": ("percent",),
    "radio_silence": ("duration_s",),
    "detection_dropout": ("duration_s", "probability"),
    "clutter": ("duration_s", "rate_per_s"),
    "clock_offset": ("offset_s",),
    "clock_drift": ("ppm",),
    "pilot_takeover": ("mode", "land_after_s"),
}
_DURATIONAL = {"link_drop", "gps_loss", "radio_silence", "detection_dropout", "clutter",
               "pilot_takeover"}
#: Faults that stay in effect once started (the receiver's clock).
_PERMANENT = {"clock_offset", "clock_drift"}
#: Fields that are text, not numbers.
_TEXT_FIELDS = {"mode"}
#: Modes a pilot can switch to with sticks centred (the vehicle brakes and holds).
PILOT_MODES = ("POSCTL", "ALTCTL")
DEFAULT_LAND_AFTER_S = 30.0


@dataclass(frozen=True, slots=True)
class Fault:
    kind: str
    at_s: float
    duration_s: float = 0.0
    percent: float = 0.0
    probability: float = 1.0
    rate_per_s: float = 0.0
    offset_s: float = 0.0
    ppm: float = 0.0
    mode: str = "POSCTL"
    land_after_s: float = DEFAULT_LAND_AFTER_S

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown fault kind {self.kind!r}; expected one of {sorted(KINDS)}")
        values = [getattr(self, f.name) for f in fields(self)
                  if f.name != "kind" and f.name not in _TEXT_FIELDS]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"fault {self.kind}: values must be finite")
        if self.at_s < 0 or self.duration_s < 0 or self.rate_per_s < 0:
            raise ValueError(f"fault {self.kind}: at_s, duration_s, rate_per_s must be >= 0")
        if not 0.0 <= self.probability <= 1.0 or not 0.0 <= self.percent <= 100.0:
            raise ValueError(f"fault {self.kind}: probability in [0, 1], percent in [0, 100]")
        if self.mode not in PILOT_MODES:
            raise ValueError(f"fault {self.kind}: mode must be one of {', '.join(PILOT_MODES)}, "
                             f"got {self.mode!r}")
        if self.land_after_s < 0:
            raise ValueError(f"fault {self.kind}: land_after_s must be >= 0")

    @property
    def length_s(self) -> float:
        """How long a durational fault lasts (``land_after_s`` for a pilot takeover)."""
        return self.land_after_s if self.kind == "pilot_takeover" else self.duration_s

    def describe(self) -> dict[str, Any]:
        keep = ("at_s",) + KINDS[self.kind]
        return {"kind": self.kind} | {k: getattr(self, k) for k in keep}


def parse_fault_flag(text: str) -> Fault:
    """``KIND,at_s=S[,field=value...]``, e.g. ``link_drop,at_s=30,duration_s=8``."""
    kind, *pairs = [p.strip() for p in text.split(",") if p.strip()]
    values: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or key not in ("at_s", *KINDS.get(kind, ())):
            raise ValueError(f"bad fault field {pair!r} for {kind!r} (expected key=value with "
                             f"keys at_s, {', '.join(KINDS.get(kind, ()))})")
        values[key] = value.strip().upper() if key in _TEXT_FIELDS else float(value)
    if "at_s" not in values:
        raise ValueError(f"fault {text!r} needs at_s=SECONDS")
    return Fault(kind, **values)


def fault_from_config(obj: Any) -> Fault:
    """A fault from the mission schema (a pydantic model or a mapping)."""
    get: Any = obj.get if isinstance(obj, dict) else (lambda k, d=None: getattr(obj, k, d))
    kind = str(get("kind"))
    extra: dict[str, Any] = {
        k: (str(get(k)) if k in _TEXT_FIELDS else float(get(k)))
        for k in KINDS.get(kind, ()) if get(k) is not None}
    return Fault(kind, float(get("at_s")), **extra)


class FaultSchedule:
    """Which faults are active, with start/end transitions for the truth log."""

    def __init__(self, faults: Iterable[Fault]) -> None:
        self.faults = sorted(faults, key=lambda f: f.at_s)
        self._started: dict[int, float] = {}  # index -> wall time at start
        self._ended: set[int] = set()

    def update(self, sim_s: float, wall_s: float) -> list[tuple[str, Fault]]:
        """Advance to (sim_s, wall_s); returns ("start"|"end", fault) transitions in order."""
        out: list[tuple[str, Fault]] = []
        for i, f in enumerate(self.faults):
            if i in self._ended:
                continue
            if i not in self._started:
                if sim_s < f.at_s:
                    continue
                self._started[i] = wall_s
                out.append(("start", f))
            if f.kind not in _DURATIONAL:
                self._ended.add(i)  # one-shot (battery_sag) or permanent (clock faults)
                continue
            elapsed = wall_s - self._started[i] if f.kind == "link_drop" else sim_s - f.at_s
            if elapsed >= f.length_s:
                self._ended.add(i)
                out.append(("end", f))
        return out

    def active(self, kind: str) -> list[Fault]:
        """Faults of ``kind`` in effect now (clock faults stay in effect once started)."""
        return [f for i, f in enumerate(self.faults) if f.kind == kind and i in self._started
                and (i not in self._ended or kind in _PERMANENT)]

    def next_start_s(self, after_s: float) -> float:
        """Sim time of the next fault start, or end on sim time, after ``after_s`` (inf if none)."""
        starts = (f.at_s for i, f in enumerate(self.faults)
                  if i not in self._started and f.at_s > after_s)
        ends = (f.at_s + f.length_s for i, f in enumerate(self.faults)
                if f.kind in _DURATIONAL and f.kind != "link_drop" and i not in self._ended
                and f.at_s + f.length_s > after_s)
        return min((*starts, *ends), default=math.inf)
