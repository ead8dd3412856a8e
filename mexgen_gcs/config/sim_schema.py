"""Schema of the mission file's `sim` section: simulated truth and injected faults.

Read only by the simulator (python -m sim / mexgen-gcs sitl). Frame: `position_m` is local ENU
metres about home (x east, y north); `heading_deg` is a compass heading (0 = north, clockwise).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from mexgen_gcs.config.schema import (
    Float,
    Int,
    KeyPath,
    Section,
    TagId,
    check_rules,
)

TruthMotion = Literal["static", "rw", "cv", "ctra", "cv-ift"]


def _range_pair(value: Any) -> Any:
    """Accept a single number x as the degenerate range (x, x)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (value, value)
    return value


class SimTag(Section):
    """Simulated ground truth of one tag (simulator only)."""

    id: TagId = Field(description="Id of a mission tag.")
    position_m: tuple[Float, Float] | None = Field(
        None, description="Start [east_m, north_m] about home; omitted = uniform random in the "
        "area (by sim.seed).",
    )
    motion: TruthMotion = Field("static", description="Truth motion: static, rw, cv, ctra, cv-ift.")
    speed_m_s: tuple[Float, Float] = Field(
        (2.5, 3.0), description="Initial speed, m/s: a number or a [min, max] range drawn "
        "uniformly (cv, ctra, cv-ift).",
    )
    heading_deg: Float | None = Field(
        None, ge=0.0, lt=360.0,
        description="Initial compass heading, degrees; omitted = uniform random.",
    )
    turn_rate_deg_s: tuple[Float, Float] = Field(
        (10.0, 15.0), description="Turn rate of ctra/cv-ift turns, deg/s: a number or a "
        "[min, max] range drawn uniformly.",
    )
    accel_std_m_s2: Float = Field(0.1, ge=0.0, le=50.0,
                                  description="Acceleration noise of cv/ctra/cv-ift, m/s^2.")
    rw_std_m_per_sqrt_s: Float = Field(0.5, ge=0.0, le=100.0,
                                       description="Random-walk noise for rw, m/sqrt(s).")

    @field_validator("speed_m_s", "turn_rate_deg_s", mode="before")
    @classmethod
    def _pairs(cls, value: Any) -> Any:
        return _range_pair(value)

    @model_validator(mode="after")
    def _ranges(self) -> SimTag:
        issues: list[tuple[KeyPath, str]] = []
        for name, hi in (("speed_m_s", 100.0), ("turn_rate_deg_s", 180.0)):
            lo_v, hi_v = getattr(self, name)
            if not 0.0 <= lo_v <= hi_v <= hi:
                issues.append(((name,), f"expected a number or [min, max] with "
                                        f"0 <= min <= max <= {hi:g}; found [{lo_v:g}, {hi_v:g}]"))
        check_rules(issues)
        return self


class _Fault(Section):
    at_s: Float = Field(ge=0.0, le=86_400.0, description="Simulated time the fault starts, s.")


class LinkDrop(_Fault):
    """The MAVLink link goes silent."""

    kind: Literal["link_drop"] = Field(description="Fault kind.")
    duration_s: Float = Field(gt=0.0, le=86_400.0, description="How long, seconds.")


class GpsLoss(_Fault):
    """The vehicle loses its position fix."""

    kind: Literal["gps_loss"] = Field(description="Fault kind.")
    duration_s: Float = Field(gt=0.0, le=86_400.0, description="How long, seconds.")


class BatterySag(_Fault):
    """The battery level drops at once."""

    kind: Literal["battery_sag"] = Field(description="Fault kind.")
    percent: Float = Field(gt=0.0, le=100.0, description="Percentage points lost.")


class RadioSilence(_Fault):
    """The receiver sends nothing, not even heartbeats."""

    kind: Literal["radio_silence"] = Field(description="Fault kind.")
    duration_s: Float = Field(gt=0.0, le=86_400.0, description="How long, seconds.")


class DetectionDropout(_Fault):
    """Pulses that would be detected are dropped with a probability."""

    kind: Literal["detection_dropout"] = Field(description="Fault kind.")
    duration_s: Float = Field(gt=0.0, le=86_400.0, description="How long, seconds.")
    probability: Float = Field(ge=0.0, le=1.0, description="Probability a detection is dropped.")


class Clutter(_Fault):
    """Extra spurious detections."""

    kind: Literal["clutter"] = Field(description="Fault kind.")
    duration_s: Float = Field(gt=0.0, le=86_400.0, description="How long, seconds.")
    rate_per_s: Float = Field(ge=0.0, le=1000.0, description="Spurious detections per second.")


class ClockOffset(_Fault):
    """The receiver's clock jumps."""

    kind: Literal["clock_offset"] = Field(description="Fault kind.")
    offset_s: Float = Field(ge=-86_400.0, le=86_400.0, description="Clock offset added, seconds.")


class ClockDrift(_Fault):
    """The receiver's clock runs fast or slow."""

    kind: Literal["clock_drift"] = Field(description="Fault kind.")
    ppm: Float = Field(ge=-100_000.0, le=100_000.0,
                       description="Receiver clock rate error from at_s on, parts per million "
                       "(positive: fast).")


class PilotTakeover(_Fault):
    """A pilot takes over with the RC transmitter: a mode switch at `at_s`, LAND later."""

    kind: Literal["pilot_takeover"] = Field(description="Fault kind.")
    mode: Literal["POSCTL", "ALTCTL"] = Field(
        "POSCTL", description="Mode the pilot switches to (sticks centred: brake and hold).")
    land_after_s: Float = Field(
        30.0, ge=0.0, le=86_400.0,
        description="Simulated seconds after the takeover when the pilot switches to LAND "
        "(the vehicle lands and disarms).",
    )


Fault = Annotated[
    LinkDrop | GpsLoss | BatterySag | RadioSilence | DetectionDropout | Clutter | ClockOffset
    | ClockDrift | PilotTakeover,
    Field(discriminator="kind"),
]
FAULT_MODELS: tuple[type[_Fault], ...] = (
    LinkDrop, GpsLoss, BatterySag, RadioSilence, DetectionDropout, Clutter, ClockOffset,
    ClockDrift, PilotTakeover,
)


class SimSection(Section):
    """Only read by the simulator (python -m sim / mexgen-gcs sitl)."""

    seed: Int = Field(7, ge=0, le=2**63 - 1, description="Seed of the simulated world.")
    tags: tuple[SimTag, ...] = Field(
        (), max_length=64,
        description="Truth per mission tag; tags not listed are static at a random position.",
    )
    reality: Literal["matched", "tx-power", "path-loss", "antenna", "shadowing", "fading",
                     "terrain", "compass", "field"] = Field(
        "matched", description="How the simulated radio differs from the mission's radio model "
        "(a reality profile, see docs/results/localisation.md); matched = exactly the model.")
    battery_endurance_s: Float = Field(1800.0, gt=0.0, le=86_400.0,
                                       description="Full to empty in flight, seconds.")
    faults: tuple[Fault, ...] = Field((), max_length=1000,
                                      description="Injected faults, each with kind and at_s.")
