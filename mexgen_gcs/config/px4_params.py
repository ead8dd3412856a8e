"""The PX4 parameters that decide what the vehicle does when this GCS fails, and its envelope,
judged against what a mission needs: the table `mexgen-gcs check --connect` prints and the
preflight check that refuses to fly an unsafe set.

Names, types, values and meanings follow PX4's parameter reference (v1.14 and later):
COM_OBL_RC_ACT 0 Position, 1 Altitude, 2 Stabilized, 3 Return, 4 Land, 5 Hold, 6 Terminate,
7 Disarm; NAV_DLL_ACT 0 Disabled, 1 Hold, 2 Return, 3 Land, 5 Terminate, 6 Disarm; GF_ACTION
0 None, 1 Warning, 2 Hold, 3 Return, 4 Terminate, 5 Land. This GCS flies offboard, so when it
dies the setpoints stop and PX4's offboard-loss failsafe acts after COM_OF_LOSS_T; when its
heartbeats stop (a dead laptop or radio, also during take-off and return, which are not
offboard) the data-link-loss failsafe acts after COM_DL_LOSS_T. A set is refused when it leaves
the vehicle without a safe action (falls from the sky, keeps flying with nobody in charge,
ignores the uploaded fence) or below the mission's needs (speed, PX4's own distance and height
fences); a return height below flight.alt_m is a warning, because PX4 keeps a higher current
height on its way home; each refusal names the parameter and a safe value, and can be
accepted knowingly (``safety.accept_px4_params`` or ``--accept-unsafe-params``).

Units: metres, m/s and seconds as PX4 declares them. No frames here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mexgen_gcs.config.mission import Mission
from mexgen_gcs.config.schema import PX4_SAFETY_PARAMS

Kind = Literal["int", "float"]
Verdict = Literal["ok", "warn", "refuse", "missing"]


@dataclass(frozen=True, slots=True)
class ParamDef:
    name: str
    kind: Kind
    """PX4's type: INT32 or FLOAT (the MAVLink PARAM protocol needs it)."""
    meaning: str
    values: Mapping[int, str] | None = None
    """Names of an enum's values."""


OBL_ACTIONS = {0: "Position", 1: "Altitude", 2: "Stabilized", 3: "Return", 4: "Land", 5: "Hold",
               6: "Terminate", 7: "Disarm"}
DLL_ACTIONS = {0: "Disabled", 1: "Hold", 2: "Return", 3: "Land", 5: "Terminate", 6: "Disarm"}
MIN_RTL_ALT_M = 15.0
"""Below this a failsafe return is refused outright (tree and mast height)."""
GF_ACTIONS = {0: "None", 1: "Warning", 2: "Hold", 3: "Return", 4: "Terminate", 5: "Land"}

PARAMS: tuple[ParamDef, ...] = (
    ParamDef("COM_OBL_RC_ACT", "int", "offboard loss action (our setpoints stop)", OBL_ACTIONS),
    ParamDef("COM_OF_LOSS_T", "float", "offboard loss timeout, s"),
    ParamDef("NAV_DLL_ACT", "int", "data link loss action (our heartbeats stop)", DLL_ACTIONS),
    ParamDef("COM_DL_LOSS_T", "int", "data link loss timeout, s"),
    ParamDef("GF_ACTION", "int", "geofence breach action", GF_ACTIONS),
    ParamDef("GF_MAX_HOR_DIST", "float", "max horizontal distance from home, m (0 off)"),
    ParamDef("GF_MAX_VER_DIST", "float", "max height above home, m (0 off)"),
    ParamDef("RTL_RETURN_ALT", "float", "return-to-launch height above home, m"),
    ParamDef("MPC_XY_VEL_MAX", "float", "max horizontal speed, m/s"),
    ParamDef("MPC_Z_VEL_MAX_UP", "float", "max climb rate, m/s"),
    ParamDef("MPC_Z_VEL_MAX_DN", "float", "max descent rate, m/s"),
    ParamDef("COM_DISARM_PRFLT", "float", "disarm if not taken off within, s (<= 0 off)"),
)
BY_NAME = {p.name: p for p in PARAMS}
NAMES = tuple(p.name for p in PARAMS)
assert NAMES == PX4_SAFETY_PARAMS, "config.schema.PX4_SAFETY_PARAMS lists these names"


@dataclass(frozen=True, slots=True)
class ParamRow:
    """One parameter: its value on the vehicle, what the mission needs, the verdict."""

    name: str
    value: float | None
    meaning: str
    need: str
    verdict: Verdict
    problem: str = ""
    """For warn/refuse: what is wrong and the safe value."""
    accepted: bool = False
    """A refusal the operator accepted (safety.accept_px4_params / --accept-unsafe-params)."""

    def shown_value(self) -> str:
        if self.value is None:
            return "(not read)"
        d = BY_NAME.get(self.name)
        text = f"{int(self.value)}" if d is not None and d.kind == "int" else f"{self.value:g}"
        if d is not None and d.values is not None:
            text += f" {d.values.get(int(self.value), '?')}"
        return text


@dataclass(frozen=True, slots=True)
class ParamReport:
    rows: tuple[ParamRow, ...]

    @property
    def refused(self) -> tuple[ParamRow, ...]:
        """Refusals not accepted: the mission must not fly."""
        return tuple(r for r in self.rows if r.verdict == "refuse" and not r.accepted)

    @property
    def warnings(self) -> tuple[ParamRow, ...]:
        return tuple(r for r in self.rows if r.verdict in ("warn", "missing") or (
            r.verdict == "refuse" and r.accepted))

    def table(self) -> str:
        """The parameter table as aligned text lines."""
        head = ("parameter", "vehicle", "mission needs", "verdict")
        body = [(r.name, r.shown_value(), r.need,
                 "REFUSED" if r.verdict == "refuse" and not r.accepted else
                 "accepted (unsafe)" if r.verdict == "refuse" else r.verdict)
                for r in self.rows]
        widths = [max(len(str(row[i])) for row in [head, *body]) for i in range(4)]
        lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
                 for row in [head, *body]]
        lines.insert(1, "  ".join("-" * w for w in widths))
        return "\n".join(lines)

    def problems(self) -> list[str]:
        """One sentence per refusal or warning, refusals first."""
        out = [f"{r.name} = {r.shown_value()}: {r.problem}" for r in self.refused]
        out += [f"{r.name} = {r.shown_value()}: {r.problem}"
                + (" (accepted)" if r.accepted else "") for r in self.warnings]
        return out


Rule = Callable[[float, Mission], tuple[str, Verdict, str]]
"""(value, mission) -> (what the mission needs, verdict, problem and safe value)."""


def _offboard_loss(v: float, m: Mission) -> tuple[str, Verdict, str]:
    need = "an action that keeps the vehicle flying safely (3 Return, 4 Land or 5 Hold)"
    a = int(v)
    if a in (6, 7):
        return need, "refuse", (f"the vehicle would {OBL_ACTIONS[a].lower()} (fall) when this "
                                "GCS's setpoints stop; set COM_OBL_RC_ACT = 3 (Return)")
    if a in (0, 1, 2):
        return need, "warn", (f"{OBL_ACTIONS[a]} hands the vehicle to the RC pilot when our "
                              "setpoints stop; without a pilot on the sticks PX4 falls back to "
                              "its own action; 3 (Return) needs nobody")
    return need, "ok", ""


def _offboard_timeout(v: float, m: Mission) -> tuple[str, Verdict, str]:
    need = f"<= {m.safety.link_loss_timeout_s:g} s (safety.link_loss_timeout_s)"
    if v > m.safety.link_loss_timeout_s:
        return need, "warn", (f"PX4 waits {v:g} s without setpoints before acting; the GCS "
                              f"counts the link lost after {m.safety.link_loss_timeout_s:g} s")
    return need, "ok", ""


def _data_link_loss(v: float, m: Mission) -> tuple[str, Verdict, str]:
    need = "2 Return (or 1 Hold / 3 Land)"
    a = int(v)
    if a == 0:
        return need, "refuse", ("data link loss is ignored: with this GCS gone during take-off "
                                "or return the vehicle flies on with nobody in charge; set "
                                "NAV_DLL_ACT = 2 (Return)")
    if a in (5, 6):
        return need, "refuse", (f"the vehicle would {DLL_ACTIONS[a].lower()} (fall) when this "
                                "GCS's heartbeats stop; set NAV_DLL_ACT = 2 (Return)")
    return need, "ok", ""


def _geofence_action(v: float, m: Mission) -> tuple[str, Verdict, str]:
    if not m.safety.upload_geofence:
        return "any (safety.upload_geofence is false)", "ok", ""
    need = "2 Hold, 3 Return or 5 Land (the uploaded fence must stop the vehicle)"
    a = int(v)
    if a in (0, 1):
        return need, "refuse", (f"{GF_ACTIONS.get(a, '?')}: a breach of the uploaded fence "
                                "would not stop the vehicle; set GF_ACTION = 2 (Hold)")
    if a == 4:
        return need, "refuse", ("Terminate: a fence breach would drop the vehicle; set "
                                "GF_ACTION = 2 (Hold)")
    return need, "ok", ""


def _max_horizontal(v: float, m: Mission) -> tuple[str, Verdict, str]:
    area = m.search_area()
    far_m = float(np.max(np.hypot(area.vertices_m[:, 0], area.vertices_m[:, 1])))
    need = f"0 (off) or >= {far_m:.0f} m (the area's farthest corner)"
    if v > 0.0 and v < far_m:
        return need, "refuse", (f"PX4's own fence stops the vehicle {v:g} m from home, inside "
                                "the search area; set GF_MAX_HOR_DIST = 0 or >= "
                                f"{math.ceil(far_m)}")
    return need, "ok", ""


def _max_vertical(v: float, m: Mission) -> tuple[str, Verdict, str]:
    top = m.flight.alt_m
    need = f"0 (off) or > {top:g} m (flight.alt_m)"
    if v > 0.0 and v <= top:
        return need, "refuse", (f"PX4's own fence stops the climb at {v:g} m, at or below "
                                f"flight.alt_m; set GF_MAX_VER_DIST = 0 or > {top:g}")
    return need, "ok", ""


def _rtl_alt(v: float, m: Mission) -> tuple[str, Verdict, str]:
    """PX4's return climbs to RTL_RETURN_ALT or keeps a higher current height, so a failsafe
    return from the search flies at flight.alt_m either way; only a return started lower (the
    take-off climb, or a search allowed down to flight.min_alt_m) flies at RTL_RETURN_ALT. A
    warning, and a refusal below MIN_RTL_ALT_M."""
    need = f">= {m.flight.alt_m:g} m (flight.alt_m)"
    if v < MIN_RTL_ALT_M:
        return need, "refuse", (f"a failsafe return at {v:g} m flies into trees and masts; set "
                                f"RTL_RETURN_ALT >= {m.flight.alt_m:g}")
    low = m.flight.min_alt_m
    if low is not None and v < m.flight.alt_m:
        return need, "warn", (f"below flight.alt_m: a return started while the search flies low "
                              f"(flight.min_alt_m {low:g} m) flies home at {max(v, low):g} m; "
                              f"RTL_RETURN_ALT >= {m.flight.alt_m:g} is safer")
    if v < m.flight.alt_m:
        return need, "warn", (f"below flight.alt_m: a return started from the search keeps "
                              f"{m.flight.alt_m:g} m, one started lower (during take-off) "
                              f"flies home at {v:g} m; RTL_RETURN_ALT >= {m.flight.alt_m:g} is "
                              "safer")
    return need, "ok", ""


def _xy_speed(v: float, m: Mission) -> tuple[str, Verdict, str]:
    need = f">= {m.flight.speed_m_s:g} m/s (flight.speed_m_s)"
    if v < m.flight.speed_m_s:
        return need, "refuse", (f"the vehicle cannot fly the mission's speed ({v:g} < "
                                f"{m.flight.speed_m_s:g} m/s) and the planner's paths assume it; "
                                f"set MPC_XY_VEL_MAX >= {m.flight.speed_m_s:g} or lower "
                                "flight.speed_m_s")
    return need, "ok", ""


def _info(need: str) -> Rule:
    return lambda v, m: (need, "ok", "")


def _disarm_preflight(v: float, m: Mission) -> tuple[str, Verdict, str]:
    need = "> 0 (PX4 disarms if not taken off in time)"
    if v <= 0.0:
        return need, "warn", "auto-disarm before take-off is off"
    return need, "ok", ""


RULES: dict[str, Rule] = {
    "COM_OBL_RC_ACT": _offboard_loss,
    "COM_OF_LOSS_T": _offboard_timeout,
    "NAV_DLL_ACT": _data_link_loss,
    "COM_DL_LOSS_T": _info("(information)"),
    "GF_ACTION": _geofence_action,
    "GF_MAX_HOR_DIST": _max_horizontal,
    "GF_MAX_VER_DIST": _max_vertical,
    "RTL_RETURN_ALT": _rtl_alt,
    "MPC_XY_VEL_MAX": _xy_speed,
    "MPC_Z_VEL_MAX_UP": _info("(information: take-off climb)"),
    "MPC_Z_VEL_MAX_DN": _info("(information: landing descent)"),
    "COM_DISARM_PRFLT": _disarm_preflight,
}


def evaluate(mission: Mission, values: Mapping[str, float | None],
             accepted: frozenset[str] | set[str] = frozenset()) -> ParamReport:
    """Judge the vehicle's values (None: could not be read) against the mission. A name in
    `accepted` (or the mission's safety.accept_px4_params) turns its refusal into a warning."""
    ok_list = set(accepted) | set(mission.safety.accept_px4_params)
    rows = []
    for d in PARAMS:
        value = values.get(d.name)
        if value is None or not math.isfinite(value):
            rows.append(ParamRow(d.name, None, d.meaning, "", "missing",
                                 "not read from the vehicle (another PX4 version?); check it "
                                 "by hand"))
            continue
        need, verdict, problem = RULES[d.name](float(value), mission)
        rows.append(ParamRow(d.name, float(value), d.meaning, need, verdict, problem,
                             accepted=verdict == "refuse" and d.name in ok_list))
    return ParamReport(tuple(rows))
