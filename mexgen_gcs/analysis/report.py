"""The post-flight report of one log: report.md, report.html, summary.json and PNG plots.

Frame: local ENU metres about home for east/north; WGS84 degrees for lat/lon; localisation
times in seconds since airborne.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from mexgen_gcs.analysis import plots
from mexgen_gcs.analysis.calibration import PathLossFit, calibrate
from mexgen_gcs.analysis.document import Document, fmt
from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.summary import FlightSummary, summarise
from mexgen_gcs.analysis.truth import Truth
from mexgen_gcs.analysis.vehicle_link import VehicleLink, read_vehicle_link
from mexgen_gcs.errors import EstimationError
from mexgen_gcs.io.logread import Damage
from mexgen_gcs.io.mavlink_tap import TLOG_FILE

REPORT_MD = "report.md"
REPORT_HTML = "report.html"
SUMMARY_JSON = "summary.json"
PLOTS = {
    "path": "path.png",
    "tags": "tags_over_time.png",
    "rssi": "rssi_distance.png",
    "timing": "planner_timing.png",
}


@dataclass(frozen=True, slots=True)
class Report:
    out_dir: Path
    markdown: Path
    html: Path
    summary_json: Path
    plots: dict[str, Path]
    summary: FlightSummary
    fits: dict[str, PathLossFit]
    """Path-loss fits by position source (estimate, truth)."""


def pooled_fits(flight: FlightData, truth: Truth | None) -> dict[str, PathLossFit]:
    """Path-loss fits over all tags: against the estimates, and the truth when known. A
    source with too little data is left out."""
    fits: dict[str, PathLossFit] = {}
    tags_est = tuple(t for t in flight.tag_ids if len(flight.estimates[t]))
    sources: list[tuple[str, tuple[str, ...]]] = [("estimate", tags_est)]
    if truth is not None:
        sources.append(("truth", tuple(t for t in flight.tag_ids if t in truth.tags)))
    for source, tags in sources:
        if not tags:
            continue
        try:
            fits[source] = calibrate(flight, tags, source, truth)
        except EstimationError:
            continue
    return fits


def write_report(flight: FlightData, out_dir: Path, truth: Truth | None = None) -> Report:
    """Compute, plot and write the report of one flight into out_dir (created)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = summarise(flight, truth)
    fits = pooled_fits(flight, truth)
    paths = {
        "path": plots.plot_path(flight, summary, truth, out_dir / PLOTS["path"]),
        "tags": plots.plot_tags_over_time(flight, summary, out_dir / PLOTS["tags"]),
        "rssi": plots.plot_rssi_distance(flight, fits.get("estimate"), out_dir / PLOTS["rssi"]),
        "timing": plots.plot_planner_timing(flight, out_dir / PLOTS["timing"]),
    }
    link = vehicle_link_of(flight)
    doc = report_document(flight, summary, fits, link)
    md = out_dir / REPORT_MD
    md.write_text(doc.markdown(), encoding="utf-8")
    page = out_dir / REPORT_HTML
    page.write_text(doc.html(), encoding="utf-8")
    js = out_dir / SUMMARY_JSON
    payload: dict[str, Any] = summary.to_dict()
    payload["path_loss_fits"] = {k: asdict(v) for k, v in fits.items()}
    payload["vehicle_link"] = link.to_dict() if link is not None else None
    js.write_text(json.dumps(json_safe(payload), indent=1), encoding="utf-8")
    return Report(out_dir, md, page, js, paths, summary, fits)


def vehicle_link_of(flight: FlightData) -> VehicleLink | None:
    """The summary of the vehicle.tlog beside the flight log, if there is one."""
    tlog = Path(flight.log.path).parent / TLOG_FILE
    return read_vehicle_link(tlog) if tlog.is_file() else None


def json_safe(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value


def _km(m: float) -> str:
    return f"{m / 1000.0:.2f} km"


def _damage(lines: dict[str, list[int]]) -> str:
    if not lines:
        return "none"
    return Damage(lines).describe()


def report_document(flight: FlightData, s: FlightSummary,
                    fits: dict[str, PathLossFit], link: VehicleLink | None = None) -> Document:
    tot = s.totals
    seed = f", seed {tot.seed}" if tot.seed is not None else ""
    doc = Document(f"Flight report: {tot.name} ({tot.method}{seed})")
    sec = doc.section("Mission")
    end = tot.end_reason + (f" (exit {tot.exit_code})" if tot.exit_code is not None else "")
    rows = [
        ("Log", s.log_file),
        ("Mission kind", tot.kind),
        ("Planner method", ", ".join(tot.methods_used)),
        ("Start", tot.start_utc),
        ("Duration", f"{tot.duration_s:.1f} s"),
        ("Airborne", "–" if tot.airborne_s is None else f"{tot.airborne_s:.1f} s"),
        ("Distance flown", _km(tot.distance_flown_m)),
        ("End reason", end),
        ("Tags localised", f"{tot.tags_localised} of {tot.tags_total}"),
        ("Detections", str(tot.detections)),
        ("Radio heartbeats", str(tot.heartbeats)),
        ("Plans", str(tot.plans)),
        ("Radio rejects", ", ".join(f"{k} {v}" for k, v in tot.radio_rejects.items()) or "none"),
        ("Damaged log records", _damage(tot.damaged_records)),
        ("Software", ", ".join(f"{k} {v}" for k, v in tot.software.items() if v) or "–"),
    ]
    sec.table(("", ""), rows)
    if tot.torn_last_line:
        sec.para("The log ends with a torn (partial) line, as after a crash; it was skipped.")
    if not tot.complete:
        sec.para("The log has no result record: the GCS did not finish the mission normally.")
    if tot.damaged_records:
        sec.para("Damaged records (not JSON, or not valid for their type) were skipped; the "
                 "report is made of the rest of the log.")
    if s.truth_damaged_records:
        sec.para(f"The ground truth file had damaged records, skipped: "
                 f"{_damage(s.truth_damaged_records)}.")

    sec = doc.section("Failsafe and safety events")
    if s.safety_events:
        sec.table(("t since airborne (s)", "event", "detail"),
                  [(fmt(e.after_s), e.kind, e.detail) for e in s.safety_events])
    else:
        sec.para("None.")

    if link is not None:
        _vehicle_link_section(doc, link)

    sec = doc.section("Tags")
    headers = ["tag", "detections", "localised after (s)", "reported", "lat", "lon", "east (m)",
               "north (m)", f"{int(flight.mission.localisation.confidence * 100)}% radius (m)",
               "1-sigma major (m)", "existence"]
    if s.has_truth:
        headers += ["error at localisation (m)", "inside claimed radius", "final error (m)",
                    "inside final radius", "RMS tracking error (m)"]
    trows = []
    for t in s.tags:
        row = [t.tag_id, str(t.detections), fmt(t.localised_after_s), _reported_cell(t),
               fmt(t.final_lat_deg, 6), fmt(t.final_lon_deg, 6), fmt(t.final_east_m),
               fmt(t.final_north_m), fmt(t.final_radius_m), fmt(t.final_sigma_major_m),
               fmt(t.final_existence, 3)]
        if s.has_truth:
            row += [fmt(t.error_at_localisation_m), _yes_no(t.inside_claimed_radius),
                    fmt(t.final_error_m), _yes_no(t.inside_final_radius),
                    fmt(t.tracking_rms_error_m)]
        trows.append(row)
    sec.table(headers, trows)
    sec.para("Position, radius and existence are the final estimate; 'localised after' is the "
             "time from airborne to the tag_localised event; 'reported' is why and when the "
             "mission moved on from the tag (reached its radius, stalled, or spent its budget) "
             "with its radius then"
             + ("; errors are distances to the simulator's truth at that moment, and the RMS "
                "tracking error is over every pulse of the flight." if s.has_truth else "."))
    if s.has_truth:
        sec.para(coverage_sentence(s.tags, flight.mission.localisation.confidence))

    sec = doc.section("Planner timing (wall ms per plan)")
    if s.timing:
        sec.table(("method", "stage", "plans", "median", "p95", "max"),
                  [(x.method, x.stage, str(x.plans), fmt(x.median_ms, 2), fmt(x.p95_ms, 2),
                    fmt(x.max_ms, 2)) for x in s.timing])
    else:
        sec.para("No plans in this log.")

    sec = doc.section("Path-loss fit")
    radio = flight.mission.radio
    frows = [("mission file", fmt(radio.p0_db, 2), fmt(radio.path_loss_exponent, 3),
              fmt(radio.noise_std_db, 2), "–", "–")]
    for source, f in fits.items():
        frows.append((f"fit to {source} positions", f"{f.p0_db:.2f} ± {f.p0_se_db:.2f}",
                      f"{f.path_loss_exponent:.3f} ± {f.n_se:.3f}", fmt(f.noise_std_db, 2),
                      str(f.used), str(f.outliers)))
    sec.table(("model", "P0 (dB)", "n", "noise std (dB)", "detections", "clutter rejected"),
              frows)
    best = fits.get("truth") or fits.get("estimate")
    if best is not None:
        sec.para("As a mission file section (mexgen-gcs analyze LOG --calibrate TAG for one tag):")
        sec.code(best.radio_block(flight.mission.radio.model_dump()))

    sec = doc.section("Plots")
    sec.image(PLOTS["path"], "Flight path with detections coloured by RSSI and final estimates")
    sec.image(PLOTS["tags"], "Uncertainty radius and existence probability per tag over time")
    sec.image(PLOTS["rssi"], "RSSI against distance to the estimate, with the fitted path loss")
    sec.image(PLOTS["timing"], "Planner wall time per stage")
    return doc


def _reported_cell(t: Any) -> str:
    """'stalled @ 212 s, 63 m' (or '–' when the tag was not reported)."""
    if t.reported_reason is None:
        return "–"
    return f"{t.reported_reason} @ {fmt(t.reported_after_s)} s, {fmt(t.reported_radius_m)} m"


def _yes_no(inside: bool | None) -> str:
    return "–" if inside is None else ("yes" if inside else "NO")


def coverage_sentence(tags: Sequence[Any], confidence: float) -> str:
    """How many localised tags were inside the radius claimed for them, with a 95 % Wilson
    interval: the figure that says whether the localisation radius means what it says."""
    from scipy.stats import binomtest

    judged = [t.inside_claimed_radius for t in tags if t.inside_claimed_radius is not None]
    final = [t.inside_final_radius for t in tags
             if t.inside_final_radius is not None and t.inside_claimed_radius is None]
    if final:
        k, n = sum(final), len(final)
        tail = (f" Of the {n} tags not localised, {k} were inside the radius of their final "
                "estimate.")
    else:
        tail = ""
    if not judged:
        return "Coverage: no tag was localised, so no claimed radius can be checked." + tail
    k, n = sum(judged), len(judged)
    ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
    return (f"Coverage: {k} of {n} localised tags were inside the radius claimed at "
            f"localisation ({k / n:.0%}, 95 % interval {ci.low:.0%}-{ci.high:.0%}); the claim "
            f"is {confidence:.0%}." + tail)


def _vehicle_link_section(doc: Document, link: VehicleLink) -> None:
    sec = doc.section("The vehicle's own view (vehicle.tlog)")
    sec.para(f"{link.messages} MAVLink messages over {link.duration_s:.1f} s of wall time; "
             f"{link.positions} positions from the autopilot"
             + (f", highest {link.max_rel_alt_m:.1f} m above home" if link.max_rel_alt_m
                is not None else "") + ". On the link: "
             + (", ".join(f"{k} ({v})" for k, v in link.systems.items()) or "nobody") + ".")
    if link.modes:
        sec.table(("t (s)", "mode", "armed"),
                  [(f"{t:.1f}", mode, "yes" if armed else "no") for t, mode, armed in link.modes])
    if link.commands:
        sec.table(("command to the autopilot", "count"),
                  [(k, str(v)) for k, v in sorted(link.commands.items())])
    if link.denied:
        sec.para("Not accepted: " + ", ".join(f"{k} ({v})" for k, v in link.denied.items())
                 + ".")
    if link.statustexts:
        sec.table(("t (s)", "autopilot says"), [(f"{t:.1f}", text)
                                                for t, text in link.statustexts[:40]])
