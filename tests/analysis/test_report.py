"""The report of a real SITL flight holds the log's numbers (checked against our own reading
of the raw JSON lines and the simulator's truth file)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.analysis import load_flight, load_truth, summarise
from mexgen_gcs.analysis.report import PLOTS, write_report
from mexgen_gcs.cli import main
from mexgen_gcs.io.truthfile import read_truth_file

pytestmark = pytest.mark.e2e

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _records(log_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (log_dir / "flight.jsonl").read_text().splitlines()]


def _truth_track(log_dir: Path, tag: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    tr = [(r.t, r.x_m, r.y_m) for r in read_truth_file(log_dir).tags() if r.tag == tag]
    a = np.array(tr)
    return a[:, 0], a[:, 1], a[:, 2]


@pytest.fixture(scope="module")
def report_dir(demo_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report")
    assert main(["analyze", str(demo_log), "--out", str(out)]) == 0
    return out


def test_report_files_exist(report_dir: Path) -> None:
    for name in ("report.md", "report.html", "summary.json", *PLOTS.values()):
        assert (report_dir / name).is_file(), name
    for name in PLOTS.values():
        data = (report_dir / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, name
    html = (report_dir / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "</html>" in html
    for name in PLOTS.values():
        assert f'src="{name}"' in html
        assert f"]({name})" in (report_dir / "report.md").read_text()


def test_localisation_times_equal_the_logged_events(demo_log: Path, report_dir: Path) -> None:
    events = {r["tag"]: r["after_s"] for r in _records(demo_log)
              if r["type"] == "event" and r["kind"] == "tag_localised"}
    assert events, "the fixture flight should localise at least one tag in 150 s"
    summary = json.loads((report_dir / "summary.json").read_text())
    by_tag = {t["tag_id"]: t for t in summary["tags"]}
    for tag, t in by_tag.items():
        if tag in events:
            assert t["localised"] and t["localised_after_s"] == events[tag]
        else:
            assert not t["localised"] and t["localised_after_s"] is None
    md = (report_dir / "report.md").read_text()
    for tag, after in events.items():
        assert f"| {tag} |" in md and f"| {after:.1f} |" in md


def test_errors_match_a_recomputation_against_the_truth_file(demo_log: Path,
                                                             report_dir: Path) -> None:
    summary = json.loads((report_dir / "summary.json").read_text())
    assert summary["has_truth"]
    recs = _records(demo_log)
    result = next(r for r in recs if r["type"] == "result")
    checked = 0
    for t in summary["tags"]:
        est = [r for r in recs if r["type"] == "estimate" and r["tag"] == t["tag_id"]]
        tt, xs, ys = _truth_track(demo_log, t["tag_id"])
        last = est[-1]
        want_final = math.hypot(last["east_m"] - np.interp(last["t"], tt, xs),
                                last["north_m"] - np.interp(last["t"], tt, ys))
        assert t["final_error_m"] == pytest.approx(want_final, abs=1e-6)
        assert t["inside_final_radius"] == (want_final <= t["final_radius_m"])
        first = next((r for r in est if r["localised"]), None)
        if first is None:
            assert t["error_at_localisation_m"] is None
            # the result record leaves the operator the last estimate and its radius
            left = result["unresolved"][t["tag_id"]]
            assert (left["east_m"], left["north_m"], left["radius_m"]) == pytest.approx(
                (last["east_m"], last["north_m"], last["radius_m"]), abs=1e-6)
            continue
        want = math.hypot(first["east_m"] - np.interp(first["t"], tt, xs),
                          first["north_m"] - np.interp(first["t"], tt, ys))
        assert t["error_at_localisation_m"] == pytest.approx(want, abs=1e-6)
        assert t["inside_claimed_radius"] == (want <= t["localised_radius_m"])
        # the result record's localisation is the same estimate (static tags: same truth)
        loc = result["localised"][t["tag_id"]]
        assert (loc["east_m"], loc["north_m"]) == pytest.approx(
            (first["east_m"], first["north_m"]), abs=1e-6)
        assert t["localised_t"] == pytest.approx(loc["t"], abs=1e-6)
        checked += 1
    assert checked >= 1
    inside = sum(bool(t["inside_claimed_radius"]) for t in summary["tags"])
    md = (report_dir / "report.md").read_text()
    assert f"Coverage: {inside} of {checked} localised tags were inside the radius" in md


def test_mission_totals_and_failsafes(demo_log: Path) -> None:
    flight = load_flight(demo_log)
    s = summarise(flight, load_truth(demo_log))
    result = next(r for r in _records(demo_log) if r["type"] == "result")
    assert s.totals.end_reason == result["end_reason"] == "max_mission_time"
    assert s.totals.exit_code == 1 and s.totals.complete and not s.totals.torn_last_line
    assert s.totals.duration_s == pytest.approx(result["duration_s"])
    assert s.totals.plans == sum(1 for r in _records(demo_log) if r["type"] == "plan")
    # the distance flown agrees with the simulator's own 1 Hz vehicle track
    rows = read_truth_file(demo_log).records
    veh = np.array([(r["east_m"], r["north_m"]) for r in rows if r["type"] == "vehicle"])
    sim_m = float(np.hypot(*np.diff(veh, axis=0).T).sum())
    assert s.totals.distance_flown_m == pytest.approx(sim_m, rel=0.05)
    kinds = [(e.kind, e.detail) for e in s.safety_events]
    assert any(k == "safety" and "max_mission_time" in d and "rtl" in d for k, d in kinds)


def test_planner_timing_is_median_and_p95_of_the_plan_records(demo_log: Path) -> None:
    plans = [r for r in _records(demo_log) if r["type"] == "plan"]
    s = summarise(load_flight(demo_log))
    rows = {(x.method, x.stage): x for x in s.timing}
    for stage in ("predict", "measure", "update", "reward", "total"):
        v = np.array([p["timing_ms"][stage] for p in plans])
        row = rows[("mexgen", stage)]
        assert row.plans == len(plans)
        assert row.median_ms == pytest.approx(float(np.median(v)))
        assert row.p95_ms == pytest.approx(float(np.percentile(v, 95)))


def test_report_without_truth_has_no_error_columns(demo_log: Path, tmp_path: Path) -> None:
    report = write_report(load_flight(demo_log), tmp_path, truth=None)
    md = report.markdown.read_text()
    assert "error at localisation" not in md and "fit to truth" not in md
    assert not report.summary.has_truth
    assert "estimate" in report.fits
