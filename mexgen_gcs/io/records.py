"""The record types of the flight log (``flight.jsonl``) and of the simulator's ground truth
(``truth.jsonl``): one definition of every field, its unit, frame and range, read by the log
readers and rendered into docs/flight-log.md, docs/truth-file.md and the JSON Schemas under
docs/schemas/ (``python -m mexgen_gcs.io.record_docs`` writes them; a test keeps them in sync).

Both files are JSON lines: one object per line, each with ``t`` and ``type``. The first record
names the file's format and version (flight log: ``mission`` with ``format`` and
``format_version``; truth: ``sim``, whose ``format_version`` is 1 when absent). A reader refuses
a file whose version it does not know, and skips -- counting them -- single records that are not
JSON or do not match their type here: a NaN time, a plan without its fields, a string where a
number belongs. Fields a record type does not list are kept (a writer may add some within a
version); a record of a type not listed here is kept as a plain `Record`.

Frames: flight-log estimates, detections and plans are local ENU metres about the mission home
(x east, y north, z up); telemetry is WGS84 degrees with NED velocities as MAVSDK gives them.
Truth positions are ENU metres about home too (``x_m`` east, ``y_m`` north). Headings and yaw are
compass degrees (0 north, clockwise). ``t`` is unix seconds of the mission clock (sim time for a
SITL flight, so both files share one clock). JSON has no NaN: a number that was not finite is
written as null, which is why most measured values may be null.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

FLIGHT_LOG_FORMAT = "mexgen-flightlog"
FLIGHT_LOG_VERSION = 1
"""The flight-log format version this code writes and the newest it reads."""
TRUTH_FORMAT = "mexgen-truth"
TRUTH_VERSION = 1
"""The truth-file format version this code reads (a header without one is version 1)."""


def f(description: str, unit: str | None = None, frame: str | None = None, **kw: Any) -> Any:
    """A documented field: description, unit and frame land in the JSON Schema and the docs."""
    extra: dict[str, Any] = {k: v for k, v in (("unit", unit), ("frame", frame))
                             if v is not None}
    return Field(description=description, json_schema_extra=extra or None, **kw)


class Record(BaseModel):
    """Any record: a time and a type. Read-only; `rec["field"]` and `rec.get` also work, for
    the fields a type lists and the extra ones alike."""

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    t: float = f("When the record was made: unix seconds of the mission clock.", "s")
    type: str = f("The record type.")

    def get(self, key: str, default: Any = None) -> Any:
        if key in type(self).model_fields:
            return getattr(self, key)
        return (self.__pydantic_extra__ or {}).get(key, default)

    def __getitem__(self, key: str) -> Any:
        marker = object()
        value = self.get(key, marker)
        if value is marker:
            raise KeyError(key)
        return value

    def __contains__(self, key: object) -> bool:
        marker = object()
        return isinstance(key, str) and self.get(key, marker) is not marker

    def to_dict(self) -> dict[str, Any]:
        """The record as JSON data (listed fields and extra ones)."""
        return self.model_dump(mode="json")

Num = float | None
"""A measured value; null when it was not finite."""
Lat = Annotated[float, Field(ge=-90.0, le=90.0)]
Lon = Annotated[float, Field(ge=-180.0, le=180.0)]
Prob = Annotated[float, Field(ge=0.0, le=1.0)]
EN = tuple[Num, Num]
ENU = tuple[Num, Num, Num]
Counts = dict[str, Annotated[int, Field(ge=0)]]


# -- flight log ---------------------------------------------------------------------------

class MissionHeader(Record):
    """First record of every flight log: what flew, with which software and seed."""

    type: Literal["mission"]
    format: Literal["mexgen-flightlog"] = f("Always 'mexgen-flightlog'.")
    format_version: int = f("Flight-log format version; readers refuse newer ones.", ge=1)
    mission: dict[str, Any] = f("The resolved mission (every default filled in), as the "
                                "mission file schema defines it.")
    mission_path: str | None = f("Path of the mission file, if it came from one.")
    mission_text: str | None = f("Text of the mission file, if it came from one.")
    versions: dict[str, str | None] = f("Versions of mexgen_gcs, python, numpy, mavsdk, "
                                        "pymavlink.")
    seed: int | None = f("Seed of the GCS's random draws.")
    method: str = f("Planner method flown: mexgen | pim | mc.")


class Telemetry(Record):
    """The vehicle as the GCS sees it, at 2 Hz of mission time."""

    type: Literal["telemetry"]
    lat: Lat | None = f("Latitude.", "deg", "WGS84")
    lon: Lon | None = f("Longitude.", "deg", "WGS84")
    rel_alt_m: Num = f("Height above home.", "m")
    v_north_m_s: Num = f("Velocity north.", "m/s", "NED")
    v_east_m_s: Num = f("Velocity east.", "m/s", "NED")
    yaw_deg: Num = f("Heading, compass degrees (0 north, clockwise).", "deg")
    mode: str = f("Flight mode name as MAVSDK reports it (OFFBOARD, HOLD, RETURN_TO_LAUNCH...).")
    armed: bool = f("Motors armed.")
    in_air: bool = f("Airborne.")
    battery_percent: Num = f("Battery remaining.", "%")
    connected: bool = f("A MAVLink heartbeat was heard recently.")


class Detection(Record):
    """One detection datagram accepted by the radio receiver (wire format v1)."""

    type: Literal["detection"]
    tag: str = f("Mission tag id.")
    rssi_db: float = f("Received signal strength.", "dB")
    t_pulse: float = f("When the receiver heard the pulse, on the mission clock (the "
                       "receiver's time corrected by its learnt clock offset and drift, see "
                       "receiver_clock).", "s")
    t_pulse_rx: Num = f("The pulse time as the receiver sent it (its own clock).", "s",
                        default=None)
    freq_hz: int | None = f("Carrier frequency, if the datagram gave one.", "Hz")
    rx_en_m: ENU | None = f("Receiver position at the pulse, [east, north, up]; absent when "
                            "the GCS had no pose for it.", "m", "ENU about home", default=None)
    rx_yaw_deg: Num = f("Receiver heading at the pulse, compass degrees.", "deg", default=None)
    used: bool = f("False when the detection could not be given to the filter.", default=True)
    why: str | None = f("Why it was not used.", default=None)


class Radio(Record):
    """A receiver heartbeat: the receiver is alive and listened for these tags."""

    type: Literal["radio"]
    kind: Literal["heartbeat"] = f("Always 'heartbeat'.")
    listening: list[str] | None = f("Tag ids listened for; null = all.")


class ReceiverClockRecord(Record):
    """A receiver's clock against the mission clock, learnt from its heartbeats (a MAVLink
    TUNNEL source: its pulse reports; docs/receiver-clocks.md): its first estimate, every 10 s
    of mission time, and when it jumps."""

    type: Literal["receiver_clock"]
    source: str = f("The receiver: the host (IP address) its datagrams come from.")
    kind: Literal["first", "update", "jump"] = f(
        "first: the first estimate; update: periodic; jump: the receiver's clock stepped "
        "(previous_offset_s is the estimate before).")
    offset_s: float = f("Receiver clock minus mission clock now (the least-delayed "
                        "heartbeats' line at the newest one).", "s")
    drift_ppm: float = f("How fast the receiver's clock runs against the mission clock "
                         "(0 until 20 s of heartbeats).", "ppm")
    samples: int = f("Samples (heartbeats) in the fit's window.", ge=0)
    spread_s: Num = f("Spread of the per-bucket least-delayed heartbeats about the fit.", "s")
    previous_offset_s: Num = f("The offset before a jump.", "s", default=None)
    correcting: bool = f("Whether pulse times are corrected with it "
                         "(receiver.clock_correction).")


class Estimate(Record):
    """One tag's filter estimate after a pulse period (1 s)."""

    type: Literal["estimate"]
    tag: str = f("Mission tag id.")
    existence: Prob = f("Probability that the tag exists in the area.")
    east_m: Num = f("Mean position east.", "m", "ENU about home")
    north_m: Num = f("Mean position north.", "m", "ENU about home")
    v_east_m_s: Num = f("Mean velocity east.", "m/s", "ENU")
    v_north_m_s: Num = f("Mean velocity north.", "m/s", "ENU")
    cov_pos_m2: tuple[tuple[Num, Num], tuple[Num, Num]] = f(
        "Position covariance [[ee, en], [ne, nn]].", "m^2", "ENU")
    radius_m: Num = f("Radius holding the tag with the mission's localisation confidence.",
                      "m")
    localised: bool = f("The tag counts as localised.")
    update: Literal["detection", "missed", "predict-only"] = f(
        "What the period brought: a detection, a missed detection (listened, heard nothing), "
        "or no receiver (prediction only).")
    ess: Num = f("Effective sample size of the particles.")


class Cloud(Record):
    """A down-sampled particle cloud of one tag (every few seconds)."""

    type: Literal["cloud"]
    tag: str = f("Mission tag id.")
    en_m: list[EN] = f("Particle positions [east, north].", "m", "ENU about home")


class Plan(Record):
    """One planning decision."""

    type: Literal["plan"]
    method: str = f("Planner method: mexgen | pim | mc.")
    targets: list[str] = f("Tags planned for.")
    headings_deg: list[float] = f("Candidate headings, compass degrees.", "deg")
    rewards: list[float | None] = f("Reward of each candidate heading (null: not finite).")
    chosen_heading_deg: float = f("The heading flown, compass degrees.", "deg")
    timing_ms: dict[str, float] = f("Wall time per planner stage (predict, measure, update, "
                                    "reward, total; core.planner says what each covers).",
                                    "ms")
    vehicle_en_m: EN = f("Vehicle position planned from, [east, north].", "m", "ENU about home")
    all_pruned: bool = f("Every action was pruned (the heading points at the area centre).")
    alts_m: list[float] | None = f("Altitude of each candidate (null: every candidate holds "
                                   "flight.alt_m).", "m", "above home", default=None)
    chosen_alt_m: float | None = f("The altitude flown to (null: flight.alt_m).", "m",
                                   "above home", default=None)


class Setpoint(Record):
    """A velocity setpoint sent to the autopilot (offboard, 10 Hz)."""

    type: Literal["setpoint"]
    v_north_m_s: float = f("Velocity north.", "m/s", "NED")
    v_east_m_s: float = f("Velocity east.", "m/s", "NED")
    v_down_m_s: float = f("Velocity down.", "m/s", "NED")
    yaw_deg: float = f("Heading to hold, compass degrees.", "deg")
    reason: str = f("Why this setpoint (plan, hold, area edge, climb...).")


class Reject(Record):
    """Datagrams the radio receiver rejected since the previous reject record, per reason."""

    type: Literal["reject"]
    counts: Counts = f("Rejections per reason since the last reject record.")
    total: Counts = f("Rejections per reason since the start.")


class Event(Record):
    """Something happened (takeoff, takeover, tag localised...): `kind` plus free fields."""

    type: Literal["event"]
    kind: str = f("What happened; the other fields depend on it.")


class Error(Record):
    """Something went wrong (planner error, mission error...): `kind` plus free fields."""

    type: Literal["error"]
    kind: str = f("What went wrong; the other fields depend on it.")


class OperatorWarning(Record):
    """Something the operator must see before or during the flight (a geofence the vehicle
    refused, a risky vehicle parameter, a home mismatch): also on stderr and, while it holds,
    in the terminal UI's warnings."""

    type: Literal["warning"]
    kind: str = f("What is wrong (geofence_not_accepted, vehicle_param, home_mismatch, ...).")
    text: str = f("The sentence shown to the operator.")


class StatusText(Record):
    """A STATUSTEXT message from the autopilot."""

    type: Literal["statustext"]
    severity: Literal["debug", "info", "notice", "warning", "error", "critical", "alert",
                      "emergency"] = f("MAVLink severity, lower case.")
    text: str = f("The autopilot's text.")


class Clock(Record):
    """The mission clock's fit to the vehicle's SYSTEM_TIME (every 10 s of mission time)."""

    type: Literal["clock"]
    source: Literal["wall", "syncing", "vehicle"] = f(
        "vehicle: fitted to the vehicle's time; syncing: too few samples for a rate yet; "
        "wall: no vehicle time (the wall clock, at the fixed rate if one was given).")
    rate: float = f("Vehicle seconds per wall second.")
    samples: int = f("Samples in the fit's window.", ge=0)
    fixed_rate: float = f("The rate given with --time-scale (0: measured).")
    residual_rms_s: float = f("Spread of the samples about the fit (-1: none yet).", "s")
    restarts: int = f("Times the vehicle's clock jumped and the fit started again.", ge=0)
    rejected: int = f("Samples that were not a usable time.", ge=0)


class LogLoss(Record):
    """Records the disk refused (full, I/O error) since the last complete record, written
    once writing works again."""

    type: Literal["log_loss"]
    lost: int = f("Records lost since the previous log_loss record.", ge=0)
    lost_total: int = f("Records lost in the whole flight.", ge=0)


class Localised(BaseModel):
    """Where and when a tag was localised (in a result record)."""

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    t: float = f("When.", "s")
    after_s: float = f("Seconds after the mission started searching.", "s")
    lat: Lat = f("Estimated latitude.", "deg", "WGS84")
    lon: Lon = f("Estimated longitude.", "deg", "WGS84")
    east_m: float = f("Estimated position east.", "m", "ENU about home")
    north_m: float = f("Estimated position north.", "m", "ENU about home")
    radius_m: Num = f("Confidence radius.", "m")


class Unresolved(BaseModel):
    """The last estimate of a tag that was not localised (in a result record): where to look,
    and the 95 % radius that holds it (the same honesty as a claim, only wider)."""

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    lat: Lat = f("Estimated latitude.", "deg", "WGS84")
    lon: Lon = f("Estimated longitude.", "deg", "WGS84")
    east_m: float = f("Estimated position east.", "m", "ENU about home")
    north_m: float = f("Estimated position north.", "m", "ENU about home")
    radius_m: Num = f("95 % radius.", "m")
    existence: float = f("Probability that the tag is there at all.", ge=0.0, le=1.0)


class TagReport(BaseModel):
    """Why and when a tag was reported (in a result record), and its radius over time."""

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    reason: Literal["reached", "stalled", "budget"] = f(
        "reached: its radius dropped to localisation.radius_m; stalled: it shrank by less than "
        "localisation.stall_min_shrink_percent over localisation.stall_window_s of work on it; "
        "budget: it was worked on for localisation.tag_budget_s.")
    after_s: float = f("When it was reported, seconds after the mission started searching.", "s")
    radius_m: Num = f("Its 95 % radius when reported.", "m")
    worked_s: float = f("How long it had been the planning target.", "s", ge=0.0)
    radius_over_time: list[list[float | None]] = f(
        "[after_s, radius_m] pairs every 10 s of the search and at the report, then to the end "
        "(the estimate keeps updating after the report).")


class TagReported(Record):
    """A tag was reported: it reached the radius, stalled or spent its budget; the planner
    moves on to the others (core.mission_core.ReportRule)."""

    type: Literal["tag_reported"]
    tag: str = f("Tag id.")
    reason: Literal["reached", "stalled", "budget"] = f("Why (see the result's reports).")
    after_s: float = f("Seconds after the mission started searching.", "s")
    east_m: float = f("Estimated position east.", "m", "ENU about home")
    north_m: float = f("Estimated position north.", "m", "ENU about home")
    radius_m: Num = f("95 % radius.", "m")
    worked_s: float = f("How long it had been the planning target.", "s", ge=0.0)


class Result(Record):
    """Last record of a flight that ended in order: how it ended."""

    type: Literal["result"]
    end_reason: str = f("Why the mission ended (all_localised, all_reported, max_mission_time, "
                        "operator_rtl, "
                        "takeover...).")
    exit_code: int = f("The command's exit code: 0 success, 1 failed or aborted, 2 refused "
                       "before arming for the vehicle's set-up (parameters, geofence).", ge=0)
    localised: dict[str, Localised] = f("Localised tags by id.")
    unresolved: dict[str, Unresolved] | None = f(
        "The last estimate of every tag not localised, by id (absent before 2026-11).",
        default=None)
    reports: dict[str, TagReport] | None = f(
        "Every reported tag by id: why, when, its radius over time (absent before reporting "
        "existed, and in follow missions).", default=None)
    rejects: Counts = f("Rejected datagrams per reason, whole flight.")
    duration_s: float = f("Mission duration.", "s", ge=0.0)
    error: str | None = f("The error that ended the mission, if one did.", default=None)
    takeover: Any = f("The autopilot takeover that ended the mission, if one did.",
                      default=None)
    counters: dict[str, int] | None = f("Counters of things that went wrong and were handled.",
                                        default=None)


FLIGHT_RECORDS: tuple[type[Record], ...] = (
    MissionHeader, Telemetry, Detection, Radio, ReceiverClockRecord, Estimate, Cloud, Plan,
    Setpoint, Reject, Event, Error, OperatorWarning, StatusText, Clock, LogLoss, TagReported,
    Result)


# -- simulator truth ----------------------------------------------------------------------

class SimTag(BaseModel):
    """A tag as the simulator placed it at the start."""

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    id: str = f("Mission tag id.")
    freq_hz: int = f("Carrier frequency.", "Hz")
    motion: str = f("Truth motion model: static | rw | cv | ctra | cv-ift.")
    x_m: float = f("Start position east.", "m", "ENU about home")
    y_m: float = f("Start position north.", "m", "ENU about home")


class SimHeader(Record):
    """First record of a truth file: the simulated world and its clock."""

    type: Literal["sim"]
    format: Literal["mexgen-truth"] = f("Always 'mexgen-truth' (absent in files written "
                                       "before the format was named).", default=TRUTH_FORMAT)
    format_version: int = f("Truth-file format version (absent = 1); readers refuse newer "
                            "ones.", default=1, ge=1)
    mission: str = f("Mission name.")
    seed: int = f("Seed of the simulated world.")
    speedup: float = f("Sim time runs this many times faster than wall time.", gt=0.0)
    start_unix: float = f("Sim clock origin: sim time = start_unix + elapsed sim seconds.", "s")
    wall_start_unix: float = f("Wall clock at the start.", "s")
    sysid: int = f("MAVLink system id of the simulated vehicle.")
    home: dict[str, float] = f("Home: lat_deg, lon_deg (WGS84) and alt_m (AMSL).")
    mavlink: list[Any] = f("[host, port] MAVLink is sent to.")
    radio: list[Any] = f("[host, port] detection datagrams are sent to.")
    listen: list[Any] = f("[host, port] the simulator listens on for MAVLink.")
    tags: list[SimTag] = f("The tags at the start.")
    faults: list[dict[str, Any]] = f("Scheduled faults (kind, at_s and the kind's fields).")
    reality: dict[str, Any] | None = f(
        "The radio world drawn from sim.reality (profile, per-tag tx_offset_db and "
        "tag_height_m, path_loss_exponent, compass_bias_deg, antenna, shadowing_std_db, "
        "rician_k_db); null for matched.", default=None)
    mission_text: str | None = f("Text of the mission file.")


class TagTruth(Record):
    """Where a tag really is (1 Hz of sim time)."""

    type: Literal["tag"]
    tag: str = f("Mission tag id.")
    motion: str = f("Truth motion model.")
    x_m: float = f("Position east.", "m", "ENU about home")
    y_m: float = f("Position north.", "m", "ENU about home")
    vx_m_s: float = f("Velocity east.", "m/s", "ENU")
    vy_m_s: float = f("Velocity north.", "m/s", "ENU")
    mode: int = f("Motion mode index (IMM models; 0 otherwise).")


class VehicleTruth(Record):
    """Where the simulated vehicle really is (1 Hz of sim time)."""

    type: Literal["vehicle"]
    east_m: float = f("Position east.", "m", "ENU about home")
    north_m: float = f("Position north.", "m", "ENU about home")
    up_m: float = f("Height above home.", "m", "ENU about home")
    v_east_m_s: float = f("Velocity east.", "m/s", "ENU")
    v_north_m_s: float = f("Velocity north.", "m/s", "ENU")
    v_up_m_s: float = f("Velocity up.", "m/s", "ENU")
    yaw_deg: float = f("Heading, compass degrees.", "deg")
    lat: Lat = f("Latitude.", "deg", "WGS84")
    lon: Lon = f("Longitude.", "deg", "WGS84")
    alt_m: float = f("Altitude.", "m", "AMSL")
    mode: str = f("PX4 mode name.")
    armed: bool = f("Motors armed.")
    landed_state: str = f("MAVLink landed state (ON_GROUND, IN_AIR, TAKEOFF, LANDING).")
    battery: Prob = f("Battery remaining, fraction of full.")
    gps_ok: bool = f("GPS available (false during a gps_loss fault).")
    link_down: bool = f("MAVLink link cut (a link_drop fault).")


class Pulse(Record):
    """One tag pulse: the true received power and what the radio did with it."""

    type: Literal["pulse"]
    tag: str = f("Mission tag id.")
    freq_hz: int = f("Carrier frequency.", "Hz")
    x_m: float = f("Tag position east.", "m", "ENU about home")
    y_m: float = f("Tag position north.", "m", "ENU about home")
    rx_enu_m: tuple[float, float, float] = f("Receiver position [east, north, up].", "m",
                                             "ENU about home")
    rx_yaw_deg: float = f("Receiver heading, compass degrees.", "deg")
    distance_m: float = f("Receiver-to-tag distance.", "m", ge=0.0)
    power_db: float = f("True received power (before noise).", "dB")
    detected: bool | None = f("The receiver detected the pulse; null when the simulator "
                              "serves IQ (`--iq-server`) and the IQ receiver decides.")
    rssi_db: Num = f("Measured RSSI, if detected.", "dB")
    dropped: bool = f("Dropped by a detection_dropout fault.")
    sent: bool = f("A datagram was sent.")
    t_sent: Num = f("The datagram's `t` (with any clock_offset fault), if sent.", "s")


class Clutter(Record):
    """A spurious detection (clutter model or fault)."""

    type: Literal["clutter"]
    tag: str = f("Tag id the clutter claims.")
    freq_hz: int = f("Carrier frequency.", "Hz")
    rssi_db: float = f("RSSI sent.", "dB")
    source: str = f("model (the radio's clutter rate) or the fault that made it.")
    sent: bool = f("A datagram was sent (false during radio silence).")
    t_sent: Num = f("The datagram's `t`, if sent.", "s")


class Fault(Record):
    """A scheduled fault starting or ending: `phase`, `kind` plus the kind's fields."""

    type: Literal["fault"]
    phase: str = f("start or end.")
    kind: str = f("Fault kind (link_drop, gps_loss, radio_silence, ...).")


class SimEvent(Record):
    """Something the simulated autopilot did (armed, mode change, failsafe...)."""

    type: Literal["event"]
    kind: str = f("What happened; other fields depend on it.")
    text: str = f("Human-readable description.")


class Fence(Record):
    """A geofence upload the simulated autopilot accepted."""

    type: Literal["fence"]
    inclusion_polygons_m: list[list[EN]] = f("Inclusion polygons, vertices [east, north].",
                                             "m", "ENU about home")
    exclusion_polygons_m: list[list[EN]] = f("Exclusion polygons.", "m", "ENU about home")
    inclusion_circles: list[tuple[float, float, float]] = f(
        "Inclusion circles [east, north, radius].", "m", "ENU about home")
    exclusion_circles: list[tuple[float, float, float]] = f("Exclusion circles.", "m",
                                                            "ENU about home")
    items: int = f("Mission items uploaded.", ge=0)


class End(Record):
    """Last record when the simulator exits in order."""

    type: Literal["end"]
    sim_s: float = f("Sim seconds elapsed.", "s", ge=0.0)
    reason: str = f("landed or signal.")
    radio: dict[str, Any] = f("Radio counters (pulses, detections_sent, clutter_sent...).")
    mavlink: dict[str, Any] = f("MAVLink counters.")


TRUTH_RECORDS: tuple[type[Record], ...] = (
    SimHeader, TagTruth, VehicleTruth, Pulse, Clutter, Fault, SimEvent, Fence, End)


def _adapter(models: tuple[type[Record], ...]) -> TypeAdapter[Any]:
    """Validates one line (JSON) as the record type its `type` names."""
    return TypeAdapter(Annotated[Union[models], Field(discriminator="type")])  # type: ignore[arg-type]  # noqa: UP007


FLIGHT_ADAPTER: TypeAdapter[Any] = _adapter(FLIGHT_RECORDS)
TRUTH_ADAPTER: TypeAdapter[Any] = _adapter(TRUTH_RECORDS)
GENERIC_ADAPTER: TypeAdapter[Record] = TypeAdapter(Record)
