"""Human views of a mission: what it would fly, the resolved dict, the key reference (what
looks wrong is in `config.checks`).

Frame: ENU metres about home for every position printed in metres; corners are also given
as WGS84 lat/lon degrees.
"""

from __future__ import annotations

import enum
import json
import types
import typing
from collections.abc import Iterator
from typing import Any, NamedTuple

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from mexgen_gcs.config.checks import MOVING_MOTIONS
from mexgen_gcs.config.mission import Mission
from mexgen_gcs.config.sim_schema import FAULT_MODELS
from mexgen_gcs.core.area import SearchArea


def dump_resolved(mission: Mission) -> dict[str, Any]:
    """The mission with every default filled in, as plain JSON-able data."""
    return mission.model_dump(mode="json")


def describe(mission: Mission) -> str:
    """A few lines saying what the mission would fly."""
    m = mission
    area = m.search_area()
    w, e, s, n = area.bounds
    frame = m.local_frame()
    lines = [f"Mission {m.name!r} ({m.source_path or 'not from a file'}): {m.kind}, "
             f"{len(m.tags)} tag{'s' if len(m.tags) != 1 else ''}"]
    ground = (f"ground {m.home.alt_m:g} m AMSL (compared with the vehicle's home)"
              if m.home.alt_m is not None else "heights above the vehicle's own home")
    lines.append(f"  home       {m.home.lat_deg:.6f}, {m.home.lon_deg:.6f}, {ground}")
    size = f"{e - w:.0f} m east-west x {n - s:.0f} m north-south"
    km2 = SearchArea.area_m2(area.vertices_m) / 1e6
    if m.area.rectangle_m is not None:
        lines.append(f"  area       rectangle {size} ({km2:.2f} km^2); about home: "
                     f"east {w:g}..{e:g} m, north {s:g}..{n:g} m")
    else:
        lines.append(f"  area       polygon of {len(area.vertices_m)} vertices, {km2:.2f} km^2, "
                     f"bounding box {size}; about home: east {w:.0f}..{e:.0f} m, north "
                     f"{s:.0f}..{n:.0f} m")
    if m.area.from_file is not None:
        lines[-1] += f" (from {m.area.from_file})"
    corners = {"SW": (w, s), "SE": (e, s), "NE": (e, n), "NW": (w, n)}
    if m.area.polygon_deg is not None:
        corners = {f"v{i}": (float(x), float(y)) for i, (x, y) in enumerate(area.vertices_m)}
    shown = []
    for label, (x, y) in corners.items():
        lat, lon, _ = frame.to_geodetic(x, y, 0.0)
        shown.append(f"{label} {float(lat):.6f}, {float(lon):.6f}")
    lines.append(f"  corners    {'; '.join(shown)}")
    f = m.flight
    lines.append(f"  flight     {f.alt_m:g} m above home at {f.speed_m_s:g} m/s, "
                 f"acceleration {f.max_accel_m_s2:g} m/s^2")
    lines.append("  tags       " + ", ".join(f"{t.id} {t.freq_hz / 1e6:.4f} MHz" for t in m.tags))
    r = m.receiver
    sources = ", ".join(r.allowed_sources) if r.allowed_sources else "any source"
    lines.append(f"  receiver   {r.listen} from {sources}; frequency tolerance "
                 f"{r.freq_tolerance_hz:g} Hz, pulse every {r.pulse_period_s:g} s, silent "
                 f"after {r.heartbeat_timeout_s:g} s")
    radio = m.radio
    reach_m = m.radio_model().distance_for_power_m(radio.sensitivity_db, f.alt_m)
    lines.append(f"  radio      P0 {radio.p0_db:g} dB at {radio.d0_m:g} m, path loss n "
                 f"{radio.path_loss_exponent:g}, noise {radio.noise_std_db:g} dB, sensitivity "
                 f"{radio.sensitivity_db:g} dB (~{reach_m:.0f} m horizontal range at altitude)")
    flt = m.filter
    lines.append(f"  filter     {flt.motion} motion, {flt.n_particles} particles per tag, "
                 f"speed {flt.speed_min_m_s:g}..{flt.speed_max_m_s:g} m/s")
    p = m.planner
    gen = {"mexgen": f"MexGen, M = {p.samples}", "pim": "PIM",
           "mc": f"MC-{p.mc_rollouts}"}[p.method]
    lines.append(f"  planner    {gen}; {p.n_particles} particles, replan every "
                 f"{p.replan_interval_s:g} s, lookahead {p.lookahead_s:g} s in "
                 f"{p.step_s:g} s steps, discount {p.discount:g}, alpha {p.alpha:g}, "
                 f"target {p.target}")
    loc = m.localisation
    lines.append(f"  localised  when {loc.confidence:.0%} of a tag's estimate is within "
                 f"{loc.radius_m:g} m (existence >= {loc.min_existence:g})")
    if m.kind == "follow" and m.follow is not None:
        lines.append(f"  follow     {m.follow.tag} for {m.follow.duration_s:g} s")
    sf = m.safety
    uploaded = "uploaded" if sf.upload_geofence else "not uploaded"
    if sf.upload_geofence:
        uploaded += (", required" if sf.require_geofence else ", optional") + (
            ", replaces any fence on the vehicle" if sf.replace_existing_geofence else
            ", not over another station's fence")
    lines.append(f"  safety     home after {sf.max_mission_time_s:g} s or at "
                 f"{sf.battery_rtl_percent:g}% battery; link lost after "
                 f"{sf.link_loss_timeout_s:g} s then {sf.on_link_regained}; radio silent "
                 f"{sf.radio_loss_timeout_s:g} s -> home; geofence {sf.geofence_margin_m:g} m "
                 f"outside the area and home ({uploaded}); vehicle home within "
                 f"{sf.home_max_distance_m:g} m of the area (warn beyond "
                 f"{sf.home_mismatch_warn_m:g} m from this home)")
    if sf.accept_px4_params:
        lines.append(f"  PX4 params unsafe values accepted: {', '.join(sf.accept_px4_params)}")
    lines += _describe_sim(m)
    return "\n".join(lines)


def _describe_sim(m: Mission) -> list[str]:
    sim = m.sim
    lines = [f"  sim        seed {sim.seed}, battery {sim.battery_endurance_s:g} s, "
             f"{len(sim.faults)} fault{'s' if len(sim.faults) != 1 else ''}"]
    for tid in m.tag_ids:
        st = m.sim_tag(tid)
        where = "random position" if st.position_m is None else \
            f"[{st.position_m[0]:g}, {st.position_m[1]:g}] m"
        speed = ""
        if st.motion in MOVING_MOTIONS:
            lo, hi = st.speed_m_s
            speed = f" at {lo:g} m/s" if lo == hi else f" at {lo:g}..{hi:g} m/s"
        lines.append(f"             {tid}: {st.motion}{speed} from {where}")
    for fault in sim.faults:
        extra = ", ".join(f"{k} {v:g}" for k, v in fault.model_dump().items()
                          if k not in ("kind", "at_s"))
        lines.append(f"             fault {fault.kind} at {fault.at_s:g} s ({extra})")
    return lines


class KeyDoc(NamedTuple):
    """Reference documentation of one mission-file key."""

    key: str
    type: str
    default: str
    limits: str
    description: str


def schema_reference() -> Iterator[KeyDoc]:
    """Documentation of every key of the mission file, in schema order."""
    yield from _model_rows(Mission, "")
    for model in FAULT_MODELS:
        kind = typing.get_args(model.model_fields["kind"].annotation)[0]
        yield from _model_rows(model, f"sim.faults[kind={kind}].")


def _model_rows(model: type[BaseModel], prefix: str) -> Iterator[KeyDoc]:
    for attr, field in model.model_fields.items():
        name = field.alias or attr
        sub = _sub_model(field.annotation)
        if field.default is PydanticUndefined and field.default_factory is None:
            default = "required"
        elif field.default_factory is not None:
            default = "section defaults"
        elif field.default is None:
            default = "none"
        else:
            default = json.dumps(to_plain(field.default))
        yield KeyDoc(f"{prefix}{name}", _type_text(field.annotation), default,
                     _limits(field.metadata), field.description or "")
        if sub is not None and name != "faults":
            brackets = "[]" if _is_seq(field.annotation) else ""
            yield from _model_rows(sub, f"{prefix}{name}{brackets}.")


def to_plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _limits(metadata: list[Any]) -> str:
    parts = []
    for item in metadata:
        for attr, sign in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            bound = getattr(item, attr, None)
            if bound is not None:
                parts.append(f"{sign} {bound:g}")
        for attr, sign in (("min_length", ">="), ("max_length", "<=")):
            bound = getattr(item, attr, None)
            if bound is not None:
                parts.append(f"length {sign} {bound}")
        pattern = getattr(item, "pattern", None)
        if pattern is not None:
            parts.append(f"matches {pattern}")
    return ", ".join(parts)


def _is_seq(annotation: Any) -> bool:
    return typing.get_origin(annotation) is tuple and typing.get_args(annotation)[-1] is Ellipsis


def _sub_model(annotation: Any) -> type[BaseModel] | None:
    """The section model inside an annotation (Optional, tuple[...] and Annotated unwrapped)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _sub_model(arg)
        if found is not None:
            return found
    return None


def _type_text(annotation: Any) -> str:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type_text(args[0])
    if origin is typing.Literal:
        return " | ".join(str(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        parts = [_type_text(a) for a in args if a is not type(None)]
        if len(parts) > 2:
            return "one of the fault mappings"
        return " | ".join(parts) + (" | none" if type(None) in args else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_type_text(args[0])}"
        return "[" + ", ".join(_type_text(a) for a in args) + "]"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "mapping"
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return " | ".join(str(member.value) for member in annotation)
    return {float: "number", int: "integer", str: "text", bool: "true | false"}.get(
        annotation, str(annotation))
