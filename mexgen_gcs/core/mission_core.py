"""MissionCore: the decision logic of a mission, one synchronous object shared by the flight
path (mission controller) and the experiment runner, so what is measured is what flies.

Frame: local ENU metres about home; yaw is a compass heading in radians.

It owns one Bernoulli filter per tag, buffers detections, runs the filter cadence once per
pulse period (detections, or a missed detection when the receiver was listening for the tag),
keeps the localisation bookkeeping (a tag localised once stays localised and is not targeted
again, as in the paper), chooses the planning target, and prepares planning requests: pure
arrays that a worker thread can plan on while the filters keep updating.

An optional second, tighter radius (``tight_radius_m``, used by the experiments) is booked the
same way: when each tag's radius first drops to it. It changes no decision until every tag is
localised at the mission's radius; after that the target rule runs on the tags not yet
within the tight radius (a flight leaves it unset and is done at that point).

Reporting (``report_rule``, :class:`ReportRule`): every tag is *reported* in bounded time, with
the reason. A tag is reported as ``reached`` when it is localised; ``stalled`` when, over the
last ``stall_window_s`` seconds in which it was the planning target, its 95 % radius shrank by
less than ``stall_min_shrink`` (a fraction); ``budget`` when it has been the planning target for
``tag_budget_s`` seconds in all. A reported tag is not targeted again (the planner moves on to
the others) and its estimate goes on updating from every pulse, but the report stands: a
stalled tag that later drops under the radius is not reported again. With no rule (or both
parts off), a tag is reported exactly when it is localised, as before. "Worked on" time is
booked per pulse to the tags the target rule picks at that pulse (the closest pending tag by
estimate, or all pending tags), so time flying to a far tag counts against it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import BernoulliFilter, FilterConfig, TagEstimate
from mexgen_gcs.core.motion import MotionModel
from mexgen_gcs.core.planner import TagBelief, VehicleState
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import TagRadioPrior

FloatArray = NDArray[np.float64]
MissionKind = Literal["localise", "follow"]
TargetRule = Literal["closest", "all"]
ReportReason = Literal["reached", "stalled", "budget"]
REPORT_REASONS: tuple[ReportReason, ...] = ("reached", "stalled", "budget")


@dataclass(frozen=True, slots=True)
class ReportRule:
    """When a tag that has not reached the radius is reported anyway (module docstring)."""

    stall_window_s: float | None = None
    """Window of worked-on time over which the radius must shrink; None: no stall rule."""
    stall_min_shrink: float = 0.1
    """Least relative shrink of the radius over the window, in [0, 1)."""
    tag_budget_s: float | None = None
    """Worked-on time after which a tag is reported whatever its radius; None: no budget."""

    def __post_init__(self) -> None:
        if self.stall_window_s is not None and not self.stall_window_s > 0.0:
            raise ValueError(f"stall_window_s must be > 0 or None (got {self.stall_window_s})")
        if not 0.0 <= self.stall_min_shrink < 1.0:
            raise ValueError(f"stall_min_shrink must be in [0, 1) (got {self.stall_min_shrink})")
        if self.tag_budget_s is not None and not self.tag_budget_s > 0.0:
            raise ValueError(f"tag_budget_s must be > 0 or None (got {self.tag_budget_s})")

    @property
    def active(self) -> bool:
        return self.stall_window_s is not None or self.tag_budget_s is not None


@dataclass(frozen=True, slots=True)
class Localised:
    """The moment a tag first met the localisation criterion."""

    tag_id: str
    t: float
    estimate: TagEstimate


@dataclass(frozen=True, slots=True)
class Reported:
    """The moment a tag was reported, why, and how long it had been worked on."""

    tag_id: str
    t: float
    estimate: TagEstimate
    reason: ReportReason
    worked_s: float


@dataclass(frozen=True, slots=True)
class PulseReport:
    """What one pulse period's filter cadence did."""

    t: float
    estimates: dict[str, TagEstimate]
    updated: dict[str, str]
    """tag -> 'detection' | 'missed' | 'predict-only'."""
    newly_localised: tuple[Localised, ...]
    newly_tight: tuple[Localised, ...] = ()
    """Tags whose radius first dropped to the tight radius this pulse (if one is set)."""
    newly_reported: tuple[Reported, ...] = ()
    """Tags reported this pulse (reached, stalled or budget)."""


@dataclass(frozen=True, slots=True)
class PlanRequest:
    """Everything the planner needs, detached from the filters (safe to use off-thread)."""

    t: float
    vehicle: VehicleState
    beliefs: tuple[TagBelief, ...]


@dataclass
class _Buffered:
    """One pulse period's detections of a tag, grouped by receiver pose: one group per
    distinct pose (a pulse), each updating the filter at its own pose."""

    groups: list[tuple[FloatArray, float, list[float]]] = field(default_factory=list)

    def add(self, z_db: float, rx_xyz: FloatArray, rx_yaw_rad: float) -> None:
        for xyz, yaw, zs in self.groups:
            if yaw == rx_yaw_rad and np.array_equal(xyz, rx_xyz):
                zs.append(z_db)
                return
        self.groups.append((np.array(rx_xyz, dtype=np.float64), rx_yaw_rad, [z_db]))


class MissionCore:
    """Per-tag filters, cadence, targets and localisation bookkeeping for one mission."""

    def __init__(
        self,
        tag_ids: Sequence[str],
        motion: MotionModel,
        radio: RadioModel,
        area: SearchArea,
        filter_config: FilterConfig,
        rng: np.random.Generator,
        *,
        kind: MissionKind = "localise",
        target_rule: TargetRule = "closest",
        follow_tag: str | None = None,
        planning_particles: int = 1000,
        t0: float = 0.0,
        tag_priors: Mapping[str, TagRadioPrior] | None = None,
        tight_radius_m: float | None = None,
        report_rule: ReportRule | None = None,
    ) -> None:
        if not tag_ids:
            raise ValueError("a mission needs at least one tag")
        if kind == "follow" and follow_tag not in tag_ids:
            raise ValueError(f"follow tag {follow_tag!r} is not one of the mission's tags")
        self.tag_ids = tuple(tag_ids)
        self.motion = motion
        self.radio = radio
        self.area = area
        self.kind: MissionKind = kind
        self.target_rule: TargetRule = target_rule
        self.follow_tag = follow_tag
        self.planning_particles = planning_particles
        self.rng = rng
        # one child generator per tag: adding a tag does not change the others' draws
        children = rng.spawn(len(self.tag_ids))
        self.filters = {
            tid: BernoulliFilter(motion, radio, area, filter_config, child,
                                 (tag_priors or {}).get(tid))
            for tid, child in zip(self.tag_ids, children, strict=True)
        }
        self.localised: dict[str, Localised] = {}
        self.tight_radius_m = tight_radius_m
        self.tight: dict[str, Localised] = {}
        """Tags whose radius has dropped to ``tight_radius_m`` (the first time)."""
        self.report_rule = report_rule or ReportRule()
        self.reported: dict[str, Reported] = {}
        """Tags reported (first time): reached, stalled or budget."""
        self.worked_s = dict.fromkeys(self.tag_ids, 0.0)
        """Seconds each tag has been the planning target (booked per pulse)."""
        self.radius_log: dict[str, list[tuple[float, float]]] = {t: [] for t in self.tag_ids}
        """(t, 95 % radius) of every tag at every pulse: the radius over time."""
        self._worked_log: dict[str, list[tuple[float, float]]] = {t: [] for t in self.tag_ids}
        self.detections = dict.fromkeys(self.tag_ids, 0)
        self.last_rssi_db: dict[str, float] = {}
        self._buffer = {tid: _Buffered() for tid in self.tag_ids}
        self._last_t = t0
        self._last_estimates: dict[str, TagEstimate] = {}

    def reset_clock(self, t: float) -> None:
        """Start the cadence at t (e.g. when airborne): the first predict spans from here."""
        self._last_t = t
        self._buffer = {tid: _Buffered() for tid in self.tag_ids}

    # -- ingest ------------------------------------------------------------------------------

    def add_detection(
        self, tag_id: str, rssi_db: float, rx_xyz: FloatArray, rx_yaw_rad: float
    ) -> None:
        """Buffer one detection for the current pulse period at the receiver pose of its own
        pulse; detections at one pose (one pulse) update together, each pose separately."""
        if tag_id not in self._buffer:
            raise KeyError(f"unknown tag {tag_id!r}")
        if not (math.isfinite(rssi_db) and np.all(np.isfinite(rx_xyz))):
            raise ValueError("detection needs a finite rssi and receiver position")
        self._buffer[tag_id].add(float(rssi_db), np.asarray(rx_xyz, dtype=np.float64),
                                 float(rx_yaw_rad))
        self.detections[tag_id] += 1
        self.last_rssi_db[tag_id] = float(rssi_db)

    def pulse(
        self,
        t: float,
        rx_xyz: FloatArray,
        rx_yaw_rad: float,
        listening: Iterable[str] | None,
    ) -> PulseReport:
        """Run one pulse period's cadence at time t for every tag.

        ``listening``: the tags the receiver reported listening for while its heartbeat was
        fresh; a listened-for tag with no detection gets a missed-detection update. ``None``
        means the radio is not known to be alive: filters only predict (silence is not
        evidence when nobody was listening).
        """
        dt = max(t - self._last_t, 0.0)
        self._last_t = t
        heard = set(listening) if listening is not None else set()
        updated: dict[str, str] = {}
        estimates: dict[str, TagEstimate] = {}
        newly: list[Localised] = []
        newly_tight: list[Localised] = []
        newly_reported: list[Reported] = []
        if self.kind == "localise":
            # the tags worked on during the period just flown: the target rule's pick from the
            # estimates before this pulse's update
            for tid in self._pending_targets(np.asarray(rx_xyz, dtype=np.float64)[:2]):
                if not self._worked_log[tid] and tid in self._last_estimates:
                    # the radius when work on it began
                    self._worked_log[tid].append((0.0, self._last_estimates[tid].radius_m))
                self.worked_s[tid] += dt
        for tid, f in self.filters.items():
            f.predict(dt)
            buf = self._buffer[tid]
            if buf.groups:
                for xyz, yaw, zs in buf.groups:
                    f.update(np.asarray(zs), xyz, yaw)
                updated[tid] = "detection"
            elif listening is not None and tid in heard:
                f.update(np.empty(0), np.asarray(rx_xyz, dtype=np.float64), rx_yaw_rad)
                updated[tid] = "missed"
            else:
                updated[tid] = "predict-only"
            self._buffer[tid] = _Buffered()
            est = f.estimate()
            estimates[tid] = est
            self.radius_log[tid].append((t, est.radius_m))
            if est.localised and tid not in self.localised and tid not in self.reported:
                rec = Localised(tid, t, est)
                self.localised[tid] = rec
                newly.append(rec)
            if self.kind == "localise" and tid not in self.reported:
                reason = "reached" if tid in self.localised else self._report_reason(tid, est)
                if reason is not None:
                    self.reported[tid] = Reported(tid, t, est, reason, self.worked_s[tid])
                    newly_reported.append(self.reported[tid])
            if (self.tight_radius_m is not None and tid not in self.tight
                    and est.radius_m <= self.tight_radius_m
                    and est.existence >= f.config.localised_min_existence):
                self.tight[tid] = Localised(tid, t, est)
                newly_tight.append(self.tight[tid])
        self._last_estimates = estimates
        return PulseReport(t, estimates, updated, tuple(newly), tuple(newly_tight),
                           tuple(newly_reported))

    def _report_reason(self, tag_id: str, est: TagEstimate) -> ReportReason | None:
        """Stall or budget for a tag not yet reported (None: keep working on it). The worked
        log keeps (worked_s, radius) at each pulse the tag was worked on."""
        rule = self.report_rule
        worked = self.worked_s[tag_id]
        log = self._worked_log[tag_id]
        if not log or log[-1][0] < worked:
            log.append((worked, est.radius_m))
        if rule.tag_budget_s is not None and worked >= rule.tag_budget_s - 1e-9:
            return "budget"
        w = rule.stall_window_s
        if w is not None and worked >= w - 1e-9:
            # the radius at the latest sample at least the window before now
            then = next(r for ws, r in reversed(log) if ws <= worked - w + 1e-9) \
                if log[0][0] <= worked - w + 1e-9 else None
            if then is not None and est.radius_m > (1.0 - rule.stall_min_shrink) * then:
                return "stalled"
        return None

    def _pending_targets(self, xy: FloatArray) -> tuple[str, ...]:
        """The target rule on the tags not yet reported, from the latest estimates."""
        pending = [tid for tid in self.tag_ids if tid not in self.reported]
        if self.target_rule == "all" or len(pending) <= 1:
            return tuple(pending)
        ests = self._last_estimates
        dists = [float(np.linalg.norm((ests[t] if t in ests else self.filters[t].estimate())
                                      .mean[:2] - xy)) for t in pending]
        return (pending[int(np.argmin(dists))],)

    # -- decisions ---------------------------------------------------------------------------

    def estimates(self) -> dict[str, TagEstimate]:
        return {tid: f.estimate() for tid, f in self.filters.items()}

    def targets(self, vehicle_xy: FloatArray) -> tuple[str, ...]:
        """The tags to plan for: the follow tag; or the closest (by estimate) tag not yet
        reported; or all tags not yet reported; once all are, the same on the tags not yet
        within the tight radius, if one is set. Empty when there is nothing left to do."""
        if self.kind == "follow":
            assert self.follow_tag is not None
            return (self.follow_tag,)
        pending = [tid for tid in self.tag_ids if tid not in self.reported]
        if not pending and self.tight_radius_m is not None:
            pending = [tid for tid in self.tag_ids if tid not in self.tight]
        if self.target_rule == "all" or not pending:
            return tuple(pending)
        xy = np.asarray(vehicle_xy, dtype=np.float64)[:2]
        dists = [float(np.linalg.norm(self.filters[t].estimate().mean[:2] - xy)) for t in pending]
        return (pending[int(np.argmin(dists))],)

    def plan_request(self, t: float, vehicle: VehicleState) -> PlanRequest | None:
        """Detach the target beliefs for planning; None when there is no target."""
        targets = self.targets(vehicle.xyz_m[:2])
        if not targets:
            return None
        beliefs = []
        for tid in targets:
            f = self.filters[tid]
            states, modes, offset, exponent, cov = f.sample_planning(self.planning_particles,
                                                                     self.rng)
            beliefs.append(TagBelief(tid, states, modes, self.motion, float(f.existence),
                                     offset, exponent, f.planning_noise(), cov))
        return PlanRequest(t, vehicle, tuple(beliefs))

    def all_localised(self) -> bool:
        return len(self.localised) == len(self.tag_ids)

    def all_reported(self) -> bool:
        """Every tag is reported (reached, stalled or budget): a localise mission is done."""
        return len(self.reported) == len(self.tag_ids)

    def all_tight(self) -> bool:
        """Every tag's radius has dropped to the tight radius (False if none is set)."""
        return self.tight_radius_m is not None and len(self.tight) == len(self.tag_ids)

    def particle_cloud(self, tag_id: str, k: int = 200) -> FloatArray:
        """A down-sampled (k, 2) position cloud of one tag for logs and the UI.

        Deterministic (systematic positions with offset 1/2), so logging never consumes the
        mission's random stream and a logged run decides exactly as an unlogged one."""
        f = self.filters[tag_id]
        w = np.exp(f.log_w - f.log_w.max())
        cdf = np.cumsum(w)
        idx = np.searchsorted(cdf / cdf[-1], (0.5 + np.arange(k)) / k, side="right")
        return f.states[np.minimum(idx, len(w) - 1), :2]
