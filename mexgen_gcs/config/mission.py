"""The mission: top-level schema, rules across sections, and builders of core objects.

Frame: local ENU metres about `home` (x east, y north, z up). `search_area()` converts a
`polygon_deg` area into that frame; every position in the file (`rectangle_m`, sim
`position_m`) is already in it.
"""

from __future__ import annotations

import difflib
from typing import Literal

import numpy as np
from pydantic import Field, PrivateAttr, field_validator, model_validator

from mexgen_gcs.config.area_files import self_intersection
from mexgen_gcs.config.schema import (
    Area,
    FilterSection,
    Flight,
    Follow,
    Home,
    KeyPath,
    Localisation,
    LogSection,
    Planner,
    RadioSection,
    Receiver,
    RuleViolation,
    Safety,
    Section,
    Str,
    TagSpec,
)
from mexgen_gcs.config.sim_schema import SimSection, SimTag
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import FilterConfig
from mexgen_gcs.core.generators import method_name
from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.core.mission_core import MissionCore, ReportRule
from mexgen_gcs.core.motion import MotionModel, make_motion_model
from mexgen_gcs.core.planner import PlannerConfig
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import RadioUncertainty, TagRadioPrior


class Mission(Section):
    """A mission file, validated. Build it with `mexgen_gcs.config.load_mission`."""

    version: Literal[1] = Field(description="Mission file format version; must be 1.")
    name: Str = Field(min_length=1, max_length=100, description="Mission name for logs.")
    kind: Literal["localise", "follow"] = Field(
        description="localise: find every tag; follow: keep tracking follow.tag."
    )
    home: Home = Field(description="Home (take-off point, origin of the ENU frame).")
    area: Area = Field(description="The search area.")
    tags: tuple[TagSpec, ...] = Field(min_length=1, max_length=64,
                                      description="The radio tags, at least one.")
    flight: Flight = Field(default_factory=Flight, description="How the vehicle flies.")
    radio: RadioSection = Field(default_factory=RadioSection, description="Radio model.")
    receiver: Receiver = Field(default_factory=Receiver, description="Detection input.")
    filter: FilterSection = Field(default_factory=FilterSection, description="Estimator.")
    planner: Planner = Field(default_factory=Planner, description="Planner.")
    localisation: Localisation = Field(default_factory=Localisation,
                                       description="When a tag is localised.")
    follow: Follow | None = Field(None, description="Required when kind = follow.")
    safety: Safety = Field(default_factory=Safety, description="Limits and failsafes.")
    log: LogSection = Field(default_factory=LogSection, description="The flight log.")
    sim: SimSection = Field(default_factory=SimSection, description="Simulator only.")

    _source_path: str | None = PrivateAttr(default=None)
    _source_text: str | None = PrivateAttr(default=None)

    @field_validator("version", mode="before")
    @classmethod
    def _version_is_a_whole_number(cls, value: object) -> object:
        if type(value) is not int:
            raise ValueError(f"expected 1 (the format version, a whole number); found {value!r}")
        return value

    # -- rules across sections --------------------------------------------------------------

    @model_validator(mode="after")
    def _rules(self) -> Mission:
        issues: list[tuple[KeyPath, str]] = []
        self._check_tags(issues)
        self._check_follow(issues)
        area = self._check_area(issues)
        if area is not None:
            self._check_home(area, issues)
        self._check_sim(area, issues)
        if issues:
            raise RuleViolation(issues)
        return self

    def _check_tags(self, issues: list[tuple[KeyPath, str]]) -> None:
        first_index: dict[str, int] = {}
        for j, tag in enumerate(self.tags):
            if tag.id in first_index:
                issues.append((("tags", j, "id"), f"duplicate tag id {tag.id!r} (already "
                               f"tags[{first_index[tag.id]}]); expected unique ids"))
            else:
                first_index[tag.id] = j
        tol = self.receiver.freq_tolerance_hz
        for j, tag in enumerate(self.tags):
            for i in range(j):
                other = self.tags[i]
                if abs(tag.freq_hz - other.freq_hz) <= 2.0 * tol:
                    issues.append((("tags", j, "freq_hz"), (
                        f"{tag.freq_hz} Hz is within 2 x receiver.freq_tolerance_hz "
                        f"({2.0 * tol:g} Hz) of tags[{i}] ({other.id}, {other.freq_hz} Hz); "
                        "expected frequencies further apart so a detection maps to one tag")))
                    break

    def _check_follow(self, issues: list[tuple[KeyPath, str]]) -> None:
        ids = self.tag_ids
        if self.follow is not None and self.follow.tag not in ids:
            issues.append((("follow", "tag"),
                           f"unknown tag {self.follow.tag!r}; expected one of the mission tags "
                           f"{', '.join(dict.fromkeys(ids))}{_did_you_mean(self.follow.tag, ids)}"))
        if self.kind != "follow":
            return
        if self.follow is None:
            issues.append((("follow",), "kind is 'follow', so a follow section is required, "
                           "e.g. follow: {tag: T1, duration_s: 600}"))
        if len(self.tags) != 1:
            followed = f" ({self.follow.tag})" if self.follow is not None else ""
            issues.append((("tags",), f"a follow mission has exactly the followed tag{followed}; "
                           f"found {len(self.tags)} tags"))

    def _check_area(self, issues: list[tuple[KeyPath, str]]) -> SearchArea | None:
        try:
            area = self.search_area()
        except ValueError as exc:
            issues.append((("area",), f"expected a polygon with non-zero area; {exc}"))
            return None
        if self.area.polygon_deg is not None:
            crossing = self_intersection(area.vertices_m)
            if crossing is not None:
                i, j = crossing
                issues.append((("area", "polygon_deg"), f"edges {i}-{i + 1} and {j}-"
                               f"{(j + 1) % len(area.vertices_m)} cross; expected a simple "
                               "polygon (vertices in order around the boundary)"))
            w, e, s, n = area.bounds
            if max(e - w, n - s) > 100_000.0:
                issues.append((("area", "polygon_deg"), "expected an area at most 100 km "
                               f"across; found {max(e - w, n - s) / 1000.0:.0f} km"))
        return area

    def _check_home(self, area: SearchArea, issues: list[tuple[KeyPath, str]]) -> None:
        outside_m = float(area.distance_outside_m(np.zeros(2)))
        limit_m = self.safety.home_max_distance_m
        if outside_m > limit_m:
            issues.append((("home",), f"home is {outside_m:.0f} m outside the search area; "
                           f"expected at most safety.home_max_distance_m = {limit_m:g} m "
                           "(move home or the area, or raise that limit)"))

    def _check_sim(self, area: SearchArea | None, issues: list[tuple[KeyPath, str]]) -> None:
        ids = self.tag_ids
        seen: set[str] = set()
        for i, sim_tag in enumerate(self.sim.tags):
            if sim_tag.id not in ids:
                issues.append((("sim", "tags", i, "id"), f"{sim_tag.id!r} is not a mission tag; "
                               f"expected one of {', '.join(dict.fromkeys(ids))}"
                               f"{_did_you_mean(sim_tag.id, ids)}"))
            elif sim_tag.id in seen:
                issues.append((("sim", "tags", i, "id"),
                               f"duplicate sim tag {sim_tag.id!r}; expected one entry per tag"))
            seen.add(sim_tag.id)
            if area is not None and sim_tag.position_m is not None:
                xy = np.asarray(sim_tag.position_m)
                if not bool(area.contains(xy)):
                    w, e, s, n = area.bounds
                    issues.append((("sim", "tags", i, "position_m"), (
                        f"[{xy[0]:g}, {xy[1]:g}] is outside the search area; expected a point "
                        f"inside it (east {w:g}..{e:g} m, north {s:g}..{n:g} m)")))

    # -- what the rest of the program builds from the mission ------------------------------

    @property
    def tag_ids(self) -> tuple[str, ...]:
        """Mission tag ids in file order."""
        return tuple(tag.id for tag in self.tags)

    @property
    def source_path(self) -> str | None:
        """The file this mission was loaded from, if any."""
        return self._source_path

    @property
    def source_text(self) -> str | None:
        """The raw text of the mission file, if loaded from one."""
        return self._source_text

    def with_source(self, path: str | None, text: str | None) -> Mission:
        """Record where the mission came from (the loader calls this); returns self."""
        self._source_path = path
        self._source_text = text
        return self

    def tag(self, tag_id: str) -> TagSpec:
        """The tag with this id; KeyError if none."""
        for tag in self.tags:
            if tag.id == tag_id:
                return tag
        raise KeyError(tag_id)

    def tag_for_frequency(self, freq_hz: float) -> str | None:
        """Id of the tag within receiver.freq_tolerance_hz of freq_hz (the nearest), or None."""
        best: tuple[float, str] | None = None
        for tag in self.tags:
            off = abs(tag.freq_hz - freq_hz)
            if off <= self.receiver.freq_tolerance_hz and (best is None or off < best[0]):
                best = (off, tag.id)
        return None if best is None else best[1]

    def local_frame(self) -> LocalFrame:
        """The ENU frame anchored at home (at home.alt_m AMSL, 0 when not given). The mission
        uses it horizontally; heights come from the vehicle's home."""
        alt = self.home.alt_m if self.home.alt_m is not None else 0.0
        return LocalFrame(self.home.lat_deg, self.home.lon_deg, alt)

    def search_area(self) -> SearchArea:
        """The search area in ENU metres about home."""
        if self.area.rectangle_m is not None:
            r = self.area.rectangle_m
            return SearchArea.rectangle(r.west_m, r.east_m, r.south_m, r.north_m)
        assert self.area.polygon_deg is not None  # guaranteed by Area's validator
        lat_lon = np.asarray(self.area.polygon_deg, dtype=np.float64)
        east, north, _ = self.local_frame().to_enu(lat_lon[:, 0], lat_lon[:, 1])
        return SearchArea(np.column_stack([east, north]))

    def area_polygon_deg(self, *, fence: bool = False) -> list[tuple[float, float]]:
        """The search area as [(lat_deg, lon_deg)] (a rectangle's four corners), or with
        ``fence`` the geofence the GCS uploads before take-off (the convex hull of the area and
        the mission home pushed out by safety.geofence_margin_m; in flight the vehicle's home
        is added too)."""
        area = self.search_area()
        vertices = (area.fence_polygon(self.safety.geofence_margin_m, np.zeros((1, 2)))
                    if fence else area.vertices_m)
        lat, lon, _ = self.local_frame().to_geodetic(vertices[:, 0], vertices[:, 1])
        return [(float(a), float(b)) for a, b in zip(np.atleast_1d(lat), np.atleast_1d(lon),
                                                     strict=True)]

    def radio_model(self) -> RadioModel:
        """The core radio model with this mission's parameters."""
        fields = RadioModel.__dataclass_fields__
        return RadioModel(**{k: v for k, v in self.radio.model_dump().items() if k in fields})

    def radio_uncertainty(self) -> RadioUncertainty:
        """What the estimator does not know about the radio (radio section)."""
        return self.radio.uncertainty()

    def tag_radio_priors(self) -> dict[str, TagRadioPrior]:
        """Per-tag offsets about radio.p0_db from tags[].p0_db / p0_std_db (calibrations)."""
        return {t.id: TagRadioPrior(0.0 if t.p0_db is None else t.p0_db - self.radio.p0_db,
                                    t.p0_std_db)
                for t in self.tags if t.p0_db is not None or t.p0_std_db is not None}

    def filter_motion_model(self) -> MotionModel:
        """The motion model the filter assumes (filter.motion and its parameters)."""
        f = self.filter
        return make_motion_model(
            f.motion,
            rw_std_m_per_sqrt_s=f.rw_std_m_per_sqrt_s,
            accel_std_m_s2=f.accel_std_m_s2,
            mismatch_accel_std_m_s2=f.mismatch_accel_std_m_s2,
            turn_rate_deg_s=f.turn_rate_deg_s,
            speed_min_m_s=f.speed_min_m_s,
            speed_max_m_s=f.speed_max_m_s,
        )

    def report_rule(self) -> ReportRule:
        """When a tag is reported before it reaches the radius (localisation section)."""
        loc = self.localisation
        return ReportRule(stall_window_s=loc.stall_window_s,
                          stall_min_shrink=loc.stall_min_shrink_percent / 100.0,
                          tag_budget_s=loc.tag_budget_s)

    def filter_config(self) -> FilterConfig:
        """The core Bernoulli filter settings (filter + localisation sections)."""
        f, loc = self.filter, self.localisation
        return FilterConfig(
            n_particles=f.n_particles,
            survival_prob=f.survival_prob,
            birth_prob=f.birth_prob,
            initial_existence=f.initial_existence,
            resample_ess_fraction=f.resample_ess_fraction,
            roughening_k=f.roughening_k,
            localised_radius_m=loc.radius_m,
            localised_confidence=loc.confidence,
            localised_min_existence=loc.min_existence,
            radio_unknowns=self.radio_uncertainty(),
        )

    def planner_config(self, method: str) -> PlannerConfig:
        """The core planner's settings for ``method`` (the planner and flight sections): the
        one place a flight, its warm-up, replay and the experiments get them."""
        p = self.planner
        return PlannerConfig(
            method=method_name(method), samples=p.samples, mc_rollouts=p.mc_rollouts,
            lookahead_s=p.lookahead_s, step_s=p.step_s, discount=p.discount, alpha=p.alpha,
            speed_m_s=self.flight.speed_m_s, max_accel_m_s2=self.flight.max_accel_m_s2,
            action_cost_weight=p.action_cost_weight, altitudes_m=self.flight.altitudes_m())

    def mission_core(self, rng: np.random.Generator, *, area: SearchArea | None = None,
                     t0: float = 0.0, tight_radius_m: float | None = None) -> MissionCore:
        """The mission's decision core: the one constructor the flight, the warm-up, the
        experiments and replay share, so that what is measured is what flies. ``area``: the
        filters' prior and birth region (default the search area; the experiments' initial
        search space); ``t0``, ``tight_radius_m``: see :class:`core.mission_core.MissionCore`."""
        return MissionCore(
            self.tag_ids, self.filter_motion_model(), self.radio_model(),
            self.search_area() if area is None else area, self.filter_config(), rng,
            kind=self.kind, target_rule=self.planner.target,
            follow_tag=self.follow.tag if self.follow is not None else None,
            planning_particles=self.planner.n_particles, t0=t0,
            tag_priors=self.tag_radio_priors(), tight_radius_m=tight_radius_m,
            report_rule=self.report_rule())

    def sim_tag(self, tag_id: str) -> SimTag:
        """The simulated truth of a mission tag: its sim.tags entry, or a static tag at a
        random position if it has none. KeyError if tag_id is not a mission tag."""
        if tag_id not in self.tag_ids:
            raise KeyError(tag_id)
        for sim_tag in self.sim.tags:
            if sim_tag.id == tag_id:
                return sim_tag
        return SimTag(id=tag_id)

    def sim_motion_model(self, tag_id: str, rng: np.random.Generator) -> MotionModel:
        """The truth motion model of a tag. Speed range as given; a turn-rate range is drawn
        once here with ``rng`` (the paper draws one turn rate per object)."""
        sim_tag = self.sim_tag(tag_id)
        lo_deg_s, hi_deg_s = sim_tag.turn_rate_deg_s
        turn_deg_s = lo_deg_s if lo_deg_s == hi_deg_s else float(rng.uniform(lo_deg_s, hi_deg_s))
        return make_motion_model(
            sim_tag.motion,
            rw_std_m_per_sqrt_s=sim_tag.rw_std_m_per_sqrt_s,
            accel_std_m_s2=sim_tag.accel_std_m_s2,
            turn_rate_deg_s=turn_deg_s,
            speed_min_m_s=sim_tag.speed_m_s[0],
            speed_max_m_s=sim_tag.speed_m_s[1],
        )


def _did_you_mean(word: str, choices: tuple[str, ...] | list[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""
