"""The paper's simulation scenarios (section 4) as settings, and the mission each run flies.

Frame: local ENU metres about the area centre (x east, y north, z up); headings are compass
degrees. Tags are on the ground (z = 0); the vehicle flies at ``alt_m``.

Two areas, both squares about the origin:

- the *initial search space* (``initial_half_m``): where the objects start and what the
  filters' prior and birth density cover (the paper's 4 km x 4 km for following, 1 km x 1 km
  for localisation);
- the *search area* (``area_half_m``): where the vehicle may fly (the planner prunes actions
  that leave it, guidance steers back into it) and where the objects must stay for
  ``min_inside_s``. For localisation it is 4 km x 4 km: an object at 2.5-3 m/s on a constant
  velocity cannot stay 650 s inside a 1 km square (it crosses 1.6-2 km), so the paper's
  "remains within the search area for at least 650 s" only holds for a larger area. For
  following it is 12 km x 12 km, so that the vehicle can follow an object (at most 3.6 km in
  600 s) wherever it goes from the 4 km square.

Two presets say what a batch is (``--preset``):

- ``paper`` (the default): the paper's sensor and planner. Its receiver is a monopole,
  omnidirectional in azimuth (``front_back_db = 0``), and it has no detection model: every
  pulse inside the operating area is detected. Here that is ``pd_max = 1`` with the
  sensitivity ``PAPER_SENSITIVITY_DB`` (-120 dB) far below the weakest noiseless power
  anywhere in the area (:func:`weakest_power_db`: the area's diagonal at the flight altitude,
  -63.3 dB for localisation, -70.4 dB for following), i.e. >= 24 detection spreads above it:
  1 - pD < 1e-130, so pD is exactly 1 in double precision.
- ``field``: the mission defaults as a sensitivity study: the airframe-shadowed antenna
  (3 dB front-to-back), -60 dB sensitivity, 2 dB detection spread, pd_max 0.95.

Both fly the product's planner (core PlannerConfig defaults): the paper's 20 s (following
10 s) look-ahead of 1 s steps, stretched only when the target's belief lies beyond it
(``planner_reach``), and the detect/miss outcome pooled (``planner_outcome``; with pD = 1, the
paper preset, there is no outcome to weigh). ``dataclasses.replace(sc, planner_reach=False)``
flies the paper's fixed look-ahead.

Motion noise is explicit and reported: truth and filter use the same RW step (0.5 m/sqrt(s))
and CV / CV-IFT acceleration noise (0.1 m/s^2 per axis); the mismatched filter (a CV model for
a CV-IFT truth) gets the inflated acceleration noise :func:`mismatch_accel_std_m_s2` derives
from the turns it must cover.

The settings that are not experiment-specific are a real mission (``mission_yaml`` ->
``config.parse_mission``), so the filter, radio and planner are configured by the same schema
and mapping code a flight uses; the two planner settings the mission schema has no key for
(``planner_reach``, ``planner_outcome``) are applied by the runner and recorded here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, Literal

import yaml

from mexgen_gcs.config import CLASSIC_ESTIMATOR, Mission, parse_mission
from mexgen_gcs.config.schema import Localisation
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.generators import Method
from mexgen_gcs.core.motion import PAPER_TRANSITION
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.reality import PROFILES
from mexgen_gcs.errors import ConfigError

ScenarioKind = Literal["follow", "localise"]
ModelName = Literal["static", "rw", "cv", "cv-ift", "cv-ift-mismatch"]
PresetName = Literal["paper", "field"]

MODELS: tuple[ModelName, ...] = ("static", "rw", "cv", "cv-ift", "cv-ift-mismatch")
"""``static``: tags that do not move (issue 13's localisation studies); the others are the
paper's four models."""
ESTIMATORS = ("classic", "robust")
PRESETS: tuple[PresetName, ...] = ("paper", "field")

PAPER_SENSITIVITY_DB = -120.0
"""The paper preset's receiver sensitivity: far below any power in the operating area."""
_LOCALISATION = Localisation()
"""The mission schema's localisation defaults (the stall and budget rules)."""
TIGHT_RADIUS_M = 25.0
"""The second localisation reading (the paper's ~12 m errors suggest a tighter criterion)."""

#: experiment method name -> (planner.method, label in tables)
METHODS: dict[str, tuple[str, str]] = {
    "pim": (Method.PIM.value, "PIM"),
    "mc8": (Method.MC.value, "MC-8"),
    "mexgen": (Method.MEXGEN.value, "MexGen"),
}

#: model -> (truth motion, the motion model the filter assumes)
_MODEL_MOTION: dict[str, tuple[str, str]] = {
    "static": ("static", "static"),
    "rw": ("rw", "rw"),
    "cv": ("cv", "cv"),
    "cv-ift": ("cv-ift", "cv-ift"),
    "cv-ift-mismatch": ("cv-ift", "cv-mismatch"),
}


@dataclass(frozen=True, slots=True)
class Scenario:
    """Everything that defines one experiment's runs except the method and the seeds."""

    kind: ScenarioKind
    model: ModelName
    preset: PresetName
    """"paper" or "field" (module docstring)."""
    n_tags: int
    area_half_m: float
    initial_half_m: float
    duration_s: float
    """Follow: how long to follow. Localise: the time limit (fail after it)."""
    min_inside_s: float
    """Truth objects must stay inside the search area this long (0 = no constraint)."""
    quick: bool = False
    """Shortened horizons and particle sets for a smoke run."""
    alt_m: float = 50.0
    min_alt_m: float | None = None
    """The lowest altitude the planner may choose (every heading at ``alt_m`` and at this);
    None: every action holds ``alt_m`` (the paper's actions)."""
    speed_m_s: float = 15.0
    max_accel_m_s2: float = 4.0
    pulse_period_s: float = 1.0
    control_period_s: float = 1.0
    """How often the setpoint (guidance with its area guard) is recomputed: once per pulse.
    The planner never chooses a heading whose path leaves the area within the look-ahead, so
    the guard only acts when every action is pruned; a 1 s reaction is plenty there."""
    replan_interval_s: float = 5.0
    lookahead_s: float = 20.0
    truth_speed_m_s: tuple[float, float] = (2.5, 3.0)
    truth_turn_rate_deg_s: tuple[float, float] = (10.0, 15.0)
    truth_rw_std_m_per_sqrt_s: float = 0.5
    truth_accel_std_m_s2: float = 0.1
    """Acceleration noise of the CV and CV-IFT truth, per axis."""
    filter_rw_std_m_per_sqrt_s: float = 0.5
    filter_accel_std_m_s2: float = 0.1
    """The CV / CV-IFT filter's acceleration noise (the truth's: the model is known)."""
    mismatch_accel_std_m_s2: float = 1.0
    """The mismatched (CV) filter's acceleration noise; see mismatch_accel_std_m_s2()."""
    filter_particles: int = 2000
    filter_roughening_k: float = 0.2
    """The filter's roughening constant (the mission's filter.roughening_k)."""
    planning_particles: int = 1000
    mexgen_samples: int = 512
    mc_rollouts: int = 8
    localised_radius_m: float = 50.0
    tight_radius_m: float | None = TIGHT_RADIUS_M
    """Second reading: when every tag's radius first drops to this (runs continue after the
    localised_radius_m completion, targeting the tags above it, until the time limit). None:
    no second reading, a run stops at the first completion."""
    localised_confidence: float = 0.95
    front_back_db: float = 0.0
    """The receiver antenna's front-to-back ratio (core RadioModel)."""
    sensitivity_db: float = PAPER_SENSITIVITY_DB
    detection_spread_db: float = 2.0
    pd_max: float = 1.0
    planner_reach: bool = True
    """core PlannerConfig.reach: stretch the look-ahead to reach a far tag."""
    planner_outcome: str = "pooled"
    """core PlannerConfig.outcome: how an uncertain detect/miss outcome is weighed."""
    planner_toward_target: bool = False
    """core PlannerConfig.toward_target: one more action, straight at the target's estimate."""
    reality: str = "matched"
    """The radio world's reality profile (core.reality.PROFILES): how it differs from the
    mission's model. "matched" is the model itself."""
    finish: bool = False
    """Report every tag in bounded time (the mission's stall and budget rules,
    ``stall_window_s`` etc. below) and end the run when all are; False: no such rule, a run
    ends when all are localised (or at the limit)."""
    stall_window_s: float | None = _LOCALISATION.stall_window_s
    stall_min_shrink_percent: float = _LOCALISATION.stall_min_shrink_percent
    tag_budget_s: float | None = _LOCALISATION.tag_budget_s
    """The mission's localisation.stall_window_s, stall_min_shrink_percent, tag_budget_s
    (schema defaults), applied when ``finish`` is set."""
    estimator: str = "classic"
    """"classic": the filter trusts the radio model exactly (the paper's simulations);
    "robust": the mission defaults' radio unknowns (power offset and path-loss exponent per
    tag, the antenna's front-to-back ratio, shadowing and model-error hypotheses, outliers;
    docs/results/localisation.md)."""

    @property
    def label(self) -> str:
        """The preset as runs.csv and experiment.json name it: "paper", "field-quick"..."""
        return f"{self.preset}-quick" if self.quick else self.preset

    @property
    def truth_motion(self) -> str:
        return _MODEL_MOTION[self.model][0]

    @property
    def filter_motion(self) -> str:
        return _MODEL_MOTION[self.model][1]

    @property
    def tag_ids(self) -> tuple[str, ...]:
        return tuple(f"T{i + 1}" for i in range(self.n_tags))

    def area(self) -> SearchArea:
        h = self.area_half_m
        return SearchArea.rectangle(-h, h, -h, h)

    def initial_area(self) -> SearchArea:
        h = self.initial_half_m
        return SearchArea.rectangle(-h, h, -h, h)

    @property
    def steps(self) -> int:
        """Pulse periods simulated at most."""
        return round(self.duration_s / self.pulse_period_s)

    def describe(self) -> dict[str, Any]:
        """Plain settings for experiment.json and the docs."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def scenario(kind: ScenarioKind, model: ModelName, quick: bool = False,
             preset: PresetName = "paper", *, reality: str = "matched",
             estimator: str = "classic", finish: bool = False) -> Scenario:
    """The settings of a scenario, model and preset; ``quick`` shortens everything (smoke);
    ``reality`` the radio world's profile, ``estimator`` classic or robust; ``finish`` the
    mission's stall and budget rules (every tag reported in bounded time)."""
    if reality not in PROFILES:
        raise ConfigError(f"unknown reality {reality!r}; expected one of {', '.join(PROFILES)}")
    if estimator not in ESTIMATORS:
        raise ConfigError(f"unknown estimator {estimator!r}; expected one of "
                          f"{', '.join(ESTIMATORS)}")
    if model not in MODELS:
        raise ConfigError(f"unknown model {model!r}; expected one of {', '.join(MODELS)}")
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; expected one of {', '.join(PRESETS)}")
    if kind == "follow":
        sc = Scenario(kind="follow", model=model, preset=preset, n_tags=1, area_half_m=6000.0,
                      initial_half_m=2000.0, duration_s=600.0, min_inside_s=600.0,
                      lookahead_s=10.0, truth_speed_m_s=(5.0, 6.0))
    elif kind == "localise":
        sc = Scenario(kind="localise", model=model, preset=preset, n_tags=4,
                      area_half_m=2000.0, initial_half_m=500.0, duration_s=1000.0,
                      min_inside_s=650.0, lookahead_s=20.0, truth_speed_m_s=(2.5, 3.0))
    else:
        raise ConfigError(f"unknown scenario {kind!r}; expected follow or localise")
    sc = replace(sc, mismatch_accel_std_m_s2=round(mismatch_accel_std_m_s2(sc), 3))
    if preset == "field":
        mission = RadioModel()  # the mission defaults (config schema = core defaults)
        sc = replace(sc, front_back_db=mission.front_back_db,
                     sensitivity_db=mission.sensitivity_db,
                     detection_spread_db=mission.detection_spread_db, pd_max=mission.pd_max)
    sc = replace(sc, reality=reality, estimator=estimator, finish=finish)
    if quick:
        sc = replace(sc, quick=True, duration_s=40.0, min_inside_s=min(sc.min_inside_s, 40.0),
                     lookahead_s=5.0, filter_particles=400, planning_particles=200,
                     mexgen_samples=64, mc_rollouts=4)
    return sc


def weakest_power_db(sc: Scenario) -> float:
    """The weakest noiseless power (dB, antenna gain aside) from anywhere in the search area
    to anywhere in it: the area's diagonal at the flight altitude."""
    diagonal = math.hypot(2.0 * math.sqrt(2.0) * sc.area_half_m, sc.alt_m)
    r = RadioModel()
    return r.p0_db - 10.0 * r.path_loss_exponent * math.log10(diagonal / r.d0_m)


def mismatch_accel_std_m_s2(sc: Scenario) -> float:
    """Acceleration noise (per axis, m/s^2) of a CV filter that must follow CV-IFT turns.

    The truth turns at rate w (fastest: v, sharpest: w from the scenario's ranges), so while
    turning it accelerates by v w sideways, per axis (v w)^2 / 2 in mean square over the
    direction of travel. From the IMM's transition matrix (the paper's, per 1 s step): a turn
    persists for tau = 1 / (1 - 0.775) = 4.4 s on average, and the chain spends pi = 0.1 of
    the time turning (stationary distribution). The acceleration is thus a zero-mean process
    of variance pi (v w)^2 / 2 correlated over ~tau, whose velocity random walk grows as
    2 Var tau per second; a CV model's white acceleration noise sigma (per step dt) grows it
    by sigma^2 dt. Equal rates::

        sigma^2 = pi (v w)^2 tau / dt   (plus the truth's own acceleration noise squared)

    Localisation (3 m/s, 15 deg/s): 0.53 m/s^2; following (6 m/s): 1.05 m/s^2. (Covering a
    single mean turn's velocity change v w tau at 2 sigma instead, sigma = v w sqrt(tau) / 2,
    gives 0.83 m/s^2: a wider belief throughout, whose radius while circling the object
    (experiments.achievable) stayed above 50 m at 60-100 m circles.)
    """
    v = sc.truth_speed_m_s[1]
    w = math.radians(sc.truth_turn_rate_deg_s[1])
    p = PAPER_TRANSITION
    stay = p[1][1]
    dt = sc.pulse_period_s
    tau = dt / (1.0 - stay)
    leave_cv = p[0][1] + p[0][2]
    turning = leave_cv / (leave_cv + (1.0 - stay))  # stationary share of the two turn modes
    return math.sqrt(turning * (v * w) ** 2 * tau / dt + sc.truth_accel_std_m_s2**2)


def scenario_from_settings(settings: dict[str, Any]) -> Scenario:
    """The Scenario that ``Scenario.describe()`` (as stored in experiment.json) came from."""
    fields = Scenario.__dataclass_fields__
    unknown = sorted(set(settings) - set(fields))
    if unknown:
        raise ConfigError(f"unknown scenario settings {unknown}")
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in settings.items()}
    return Scenario(**values)  # type: ignore[arg-type]  # checked against the fields above


ORACLE_PREFIX = "oracle"
"""``oracle<R>`` orbits each tag at R m, ``oraclestar<R>`` flies passes over it out to R m
(a star); both know the truth (runner)."""
ORACLE_PATTERNS = ("star", "")
"""The oracle name's pattern word: "star" (passes), "" (orbit)."""


def oracle_pattern(method: str) -> str | None:
    """"orbit" or "star" for an oracle method name, None for a planner's."""
    if not method.startswith(ORACLE_PREFIX):
        return None
    oracle_orbit_m(method)  # validates
    return "star" if method.startswith(ORACLE_PREFIX + "star") else "orbit"


def oracle_orbit_m(method: str) -> float | None:
    """The radius (m) of an oracle method name: the orbit of ``oracle<R>`` (oracle60 -> 60.0)
    or the passes' reach of ``oraclestar<R>``; None for a planner's name."""
    if not method.startswith(ORACLE_PREFIX):
        return None
    text = method[len(ORACLE_PREFIX):]
    text = text.removeprefix("star")
    if not text.isdigit() or not 5 <= int(text) <= 1000:
        raise ConfigError(f"unknown method {method!r}: an oracle is oracle<R> (orbit) or "
                          "oraclestar<R> (passes) with R in whole metres, 5..1000 (e.g. "
                          "oracle60)")
    return float(text)


def method_config(method: str) -> tuple[str, str]:
    """(planner.method, table label) of an experiment method name (pim, mc8, mexgen, or
    oracle<R>, whose mission is MexGen's; its planner is not used)."""
    orbit = oracle_orbit_m(method)
    if orbit is not None:
        kind = "star" if oracle_pattern(method) == "star" else "orbit"
        return Method.MEXGEN.value, f"Oracle {kind} {orbit:.0f} m"
    try:
        return METHODS[method]
    except KeyError:
        raise ConfigError(
            f"unknown method {method!r}; expected one of {', '.join(METHODS)} or "
            "oracle<R>") from None


def method_label(method: str) -> str:
    """The table label of an experiment method name (MexGen, Oracle-60...)."""
    return method_config(method)[1]


def ordered_methods(names: Iterable[str]) -> list[str]:
    """The distinct method names given, in table order: METHODS' order, then the oracles by
    orbit radius."""
    present = set(names)
    oracles = sorted((m for m in present if oracle_orbit_m(m) is not None),
                     key=lambda m: (oracle_pattern(m) or "", oracle_orbit_m(m) or 0.0))
    return [m for m in METHODS if m in present] + oracles


def mission_yaml(sc: Scenario, method: str) -> str:
    """The mission one run flies, as mission-file YAML (validated by ``mission_for``)."""
    planner_method, _ = method_config(method)
    h = sc.area_half_m
    tags = [{"id": tid, "freq_hz": 150_100_000 + 120_000 * i} for i, tid in enumerate(sc.tag_ids)]
    speed_lo, speed_hi = sc.truth_speed_m_s
    doc: dict[str, Any] = {
        "version": 1,
        "name": f"experiment-{sc.kind}-{sc.model}",
        "kind": sc.kind,
        "home": {"lat_deg": -34.9212, "lon_deg": 138.6011, "alt_m": 0.0},
        "area": {"rectangle_m": {"west_m": -h, "east_m": h, "south_m": -h, "north_m": h}},
        "flight": {"alt_m": sc.alt_m, "speed_m_s": sc.speed_m_s,
                   "max_accel_m_s2": sc.max_accel_m_s2, "min_alt_m": sc.min_alt_m},
        "tags": tags,
        "radio": {"front_back_db": sc.front_back_db, "sensitivity_db": sc.sensitivity_db,
                  "detection_spread_db": sc.detection_spread_db, "pd_max": sc.pd_max},
        "receiver": {"pulse_period_s": sc.pulse_period_s},
        "filter": {
            "motion": sc.filter_motion,
            "rw_std_m_per_sqrt_s": sc.filter_rw_std_m_per_sqrt_s,
            "accel_std_m_s2": sc.filter_accel_std_m_s2,
            "mismatch_accel_std_m_s2": sc.mismatch_accel_std_m_s2,
            "turn_rate_deg_s": 0.5 * sum(sc.truth_turn_rate_deg_s),
            "speed_min_m_s": speed_lo,
            "speed_max_m_s": speed_hi,
            "n_particles": sc.filter_particles,
            "roughening_k": sc.filter_roughening_k,
        },
        "planner": {
            "method": planner_method,
            "samples": sc.mexgen_samples,
            "mc_rollouts": sc.mc_rollouts,
            "n_particles": sc.planning_particles,
            "replan_interval_s": sc.replan_interval_s,
            "lookahead_s": sc.lookahead_s,
            "target": "closest",
        },
        "localisation": {"radius_m": sc.localised_radius_m,
                         "confidence": sc.localised_confidence,
                         "stall_window_s": sc.stall_window_s if sc.finish else None,
                         "stall_min_shrink_percent": sc.stall_min_shrink_percent,
                         "tag_budget_s": sc.tag_budget_s if sc.finish else None},
        "safety": {"max_mission_time_s": max(sc.duration_s, 1.0)},
    }
    if sc.kind == "follow":
        doc["follow"] = {"tag": sc.tag_ids[0], "duration_s": sc.duration_s}
    if sc.estimator == "classic":
        for dotted, value in CLASSIC_ESTIMATOR.items():
            section, key = dotted.split(".")
            doc[section][key] = value
    elif sc.estimator not in ESTIMATORS:
        raise ConfigError(f"unknown estimator {sc.estimator!r}; expected classic or robust")
    return yaml.safe_dump(doc, sort_keys=False)


@lru_cache(maxsize=32)
def mission_for(sc: Scenario, method: str) -> Mission:
    """The validated mission of one (scenario, method), cached per process."""
    return parse_mission(mission_yaml(sc, method), source=f"<experiment {sc.kind} {sc.model} "
                         f"{method}>")
