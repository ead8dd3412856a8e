"""Typed schema of the mission file's sections (pydantic v2, frozen, unknown keys forbidden).

Frame: positions in metres are local ENU about the mission home (x east, y north, z up);
headings are compass degrees (0 = north, clockwise). Every key carries its unit in its name.
The top-level `Mission` model and its cross-section rules live in `mission.py`, the `sim`
section in `sim_schema.py`.

Cross-field rules raise `RuleViolation`, a ValueError that carries the key path of each
problem relative to the model that raised it, so the loader can point at the exact line.
"""

from __future__ import annotations

import contextlib
import difflib
import ipaddress
from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, Strict, field_validator, model_validator

from mexgen_gcs.config.urls import parse_udp_url
from mexgen_gcs.core.generators import Method
from mexgen_gcs.core.radio_belief import RadioUncertainty

KeyPath = tuple[str | int, ...]

Float = Annotated[float, Strict()]
"""A number (int or float literal); text and booleans are rejected."""
Int = Annotated[int, Strict()]
"""A whole number; 1.0, text and booleans are rejected."""
Str = Annotated[str, Strict()]
Bool = Annotated[bool, Strict()]

TAG_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$"
"""Tag ids: 1-32 characters, letters/digits first, then letters, digits, `_`, `.` or `-`."""

TagId = Annotated[str, Strict(), Field(pattern=TAG_ID_PATTERN)]
FilterMotion = Literal["static", "rw", "cv", "ctra", "cv-ift", "cv-mismatch"]


class RuleViolation(ValueError):
    """One or more cross-field problems, each `(key path relative to the model, message)`."""

    def __init__(self, issues: list[tuple[KeyPath, str]]) -> None:
        super().__init__("; ".join(msg for _, msg in issues))
        self.issues = issues


def check_rules(issues: list[tuple[KeyPath, str]]) -> None:
    """Raise RuleViolation if any issue was collected."""
    if issues:
        raise RuleViolation(issues)


class Section(BaseModel):
    """Base of every schema model: frozen, unknown keys are errors, no NaN/infinity."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Home(Section):
    """Take-off point and origin of the local ENU frame."""

    lat_deg: Float = Field(ge=-90.0, le=90.0, description="Latitude of home, degrees WGS84.")
    lon_deg: Float = Field(ge=-180.0, le=180.0, description="Longitude of home, degrees WGS84.")
    alt_m: Float | None = Field(
        None, ge=-500.0, le=9000.0,
        description="Ground altitude at home, metres AMSL, optional: heights come from the "
        "vehicle's own home (HOME_POSITION); when given it is compared with the vehicle's "
        "home before arming (warning beyond safety.home_alt_mismatch_warn_m).",
    )


class Rectangle(Section):
    """An axis-aligned rectangle in ENU metres about home."""

    west_m: Float = Field(ge=-50_000.0, le=50_000.0, description="West edge, metres east of home.")
    east_m: Float = Field(ge=-50_000.0, le=50_000.0, description="East edge, metres east of home.")
    south_m: Float = Field(
        ge=-50_000.0, le=50_000.0, description="South edge, metres north of home."
    )
    north_m: Float = Field(
        ge=-50_000.0, le=50_000.0, description="North edge, metres north of home."
    )

    @model_validator(mode="after")
    def _ordered(self) -> Rectangle:
        issues: list[tuple[KeyPath, str]] = []
        if not self.east_m > self.west_m:
            issues.append((("east_m",), f"expected east_m > west_m ({self.west_m:g}); "
                                        f"found {self.east_m:g}"))
        if not self.north_m > self.south_m:
            issues.append((("north_m",), f"expected north_m > south_m ({self.south_m:g}); "
                                         f"found {self.north_m:g}"))
        check_rules(issues)
        return self


LatLon = tuple[
    Annotated[Float, Field(ge=-90.0, le=90.0)], Annotated[Float, Field(ge=-180.0, le=180.0)]
]


class Area(Section):
    """The search area: exactly one of `rectangle_m`, `polygon_deg` or `from` (a file)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False,
                              populate_by_name=True)

    rectangle_m: Rectangle | None = Field(
        None, description="Rectangle in metres about home (ENU): west_m, east_m, south_m, north_m."
    )
    polygon_deg: tuple[LatLon, ...] | None = Field(
        None, min_length=3, max_length=200,
        description="Simple polygon as [[lat_deg, lon_deg], ...], at least 3 vertices, "
        "either orientation, not closed (the last vertex joins the first).",
    )
    from_file: Str | None = Field(
        None, alias="from", min_length=1, max_length=4096,
        description="The area from a file (relative paths from the mission file): a "
        "QGroundControl .plan (its one geofence inclusion polygon), .kml (one Polygon) or "
        ".geojson (one Polygon); the loader reads it into polygon_deg.",
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> Area:
        if self.from_file is not None:
            if self.rectangle_m is not None:
                raise RuleViolation([((), "expected exactly one of rectangle_m, polygon_deg or "
                                         "from; found rectangle_m and from")])
            if self.polygon_deg is None:  # only the loader can read the file
                raise RuleViolation([(("from",), f"{self.from_file!r} was not read; load the "
                                      "mission with load_mission (relative to its file)")])
            return self
        if (self.rectangle_m is None) == (self.polygon_deg is None):
            found = "both" if self.rectangle_m is not None else "neither"
            raise RuleViolation([((), f"expected exactly one of rectangle_m, polygon_deg or "
                                     f"from; found {found}")])
        return self


class Flight(Section):
    """How the vehicle flies the search."""

    alt_m: Float = Field(50.0, gt=0.0, le=1000.0, description="Flight altitude above home, metres.")
    speed_m_s: Float = Field(10.0, gt=0.0, le=40.0, description="Horizontal cruise speed, m/s.")
    max_accel_m_s2: Float = Field(
        4.0, gt=0.0, le=20.0, description="Horizontal acceleration the planner assumes, m/s^2."
    )
    min_alt_m: Float | None = Field(
        None, gt=0.0, le=1000.0,
        description="Lowest altitude above home the planner may descend to, metres: every "
        "heading is also scored at this altitude and the vehicle climbs or descends to the "
        "chosen one (closer passes over a tag tell more of where it is). It must be safe over "
        "the whole area: the ground and anything on it, relative to home. Omitted: the "
        "search holds alt_m.")

    @model_validator(mode="after")
    def _min_alt_below(self) -> Flight:
        if self.min_alt_m is not None and self.min_alt_m > self.alt_m:
            raise RuleViolation([(("min_alt_m",), f"expected min_alt_m <= alt_m "
                                  f"({self.alt_m:g}); found {self.min_alt_m:g}")])
        return self

    def altitudes_m(self) -> tuple[float, ...]:
        """The planner's action altitudes: () to hold alt_m, else (alt_m, min_alt_m)."""
        if self.min_alt_m is None or self.min_alt_m == self.alt_m:
            return ()
        return (self.alt_m, self.min_alt_m)


class TagSpec(Section):
    """One radio tag to find."""

    id: TagId = Field(description="Tag id as it appears in detections, e.g. T1.")
    freq_hz: Int = Field(
        gt=0, le=100_000_000_000, description="Carrier frequency, Hz (e.g. 150100000)."
    )
    p0_db: Float | None = Field(
        None, ge=-200.0, le=100.0,
        description="This tag's received power at radio.d0_m, dB, when measured before take-off "
        "(e.g. from `mexgen-gcs analyze --calibrate`); omitted = radio.p0_db.",
    )
    p0_std_db: Float | None = Field(
        None, ge=0.0, le=40.0,
        description="Uncertainty of this tag's p0_db, dB; omitted = radio.p0_std_db.",
    )


def _hypotheses(value: Any) -> Any:
    """Accept a single number x as the one hypothesis [x]."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (value,)
    return value


CLASSIC_ESTIMATOR: Mapping[str, Any] = MappingProxyType({
    "radio.p0_std_db": 0.0, "radio.path_loss_exponent_std": 0.0, "radio.front_back_std_db": 0.0,
    "radio.shadowing_std_db": [0.0], "radio.model_error_std_db": [0.0],
    "radio.outlier_prob": 0.0})
"""Dotted mission overrides for the classic estimator, which trusts the radio model exactly
(the paper's simulations and the estimator of earlier versions)."""


class RadioSection(Section):
    """Radio measurement and detection model (the first fields are core RadioModel's, same
    names), and what the estimator does not know about it (core RadioUncertainty). All of the
    latter zero (shadowing and model error [0]) is the classic estimator that trusts the model
    exactly; the defaults are chosen for the field (see missions/README.md)."""

    p0_db: Float = Field(-7.0, ge=-200.0, le=100.0,
                         description="Received power at the reference distance d0_m, dB.")
    d0_m: Float = Field(1.0, gt=0.0, le=1000.0, description="Reference distance, metres.")
    path_loss_exponent: Float = Field(1.5, gt=0.0, le=10.0, description="Path-loss exponent n.")
    noise_std_db: Float = Field(2.5, gt=0.0, le=50.0,
                                description="Standard deviation of the measurement noise, dB.")
    front_back_db: Float = Field(3.0, ge=0.0, le=60.0,
                                 description="Antenna loss towards the tail vs the nose, dB.")
    sensitivity_db: Float = Field(-60.0, ge=-200.0, le=100.0,
                                  description="Power at which half of pd_max is detected, dB.")
    detection_spread_db: Float = Field(2.0, gt=0.0, le=50.0,
                                       description="Width of the detection threshold, dB.")
    pd_max: Float = Field(0.95, ge=0.0, le=1.0,
                          description="Detection probability far above the sensitivity.")
    min_distance_m: Float = Field(1.0, gt=0.0, le=1000.0,
                                  description="Distances below this are clamped, metres.")
    clutter_rate: Float = Field(0.01, ge=0.0, le=100.0,
                                description="Spurious detections per tag channel per pulse.")
    clutter_min_db: Float = Field(-90.0, ge=-300.0, le=100.0,
                                  description="Lowest power of a clutter detection, dB.")
    clutter_max_db: Float = Field(0.0, ge=-300.0, le=100.0,
                                  description="Highest power of a clutter detection, dB.")
    p0_std_db: Float = Field(
        4.0, ge=0.0, le=40.0,
        description="Prior std of each tag's received-power offset about p0_db, dB (collar "
        "transmit power and antenna gain vary by several dB); 0 = known exactly.")
    path_loss_exponent_std: Float = Field(
        0.25, ge=0.0, le=5.0,
        description="Prior std of the path-loss exponent about path_loss_exponent; 0 = known.")
    front_back_std_db: Float = Field(
        4.0, ge=0.0, le=40.0,
        description="Prior std of the antenna's front-to-back ratio about front_back_db, dB "
        "(the airframe changes the pattern); 0 = known.")
    shadowing_std_db: tuple[Annotated[Float, Field(ge=0.0, le=40.0)], ...] = Field(
        (0.0, 2.0, 4.0), min_length=1, max_length=6,
        description="Hypotheses about spatially correlated shadowing, dB (a number or a list); "
        "the data select among them with model_error_std_db.")
    shadowing_distance_m: Float = Field(
        50.0, gt=0.0, le=10_000.0, description="Correlation distance of the shadowing, m.")
    model_error_std_db: tuple[Annotated[Float, Field(ge=0.0, le=40.0)], ...] = Field(
        (0.0, 3.0), min_length=1, max_length=6,
        description="Hypotheses about uncorrelated model error (fading, antenna pattern), dB.")
    outlier_prob: Float = Field(
        0.05, ge=0.0, lt=1.0,
        description="Probability that a detected power is an outlier (robust likelihood).")

    @field_validator("shadowing_std_db", "model_error_std_db", mode="before")
    @classmethod
    def _lists(cls, value: Any) -> Any:
        return _hypotheses(value)

    @model_validator(mode="after")
    def _clutter_range(self) -> RadioSection:
        if not self.clutter_max_db > self.clutter_min_db:
            raise RuleViolation([(("clutter_max_db",), f"expected clutter_max_db > clutter_min_db "
                                  f"({self.clutter_min_db:g}); found {self.clutter_max_db:g}")])
        return self

    def uncertainty(self) -> RadioUncertainty:
        """What the estimator does not know about the radio (core RadioUncertainty)."""
        return RadioUncertainty(
            p0_std_db=self.p0_std_db, path_loss_exponent_std=self.path_loss_exponent_std,
            front_back_std_db=self.front_back_std_db,
            shadowing_std_db=tuple(self.shadowing_std_db),
            shadowing_distance_m=self.shadowing_distance_m,
            model_error_std_db=tuple(self.model_error_std_db), outlier_prob=self.outlier_prob)


class Receiver(Section):
    """Where and how detections arrive (detection wire format v1 over UDP)."""

    listen: Str = Field("udp://0.0.0.0:14600",
                        description="UDP address to listen on, udp://HOST:PORT.")
    allowed_sources: tuple[Str, ...] = Field(
        ("127.0.0.1/32",), max_length=64,
        description="Networks (CIDR) datagrams may come from; an empty list accepts any source.",
    )
    freq_tolerance_hz: Float = Field(
        5000.0, gt=0.0, le=1_000_000.0,
        description="A reported frequency maps to a tag within this many Hz.",
    )
    pulse_period_s: Float = Field(1.0, gt=0.0, le=60.0, description="Tag pulse period, seconds.")
    format: Literal["wire-v1", "mavlink-tunnel"] = Field(
        "wire-v1",
        description="What arrives on `listen`: wire-v1 = the GCS's JSON datagrams "
        "(docs/wire-format.md); mavlink-tunnel = MAVLink TUNNEL messages carrying "
        "TagTracker/UAV-RT PulseInfo_t (docs/receiver-interop.md).",
    )
    pulse_width_s: Float = Field(
        0.02, gt=0.0, le=1.0,
        description="Tag pulse width, seconds: the IQ receiver's detector is matched to it.")
    max_clock_skew_s: Float = Field(
        30.0, gt=0.0, le=86_400.0,
        description="Detections whose timestamp, on the mission clock after the receiver's "
        "clock correction, is further than this from now are rejected, s.",
    )
    max_clock_offset_s: Float = Field(
        2_592_000.0, gt=0.0, le=1e11,
        description="Timestamps further than this from now as sent (before correction) are "
        "refused as garbage, s (default 30 days; a receiver that boots at 1970 needs 1e11).",
    )
    clock_correction: Bool = Field(
        True,
        description="Learn each receiver's clock offset and drift from its heartbeats and map "
        "its timestamps to the mission clock (false: log the estimate, use times as sent).",
    )
    tunnel_calibration_db: Float = Field(
        0.0, ge=-300.0, le=300.0,
        description="mavlink-tunnel only: added to 10 log10(noise_psd) + snr to give rssi_db, "
        "dB (measure it against a known source).",
    )
    heartbeat_timeout_s: Float = Field(
        3.0, gt=0.0, le=600.0, description="The receiver counts as silent after this long, s."
    )

    @field_validator("listen")
    @classmethod
    def _listen_url(cls, value: str) -> str:
        parse_udp_url(value)
        return value

    @field_validator("allowed_sources")
    @classmethod
    def _networks(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        issues: list[tuple[KeyPath, str]] = []
        for i, text in enumerate(value):
            try:
                ipaddress.ip_network(text, strict=True)
            except ValueError as exc:
                hint = ""
                with contextlib.suppress(ValueError):
                    hint = f" (did you mean {ipaddress.ip_network(text, strict=False)}?)"
                issues.append(((i,), f"expected a network like 127.0.0.1/32; found {text!r}: "
                                     f"{exc}{hint}"))
        check_rules(issues)
        return value

    def networks(self) -> tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...]:
        """`allowed_sources` parsed; empty = any source."""
        return tuple(ipaddress.ip_network(text) for text in self.allowed_sources)


class FilterSection(Section):
    """Per-tag Bernoulli particle filter and the motion model it assumes."""

    motion: FilterMotion = Field(
        "rw", description="Motion model the filter assumes: static, rw, cv, ctra, cv-ift, "
        "cv-mismatch (CV with mismatch_accel_std_m_s2, standing in for a CV-IFT truth).",
    )
    rw_std_m_per_sqrt_s: Float = Field(0.5, ge=0.0, le=100.0,
                                       description="Random-walk position noise, m/sqrt(s).")
    accel_std_m_s2: Float = Field(0.1, ge=0.0, le=50.0,
                                  description="Acceleration noise of cv/ctra/cv-ift, m/s^2.")
    mismatch_accel_std_m_s2: Float = Field(
        1.0, ge=0.0, le=50.0, description="Acceleration noise of cv-mismatch, m/s^2."
    )
    turn_rate_deg_s: Float = Field(12.5, ge=0.0, le=180.0,
                                   description="Turn rate of ctra/cv-ift turns, deg/s.")
    speed_min_m_s: Float = Field(0.0, ge=0.0, le=100.0,
                                 description="Slowest initial particle speed, m/s.")
    speed_max_m_s: Float = Field(6.0, ge=0.0, le=100.0,
                                 description="Fastest initial particle speed, m/s.")
    n_particles: Int = Field(2000, ge=10, le=1_000_000, description="Particles per tag.")
    survival_prob: Float = Field(0.999, ge=0.0, le=1.0,
                                 description="Probability a tag persists per pulse period.")
    birth_prob: Float = Field(0.001, ge=0.0, le=1.0,
                              description="Probability a tag appears per pulse period.")
    initial_existence: Float = Field(0.9, ge=0.0, le=1.0,
                                     description="Existence probability before any pulse.")
    resample_ess_fraction: Float = Field(
        0.5, gt=0.0, le=1.0, description="Resample when ESS falls below this fraction of N."
    )
    roughening_k: Float = Field(
        0.2, ge=0.0, le=10.0,
        description="Roughening constant after resampling (jitter std k x range x N^(-1/D)). "
        "The robust estimator's claims hold at 0.2 but not far from it (0.22 of claims held "
        "at 0.3 in the matched world; docs/results/localisation.md): change it only with a study.")

    @model_validator(mode="after")
    def _speeds(self) -> FilterSection:
        if self.speed_min_m_s > self.speed_max_m_s:
            raise RuleViolation([(("speed_min_m_s",), f"expected speed_min_m_s <= speed_max_m_s "
                                  f"({self.speed_max_m_s:g}); found {self.speed_min_m_s:g}")])
        return self


class Planner(Section):
    """Information-gain planner: which measurement generator and its horizon."""

    method: Method = Field(
        Method.MEXGEN,
        description="Measurement generator: mexgen (MexGen-M), pim or mc (MC-M).")
    samples: Int = Field(512, ge=1, le=1_000_000, description="MexGen samples M.")
    mc_rollouts: Int = Field(8, ge=1, le=10_000, description="MC rollouts per action (MC-M).")
    n_particles: Int = Field(1000, ge=10, le=1_000_000,
                             description="Particles drawn from the filter for planning.")
    replan_interval_s: Float = Field(5.0, gt=0.0, le=3600.0, description="Replan period, s.")
    lookahead_s: Float = Field(20.0, gt=0.0, le=3600.0, description="Planning horizon, s.")
    step_s: Float = Field(1.0, gt=0.0, le=600.0, description="Horizon step, s.")
    discount: Float = Field(0.95, gt=0.0, le=1.0, description="Discount factor per step.")
    alpha: Float = Field(0.1, gt=0.0, le=100.0, description="Renyi divergence alpha (not 1).")
    target: Literal["closest", "all"] = Field(
        "closest", description="Plan for the closest unlocalised tag or all unlocalised tags."
    )
    action_cost_weight: Float = Field(0.0, ge=0.0, le=1e6,
                                      description="Weight of the action cost in the reward.")

    @model_validator(mode="after")
    def _steps(self) -> Planner:
        issues: list[tuple[KeyPath, str]] = []
        if self.step_s > self.lookahead_s:
            issues.append((("step_s",), f"expected step_s <= lookahead_s ({self.lookahead_s:g}); "
                                        f"found {self.step_s:g}"))
        if self.alpha == 1.0:
            issues.append((("alpha",), "expected alpha != 1 (the Renyi divergence is undefined "
                                       "at 1); found 1"))
        check_rules(issues)
        return self


class Localisation(Section):
    """When a tag counts as localised, and when it is reported anyway so the mission ends in
    bounded time (core.mission_core.ReportRule; docs/mission-finish.md)."""

    radius_m: Float = Field(50.0, gt=0.0, le=100_000.0,
                            description="Uncertainty radius a tag must shrink to, metres.")
    confidence: Float = Field(0.95, gt=0.0, lt=1.0,
                              description="Probability mass inside radius_m.")
    min_existence: Float = Field(0.5, ge=0.0, le=1.0,
                                 description="Existence probability a localised tag needs.")
    stall_window_s: Float | None = Field(
        120.0, gt=0.0, le=86_400.0,
        description="A tag worked on this long whose radius shrank by less than "
        "stall_min_shrink_percent over that time is reported as stalled and the vehicle moves "
        "on, seconds of worked-on time (null: never stalled).")
    stall_min_shrink_percent: Float = Field(
        10.0, ge=0.0, lt=100.0,
        description="Least shrink of the radius over stall_window_s that keeps a tag worked on, "
        "percent.")
    tag_budget_s: Float | None = Field(
        240.0, gt=0.0, le=86_400.0,
        description="A tag worked on this long in all is reported with its radius (reason "
        "budget) and the vehicle moves on, seconds (null: no budget).")


class Follow(Section):
    """Which tag to follow, for kind = follow."""

    tag: TagId = Field(description="Id of the tag to follow (one of tags).")
    duration_s: Float = Field(600.0, gt=0.0, le=86_400.0,
                              description="How long to follow, seconds.")


class LogSection(Section):
    """The flight log (written by a thread of its own, off the flight's event loop)."""

    fsync_every_s: Float | None = Field(
        1.0, ge=0.0, le=3600.0,
        description="Force the flight log to disk (fsync) at most this often, wall seconds: "
        "a power cut loses at most about this much of the log's tail. 0: after every record; "
        "null: never (the operating system decides).")


PX4_SAFETY_PARAMS = (
    "COM_OBL_RC_ACT", "COM_OF_LOSS_T", "NAV_DLL_ACT", "COM_DL_LOSS_T", "GF_ACTION",
    "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST", "RTL_RETURN_ALT", "MPC_XY_VEL_MAX", "MPC_Z_VEL_MAX_UP",
    "MPC_Z_VEL_MAX_DN", "COM_DISARM_PRFLT")
"""The PX4 parameters the preflight check reads (config.px4_params judges them)."""


class Safety(Section):
    """Limits and failsafes."""

    max_mission_time_s: Float = Field(1800.0, gt=0.0, le=86_400.0,
                                      description="Return home after this long, seconds.")
    battery_rtl_percent: Float = Field(25.0, ge=0.0, lt=100.0,
                                       description="Return home at this battery level, percent.")
    link_loss_timeout_s: Float = Field(3.0, gt=0.0, le=600.0,
                                       description="Vehicle link counts as lost after this, s.")
    on_link_regained: Literal["resume", "rtl"] = Field(
        "resume", description="After a link loss: resume the mission or return home."
    )
    radio_loss_timeout_s: Float = Field(
        15.0, gt=0.0, le=3600.0,
        description="Hold while the receiver is silent; return home after this long, seconds.",
    )
    geofence_margin_m: Float = Field(50.0, ge=0.0, le=10_000.0,
                                     description="Geofence distance outside the area, metres.")
    upload_geofence: Bool = Field(True, description="Upload the geofence to the vehicle.")
    require_geofence: Bool = Field(
        False, description="Refuse to arm (exit 2) when the vehicle does not accept the "
        "geofence; false: warn and fly without it. Needs upload_geofence.")
    replace_existing_geofence: Bool = Field(
        False, description="Replace a geofence already on the vehicle (e.g. the pilot's, from "
        "QGroundControl); false: show it and refuse to arm (exit 2).")
    accept_px4_params: tuple[Str, ...] = Field(
        (), max_length=len(PX4_SAFETY_PARAMS),
        description="PX4 parameters whose unsafe value the preflight check accepts knowingly "
        "(a warning instead of a refusal), e.g. [NAV_DLL_ACT]; see docs/field-kit.md.")
    home_max_distance_m: Float = Field(
        500.0, ge=0.0, le=100_000.0,
        description="Home (the mission's and the vehicle's) must be inside the area or at most "
        "this far outside, metres; else the mission refuses to arm.",
    )
    home_mismatch_warn_m: Float = Field(
        20.0, ge=0.0, le=100_000.0,
        description="Warn before arming when the vehicle's home is further than this from the "
        "mission's home (horizontal), metres.",
    )
    home_alt_mismatch_warn_m: Float = Field(
        15.0, ge=0.0, le=10_000.0,
        description="Warn before arming when home.alt_m (if given) differs from the vehicle's "
        "home altitude by more than this, metres.",
    )

    @model_validator(mode="after")
    def _fence_and_params(self) -> Safety:
        issues: list[tuple[KeyPath, str]] = []
        if self.require_geofence and not self.upload_geofence:
            issues.append((("require_geofence",), "require_geofence is true but upload_geofence "
                           "is false; expected upload_geofence: true (or require_geofence: "
                           "false)"))
        for i, name in enumerate(self.accept_px4_params):
            if name not in PX4_SAFETY_PARAMS:
                close = difflib.get_close_matches(name, PX4_SAFETY_PARAMS, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                issues.append((("accept_px4_params", i), f"{name!r} is not a checked PX4 "
                               f"parameter{hint}; expected one of {', '.join(PX4_SAFETY_PARAMS)}"))
        check_rules(issues)
        return self
