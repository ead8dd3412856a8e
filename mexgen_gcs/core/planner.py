"""The rollout planner: choose the next heading by discounted Renyi information gain (paper
section 4, "Path planning", eq. reward_sum and eq. expected_reward).

Frame: local ENU metres about home (x east, y north, z up; tags on the ground at z = 0).
Headings are compass headings (0 = north, 90 deg = east, clockwise).

For each action (a heading held over the look-ahead, see :mod:`core.paths`) and each look-ahead
step k = 1..H (every ``step_s``, by default every tag pulse):

1. predict: propagate the particles with the tag's motion model. Tag motion does not depend on
   the action, so one propagation per step serves every action (and MC rollout);
2. measure: generate a measurement from the predicted belief with the configured generator
   (PIM, MexGen-M or MC-M, :mod:`core.generators`), for every row at once: a power z and the
   probability p that the pulse is detected at all;
3. update: weight the particles by the likelihood of that outcome (pD N(z; P, R) for a
   detection, 1 - pD for a miss, :mod:`core.likelihood`), the two weighed by p as
   ``outcome`` says (:mod:`core.rollout` has the equations);
4. reward: add ``discount^(k-1) * Renyi(updated, predicted)`` (:mod:`core.reward`).

With ``toward_target`` the action set gains one heading: straight at the first planned
belief's mean (a pass over the target's estimate, which the fixed headings only approximate
to within half their spacing); it is scored like every other action.

An action's value is the mean over its rollouts (MC-M: M rollouts; otherwise one) summed over
the planned tags, minus ``action_cost_weight * turn_cost`` (the turn from the current course,
in [0, 1], charged once). Actions whose path leaves the search area within the pruning horizon
are pruned (reward -inf, never chosen); if every action is pruned the heading nearest the
bearing to the area centre is returned with ``all_pruned`` set.

Reach (``reach``, on by default): a heading held for the 20 s look-ahead covers 300 m at
15 m/s, so for a tag 1.5-3 km away no action can get near it within the rollout and the
comparison is between what can be learnt from afar: at the edge of detection, and across the
bearing where the antenna's front-to-back ratio separates particles by bearing. Even the
exact expected information (MC-M with M large) then prefers flying sideways or away, and the
vehicle never closes in (issue 12). With ``reach`` the look-ahead is stretched, keeping its
number of steps (so the cost), to the time needed to fly to the nearest planned belief's mean
(``max_lookahead_s`` at most); within ``speed * lookahead_s`` of it nothing changes. The
pruning horizon stays ``prune_horizon_s`` (default: the configured look-ahead); beyond it a
stretched path that reaches the area's boundary is held there, as the vehicle would be.

Everything is vectorised over tags x actions x rollouts x particles as float32 arrays (T, A, R,
N) in :mod:`core.rollout`; the only Python loops are over look-ahead steps and, for the
prediction, over tags. Tags are stacked when they have the same particle count (the normal
case: the caller resamples every belief to ``planner.n_particles``); otherwise groups of equal
size are planned in turn. A :class:`Planner` keeps its working arrays between plans (use one
per planning thread); :func:`plan` is the one-off form.

Per-stage wall times (``time.perf_counter``; measuring only, the core reads no clock for its
decisions): predict = motion model; measure = the generator; update = the noiseless measurement
of every particle from every action's pose and its detection probability (a grid the
generators also read); reward = the weight update, the divergence and the discounting, which
are one compiled pass (:mod:`core.rollout_kernels`). Set-up (paths, pruning, buffers) is in
``total_s`` only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.generators import METHODS, MeasurementGenerator, Method, make_generator
from mexgen_gcs.core.likelihood import detection_table
from mexgen_gcs.core.motion import ModeArray, MotionModel
from mexgen_gcs.core.paths import (
    PRUNE_SUBSTEPS,
    action_headings_rad,
    compass_bearing_rad,
    fine_times_s,
    inside_test,
    leaves_area,
    vehicle_paths,
)
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import PulseNoise
from mexgen_gcs.core.reward import turn_cost
from mexgen_gcs.core.rollout import PlanningBelief, rollout_gains
from mexgen_gcs.core.workspace import Workspace
from mexgen_gcs.errors import ConfigError, PlannerError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

OutcomeRule = Literal["pooled", "branches"]

STAGES = ("predict", "measure", "update", "reward")
"""Keys of :attr:`PlanResult.timing_s`."""

_COURSE_MIN_SPEED_M_S = 0.5
"""Below this horizontal speed the current course is taken from the yaw."""


@dataclass(frozen=True, slots=True)
class PlannerConfig:
    """Planner settings; the mission's ``planner`` and ``flight`` sections map onto these."""

    method: Method | str = Method.MEXGEN
    """Measurement generator: "pim" | "mexgen" | "mc"."""
    samples: int = 512
    """MexGen M: measurement samples per action and step."""
    mc_rollouts: int = 8
    """MC-M: rollouts per action."""
    lookahead_s: float = 20.0
    """Look-ahead horizon (paper: 20 s to localise, 10 s to follow)."""
    step_s: float = 1.0
    """Time between simulated measurements (one tag pulse period)."""
    discount: float = 0.95
    """lambda in (0, 1]: weight of step k is lambda^(k-1)."""
    alpha: float = 0.1
    """Order of the Renyi divergence (> 0, != 1)."""
    n_headings: int = 8
    """Actions: this many compass headings from north (8: N, NE, ..., NW)."""
    speed_m_s: float = 10.0
    """Commanded horizontal speed of every action."""
    max_accel_m_s2: float = 4.0
    """Horizontal acceleration limit of the vehicle (paths start from its current velocity)."""
    action_cost_weight: float = 0.0
    """Weight of the turn cost |heading - course| / 180 deg subtracted from an action's value."""
    prune_horizon_s: float | None = None
    """An action is pruned if its path leaves the area within this time; None = the look-ahead."""
    mexgen_stratified: bool = True
    """MexGen draws its M samples stratified (faster, never noisier) or, if False,
    independently as in the paper's description (see generators.MexGen)."""
    outcome: OutcomeRule = "pooled"
    """How a step's uncertain detect/miss outcome enters the reward (core.rollout): "branches"
    = the two outcomes' rewards averaged with weights p, 1 - p; "pooled" = the reward of the
    expected outcome, likelihood (pD N)^p (1 - pD)^(1 - p). Identical when p is 0 or 1."""
    reach: bool = True
    """Stretch the look-ahead (same number of steps) until it reaches the nearest planned
    belief's mean at ``speed_m_s``, up to ``max_lookahead_s`` (see the module docstring)."""
    max_lookahead_s: float = 300.0
    """Longest stretched look-ahead."""
    toward_target: bool = False
    """Add one action: the heading straight at the first planned belief's mean (a close pass
    over the target's estimate), scored like the others by the same generator."""
    altitudes_m: tuple[float, ...] = ()
    """Altitudes (above home, m) the actions may fly at: every heading at each of them (the
    action set grows by that factor), the vehicle climbing or descending at
    ``climb_rate_m_s`` from where it is. Empty: every action holds the vehicle's altitude (the
    paper's actions)."""
    climb_rate_m_s: float = 2.0
    """Vertical speed of an altitude change in the rollout (the guidance's limit)."""

    def __post_init__(self) -> None:
        checks: list[tuple[str, bool, str]] = [
            ("method", self.method in METHODS, "one of " + ", ".join(METHODS)),
            ("samples", self.samples >= 1, ">= 1"),
            ("mc_rollouts", self.mc_rollouts >= 1, ">= 1"),
            ("step_s", self.step_s > 0.0, "> 0"),
            ("lookahead_s", self.lookahead_s >= self.step_s, ">= step_s"),
            ("discount", 0.0 < self.discount <= 1.0, "in (0, 1]"),
            ("alpha", self.alpha > 0.0 and self.alpha != 1.0, "> 0 and != 1"),
            ("n_headings", self.n_headings >= 1, ">= 1"),
            ("speed_m_s", self.speed_m_s > 0.0, "> 0"),
            ("max_accel_m_s2", self.max_accel_m_s2 > 0.0, "> 0"),
            ("action_cost_weight", self.action_cost_weight >= 0.0, ">= 0"),
            ("prune_horizon_s", self.prune_horizon_s is None or self.prune_horizon_s > 0.0,
             "> 0 or null"),
            ("outcome", self.outcome in ("pooled", "branches"), "pooled or branches"),
            ("max_lookahead_s", self.max_lookahead_s >= self.lookahead_s, ">= lookahead_s"),
            ("altitudes_m", all(math.isfinite(a) and a > 0.0 for a in self.altitudes_m),
             "a list of altitudes > 0"),
            ("climb_rate_m_s", self.climb_rate_m_s > 0.0, "> 0"),
        ]
        for name, ok, need in checks:
            if not ok:
                raise ConfigError(f"planner.{name} must be {need} (got {getattr(self, name)!r})")

    @property
    def steps(self) -> int:
        """H, the number of look-ahead steps."""
        return max(1, round(self.lookahead_s / self.step_s))

    def generator(self) -> MeasurementGenerator:
        return make_generator(self.method, self.samples, self.mc_rollouts,
                              self.mexgen_stratified)


@dataclass(frozen=True, slots=True, eq=False)
class TagBelief:
    """The planning belief of one tag: N equal-weight particles (resampled by the caller).

    Any object with these attributes will do (:class:`core.rollout.PlanningBelief`).
    """

    tag_id: str
    states: FloatArray
    """(N, 4) [x_east_m, y_north_m, vx_m_s, vy_m_s]."""
    modes: ModeArray
    """(N,) int8 motion-model modes (0 for single-mode models)."""
    motion: MotionModel
    """The motion model the tag's filter assumes."""
    existence: float = 1.0
    """The filter's existence probability (not used by the planner; carried for the log)."""
    offset_db: FloatArray | None = None
    """(N,) each particle's received-power offset about the model's P0 (None: 0)."""
    exponent: FloatArray | None = None
    """(N,) each particle's path-loss exponent (None: the model's)."""
    noise: PulseNoise | None = None
    """What another pulse would tell, by receiver position (None: the receiver noise)."""
    radio_cov: FloatArray | None = None
    """(3,) ``[bb, bn, nn]``: the uncertainty of the offsets and exponents (None: none), added
    to each pulse's noise at the belief's mean position."""


class PlanningVehicle(Protocol):
    """What the planner reads of the vehicle state."""

    @property
    def xyz_m(self) -> FloatArray: ...
    @property
    def v_xy_m_s(self) -> FloatArray: ...
    @property
    def yaw_rad(self) -> float: ...


@dataclass(frozen=True, slots=True)
class VehicleState:
    """Where the vehicle is now (any object with these attributes will do)."""

    xyz_m: FloatArray
    """(3,) east, north, up (up = height above the home ground, where the tags are)."""
    v_xy_m_s: FloatArray
    """(2,) horizontal velocity east, north."""
    yaw_rad: float
    """Compass heading of the airframe (0 = north, clockwise)."""


@dataclass(frozen=True, slots=True, eq=False)
class PlanResult:
    """An immutable planning decision (the flight log's form is `io.plans.plan_record`)."""

    method: str
    target_ids: tuple[str, ...]
    headings_deg: FloatArray
    """(A,) compass headings of the actions."""
    rewards: FloatArray
    """(A,) expected discounted reward; -inf for pruned actions."""
    pruned: BoolArray
    """(A,) True where the action's path leaves the search area."""
    chosen: int
    """Index of the chosen action."""
    heading_deg: float
    """headings_deg[chosen]."""
    all_pruned: bool
    """Every action was pruned: the chosen heading points (nearest) towards the area centre."""
    timing_s: Mapping[str, float]
    """Wall time per stage (predict, measure, update, reward), seconds."""
    total_s: float
    """Wall time of the whole call, seconds."""
    paths_m: FloatArray
    """(A, H, 2) planned horizontal positions of each action at each look-ahead step."""
    lookahead_s: float = 0.0
    """The look-ahead used (stretched to reach a far belief when ``reach`` is set)."""
    alts_m: FloatArray | None = None
    """(A,) the altitude each action flies to (None: the actions hold the altitude)."""

    @property
    def alt_m(self) -> float | None:
        """The chosen action's altitude above home, m (None: hold the mission's altitude)."""
        return None if self.alts_m is None else float(self.alts_m[self.chosen])


class Planner:
    """Chooses headings for one mission: the settings, radio model and search area, plus a
    workspace reused between plans (so planning allocates almost nothing per call).

    Not thread-safe: use one Planner per planning thread.
    """

    def __init__(self, config: PlannerConfig, radio: RadioModel, area: SearchArea) -> None:
        self.config = config
        self.radio = radio
        self.area = area
        self.generator: MeasurementGenerator = config.generator()
        self.headings_rad = action_headings_rad(config.n_headings)
        self._table = detection_table(radio)
        self._inside = inside_test(area)
        self._workspace = Workspace()

    def plan(
        self,
        beliefs: Sequence[PlanningBelief],
        vehicle: PlanningVehicle,
        rng: np.random.Generator,
    ) -> PlanResult:
        """Choose the next heading for the given tags: one tag for the "closest" target rule,
        several for "all" (their rewards are summed). Raises PlannerError on bad input.
        Cost O(H T A R N) array work (see the module docstring).
        """
        t_start = time.perf_counter()
        cfg = self.config
        _check_beliefs(beliefs)
        xyz, v_xy, yaw_rad = _check_vehicle(vehicle)
        headings = self.headings_rad
        if cfg.toward_target:
            mean_xy = np.asarray(beliefs[0].states)[:, :2].mean(axis=0)
            headings = np.append(headings, compass_bearing_rad(xyz, mean_xy))
        alts: FloatArray | None = None
        if cfg.altitudes_m:
            alts = np.repeat(np.asarray(cfg.altitudes_m, dtype=np.float64), headings.size)
            headings = np.tile(headings, len(cfg.altitudes_m))
        horizon = cfg.prune_horizon_s if cfg.prune_horizon_s is not None else cfg.lookahead_s
        times = fine_times_s(max(horizon, cfg.steps * cfg.step_s), cfg.step_s)
        fine = vehicle_paths(xyz, v_xy, headings, cfg.speed_m_s, cfg.max_accel_m_s2, times)
        paths = fine[PRUNE_SUBSTEPS - 1 :: PRUNE_SUBSTEPS][: cfg.steps]  # (H, A, 2) at the steps
        pruned = leaves_area(self._inside, fine[times <= horizon + 1e-9])
        step_s = cfg.step_s
        lookahead_s = reach_lookahead_s(cfg, beliefs, xyz) if cfg.reach else cfg.lookahead_s
        if lookahead_s > cfg.steps * cfg.step_s + 1e-9:
            step_s = lookahead_s / cfg.steps
            paths = _held_inside(self._inside, xyz, vehicle_paths(
                xyz, v_xy, headings, cfg.speed_m_s, cfg.max_accel_m_s2,
                step_s * np.arange(1.0, cfg.steps + 1.0)))
        timing = dict.fromkeys(STAGES, 0.0)
        rewards = np.full(headings.shape, -np.inf)
        all_pruned = bool(pruned.all())
        if all_pruned:
            to_centre = compass_bearing_rad(xyz, self.area.centre_m)
            off = np.abs((headings - to_centre + math.pi) % (2.0 * math.pi) - math.pi)
            chosen = int(np.argmin(off))
        else:
            active = np.flatnonzero(~pruned)
            gains = np.zeros(active.size)
            alt_rows: float | FloatArray = float(xyz[2])
            if alts is not None:
                alt_rows = altitude_paths_m(float(xyz[2]), alts[active], cfg.climb_rate_m_s,
                                            step_s * np.arange(1.0, paths.shape[0] + 1.0))
            for group in _groups_of_equal_size(beliefs):
                per_tag = rollout_gains(
                    group, paths[:, active], alt_rows, headings[active], self.radio,
                    self._table, self.generator, step_s, cfg.discount, cfg.alpha, rng,
                    timing, self._workspace, pooled=cfg.outcome == "pooled",
                )
                gains += per_tag.sum(axis=0)
            if cfg.action_cost_weight > 0.0:
                course = _course_rad(v_xy, yaw_rad)
                gains -= cfg.action_cost_weight * turn_cost(headings[active], course)
            if not np.all(np.isfinite(gains)):
                raise PlannerError(f"planner produced non-finite rewards {gains.tolist()}")
            rewards[active] = gains
            chosen = int(active[np.argmax(gains)])
        headings_deg = np.degrees(headings)
        return PlanResult(
            method=cfg.method,
            target_ids=tuple(str(b.tag_id) for b in beliefs),
            headings_deg=_frozen(headings_deg),
            rewards=_frozen(rewards),
            pruned=_frozen(pruned),
            chosen=chosen,
            heading_deg=float(headings_deg[chosen]),
            all_pruned=all_pruned,
            timing_s=MappingProxyType(timing),
            total_s=time.perf_counter() - t_start,
            paths_m=_frozen(np.ascontiguousarray(paths.transpose(1, 0, 2))),
            lookahead_s=step_s * cfg.steps,
            alts_m=None if alts is None else _frozen(alts),
        )


def altitude_paths_m(alt_m: float, targets_m: FloatArray, climb_rate_m_s: float,
                     times_s: FloatArray) -> FloatArray:
    """(H, A) altitudes at ``times_s`` (H,) of a vehicle at ``alt_m`` climbing or descending
    at ``climb_rate_m_s`` to each action's altitude ``targets_m`` (A,), then holding it."""
    gap = np.asarray(targets_m, dtype=np.float64)[None, :] - alt_m
    reach = climb_rate_m_s * np.asarray(times_s, dtype=np.float64)[:, None]
    return alt_m + np.sign(gap) * np.minimum(np.abs(gap), reach)


def plan(
    beliefs: Sequence[PlanningBelief],
    vehicle: PlanningVehicle,
    area: SearchArea,
    radio: RadioModel,
    config: PlannerConfig,
    rng: np.random.Generator,
) -> PlanResult:
    """One-off :meth:`Planner.plan` (allocates a fresh workspace; a mission keeps a Planner)."""
    return Planner(config, radio, area).plan(beliefs, vehicle, rng)


def reach_lookahead_s(
    config: PlannerConfig, beliefs: Sequence[PlanningBelief], vehicle_xyz_m: FloatArray
) -> float:
    """The look-ahead that reaches the nearest belief: distance from the vehicle to the nearest
    planned belief's mean position over ``speed_m_s``, clipped to [lookahead_s,
    max_lookahead_s]. O(T N)."""
    xy = np.asarray(vehicle_xyz_m, dtype=np.float64)[:2]
    dist = min(float(np.linalg.norm(np.asarray(b.states)[:, :2].mean(axis=0) - xy))
               for b in beliefs)
    return min(max(config.lookahead_s, dist / config.speed_m_s), config.max_lookahead_s)


def _held_inside(
    inside: Callable[[FloatArray], BoolArray], xyz: FloatArray, paths: FloatArray
) -> FloatArray:
    """Stretched paths (H, A, 2) held at their last point inside the area from the first one
    outside on (the vehicle is kept in the area; it does not fly on beyond the boundary). An
    action whose first point is already outside holds the vehicle's position. O(H A)."""
    ext = np.concatenate([np.broadcast_to(xyz[:2], (1, *paths.shape[1:])), paths])
    kept = np.logical_and.accumulate(np.concatenate(
        [np.ones((1, paths.shape[1]), dtype=bool), inside(paths)]), axis=0)
    last = np.cumsum(kept, axis=0)[1:] - 1  # index into ext of the last kept point, (H, A)
    return np.take_along_axis(ext, last[..., None], axis=0)


def _check_beliefs(beliefs: Sequence[PlanningBelief]) -> None:
    if len(beliefs) == 0:
        raise PlannerError("no tag beliefs to plan for: pass at least one tag's belief")
    for b in beliefs:
        s, m = np.asarray(b.states), np.asarray(b.modes)
        if s.ndim != 2 or s.shape[1] != 4:
            raise PlannerError(
                f"tag {b.tag_id}: planning belief states must be (N, 4), got {s.shape}"
            )
        if s.shape[0] == 0:
            raise PlannerError(
                f"tag {b.tag_id}: planning belief has no particles; resample N >= 1 "
                "particles from the filter before planning"
            )
        if m.shape != (s.shape[0],):
            raise PlannerError(f"tag {b.tag_id}: modes must be ({s.shape[0]},), got {m.shape}")
        if not np.all(np.isfinite(s)):
            raise PlannerError(f"tag {b.tag_id}: planning belief has non-finite states")


def _check_vehicle(vehicle: PlanningVehicle) -> tuple[FloatArray, FloatArray, float]:
    xyz = np.asarray(vehicle.xyz_m, dtype=np.float64).reshape(-1)
    v_xy = np.asarray(vehicle.v_xy_m_s, dtype=np.float64).reshape(-1)
    yaw = float(vehicle.yaw_rad)
    if xyz.shape != (3,) or v_xy.shape != (2,):
        raise PlannerError(
            f"vehicle position must be (3,) and velocity (2,), got {xyz.shape}, {v_xy.shape}"
        )
    if not (np.all(np.isfinite(xyz)) and np.all(np.isfinite(v_xy)) and math.isfinite(yaw)):
        raise PlannerError("vehicle state is not finite")
    return xyz, v_xy, yaw


def _course_rad(v_xy: FloatArray, yaw_rad: float) -> float:
    """Compass course over ground, or the yaw when (nearly) hovering."""
    if math.hypot(v_xy[0], v_xy[1]) >= _COURSE_MIN_SPEED_M_S:
        return math.atan2(v_xy[0], v_xy[1]) % (2.0 * math.pi)
    return yaw_rad % (2.0 * math.pi)


def _groups_of_equal_size(beliefs: Sequence[PlanningBelief]) -> list[list[PlanningBelief]]:
    groups: dict[int, list[PlanningBelief]] = {}
    for b in beliefs:
        groups.setdefault(int(np.shape(b.states)[0]), []).append(b)
    return list(groups.values())


def _frozen(a: NDArray[Any]) -> NDArray[Any]:
    a = np.array(a)
    a.flags.writeable = False
    return a
