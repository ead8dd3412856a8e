"""Experiments of a mission that ends usefully (``--finish``): every tag reported with its
reason, the run ending when all are; the oracle that knows the truth; the summary's
time-to-radius curve and reason counts."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.cli import parse_methods
from mexgen_gcs.experiments.runner import (
    COLUMNS,
    RunSpec,
    StarPasses,
    first_all_under,
    orbit_heading,
    run_one,
)
from mexgen_gcs.experiments.scenario import (
    method_label,
    mission_for,
    oracle_orbit_m,
    oracle_pattern,
    ordered_methods,
    scenario,
)
from mexgen_gcs.experiments.summary import reason_counts, summary_markdown, under_times


def _short(finish: bool, **kw: object):
    sc = scenario("localise", "static", quick=True, reality="field", estimator="robust",
                  finish=finish)
    return replace(sc, duration_s=120.0, **kw)  # type: ignore[arg-type]


def test_finish_reports_every_tag_and_ends_the_run() -> None:
    # 10 s of work per tag: all four are reported (stalled or budget) well within the limit
    sc = _short(True, tag_budget_s=10.0, stall_window_s=8.0)
    res = run_one(RunSpec(sc, "mexgen", 3, 0, 0))
    row = res.row
    reasons = row["reasons"].split(";")
    assert len(reasons) == 4 and set(reasons) <= {"reached", "stalled", "budget"}
    times = [float(x) for x in row["reported_t_s"].split(";")]
    assert float(row["all_reported_s"]) == max(times) == float(row["sim_s"])  # ended there
    assert float(row["sim_s"]) < sc.duration_s
    radii = [float(x) for x in row["reported_radii_m"].split(";")]
    assert all(r > 0 for r in radii)
    assert res.series["radius_m"].shape == (len(res.series["t_s"]), 4)
    assert tuple(row) == COLUMNS


def test_without_finish_nothing_is_reported_early_and_the_run_goes_on() -> None:
    sc = _short(False)
    row = run_one(RunSpec(sc, "mexgen", 3, 0, 0)).row
    assert set(row["reasons"].split(";")) <= {"", "reached"}
    assert float(row["sim_s"]) == sc.duration_s or row["success"] == "1"
    doc = mission_for(sc, "mexgen").localisation
    assert doc.stall_window_s is None and doc.tag_budget_s is None


def test_the_finish_mission_carries_the_schema_defaults() -> None:
    loc = mission_for(_short(True), "mexgen").localisation
    assert loc.stall_window_s == 120.0 and loc.tag_budget_s == 240.0
    assert loc.stall_min_shrink_percent == 10.0


def test_first_all_under_is_the_first_pulse_with_every_tag_under() -> None:
    t = np.array([1.0, 2.0, 3.0, 4.0])
    r = np.array([[90, 40], [60, 45], [49, 80], [30, 50]], dtype=float)
    assert first_all_under(t, r, 50.0) == 4.0
    assert first_all_under(t, r, 75.0) == 2.0
    assert first_all_under(t, r, 20.0) is None


@pytest.mark.parametrize("start_xy", [(500.0, 0.0), (0.0, -300.0), (45.0, 10.0), (5.0, 0.0)])
def test_orbit_heading_converges_onto_the_circle(start_xy: tuple[float, float]) -> None:
    """Flown with a point mass that turns instantly, the field brings the vehicle onto the
    circle and keeps it there, counter-clockwise."""
    centre = np.array([100.0, 50.0])
    xy = centre + np.array(start_xy)
    dists = []
    for _ in range(600):
        heading, speed = orbit_heading(xy, centre, 60.0, 15.0, 4.0)
        xy = xy + 0.1 * speed * np.array([math.sin(math.radians(heading)),
                                          math.cos(math.radians(heading))])
        dists.append(float(np.hypot(*(xy - centre))))
    assert abs(dists[-1] - 60.0) < 3.0
    assert max(abs(d - 60.0) for d in dists[-200:]) < 3.0
    _, speed = orbit_heading(centre + np.array([30.0, 0.0]), centre, 30.0, 15.0, 4.0)
    assert speed == pytest.approx(math.sqrt(4.0 * 30.0))  # v^2 / r within the limit


def test_the_oracle_flies_to_the_true_tags_with_the_same_filter() -> None:
    sc = _short(True)
    res = run_one(RunSpec(sc, "oracle40", 3, 0, 0))
    assert res.row["method"] == "oracle40" and res.row["plans"] == "0"
    assert res.row["truth_digest"] == run_one(RunSpec(sc, "mexgen", 3, 0, 0)).row["truth_digest"]
    # by the end it circles a tag: its smallest distance to any true tag is near 40 m
    from mexgen_gcs.experiments.world import truth_for

    tags = truth_for(sc, 3, 0).states[0, :, :2]
    path = res.series["vehicle_en_m"].astype(np.float64)
    d = np.min(np.hypot(path[:, None, 0] - tags[None, :, 0], path[:, None, 1] - tags[None, :, 1]),
               axis=1)
    assert d.min() < 60.0


def test_oracle_names() -> None:
    assert oracle_orbit_m("oracle60") == 60.0 and oracle_orbit_m("mexgen") is None
    assert oracle_orbit_m("oraclestar150") == 150.0
    assert oracle_pattern("oraclestar150") == "star" and oracle_pattern("oracle60") == "orbit"
    assert method_label("oracle60") == "Oracle orbit 60 m"
    assert ordered_methods(["oracle80", "oraclestar100", "mexgen", "oracle40", "pim"]) == [
        "pim", "mexgen", "oracle40", "oracle80", "oraclestar100"]
    assert parse_methods("mexgen,oracle30") == ("mexgen", "oracle30")
    for bad in ("oracle", "oracle2", "oraclex", "mexgen2", "oraclestar", "oraclestarx"):
        with pytest.raises(ConfigError):
            parse_methods(bad)


def _row(method: str, start: int, under: tuple[str, str, str], reasons: str,
         ended: str) -> dict[str, str]:
    row = dict.fromkeys(COLUMNS, "")
    row.update(scenario="localise", model="static", method=method, start=str(start), rep="0",
               success="0", n_localised="0", all_under_50_s=under[0], all_under_75_s=under[1],
               all_under_100_s=under[2], reasons=reasons, all_reported_s=ended,
               final_radii_m="40;60;80;100", sim_s="1000.0", wall_s="1", cpu_s="1",
               plans="1", detections="1", radius_m="50.0", tight_radius_m="")
    return row


def test_the_summary_tabulates_time_to_radius_and_reasons() -> None:
    rows = [_row("mexgen", 0, ("", "600.0", "300.0"), "reached;stalled;budget;", ""),
            _row("mexgen", 1, ("200.0", "150.0", "100.0"), "reached;reached;reached;reached",
                 "200.0"),
            _row("oracle60", 0, ("400.0", "300.0", "100.0"), "reached;reached;reached;stalled",
                 "450.0")]
    t, done = under_times(rows[:2], 50, 1000.0)
    assert list(done) == [False, True] and list(t) == [1000.0, 200.0]
    assert reason_counts(rows[:2]) == {"reached": 5, "stalled": 1, "budget": 1, "": 1}
    md = summary_markdown(rows, {"scenario": "localise", "seed": 1, "settings": {}})
    assert "## Time to radius and reporting" in md
    # MexGen at 75 m: one run by 250 s, both by 750 s
    line = next(x for x in md.splitlines() if x.startswith("| Static | MexGen | 75 |"))
    cells = [c.strip() for c in line.split("|")]
    assert cells[4].startswith("0.50") and cells[6].startswith("1.00")
    reasons = next(x for x in md.splitlines() if x.startswith("| Static | MexGen | 8 |"))
    assert "| 5 | 1 | 1 | 1 |" in reasons and "0.50" in reasons
    assert "| Static | Oracle orbit 60 m |" in md


def test_star_passes_cross_the_tag_from_ever_new_sides() -> None:
    """Flown with a point mass that turns instantly, each pass runs out to the reach and the
    passes cross within 0.2 reach of the tag, from directions 22.5 deg apart."""
    star = StarPasses(150.0)
    tag = np.array([300.0, -100.0])
    xy = np.array([0.0, 0.0])
    dists, headings = [], []
    for _ in range(3000):
        h = star.heading("T1", xy, tag)
        headings.append(h)
        xy = xy + 1.0 * np.array([math.sin(math.radians(h)), math.cos(math.radians(h))])
        dists.append(float(np.hypot(*(xy - tag))))
    d = np.array(dists[500:])
    assert d.min() < 0.2 * 150.0 + 2.0 and d.max() < 150.0 + 2.0
    assert len({round(x) for x in headings[500:]}) > 8  # many directions
    first = star.heading("T2", np.array([0.0, 0.0]), np.array([0.0, 100.0]))
    assert first == pytest.approx(0.0)  # a new tag: straight over it from here


def test_cli_finish_and_an_oracle(tmp_path) -> None:
    import json

    from mexgen_gcs.cli import main
    from mexgen_gcs.experiments.store import read_rows

    assert main(["experiment", "localise", "--model", "static", "--reality", "field",
                 "--estimator", "robust", "--methods", "mexgen,oraclestar100", "--finish",
                 "--quick", "--starts", "1", "--reps", "1", "--workers", "1", "--out",
                 str(tmp_path)]) == 0
    ident = json.loads((tmp_path / "experiment.json").read_text())
    assert ident["format"] == 5 and ident["settings"]["static"]["finish"] is True
    assert "--finish" in (tmp_path / "commands.log").read_text()
    assert {r["method"] for r in read_rows(tmp_path)} == {"mexgen", "oraclestar100"}
    summary = (tmp_path / "summary.md").read_text()
    assert "## Time to radius and reporting" in summary and "Oracle star 100 m" in summary
    assert "Reporting (`--finish`)" in summary


def test_altitude_actions_fly_between_the_bounds_and_are_reproducible() -> None:
    """``min_alt_m`` (``experiment --min-alt``): the point mass follows the planner's chosen
    altitude, never below the bound nor above the search altitude; same seed, same run."""
    sc = _short(False, min_alt_m=20.0)
    a = run_one(RunSpec(sc, "mexgen", 3, 0, 0))
    alt = a.series["vehicle_alt_m"]
    assert alt.min() < 30.0, "never descended"
    assert alt.min() >= 20.0 - 1e-3 and alt.max() <= sc.alt_m + 1e-3
    b = run_one(RunSpec(sc, "mexgen", 3, 0, 0))
    np.testing.assert_array_equal(alt, b.series["vehicle_alt_m"])
    held = run_one(RunSpec(_short(False), "mexgen", 3, 0, 0)).series["vehicle_alt_m"]
    assert np.all(held == np.float32(sc.alt_m))


def test_cli_min_alt(tmp_path, capsys) -> None:
    import json

    from mexgen_gcs.cli import main

    base = ["experiment", "localise", "--model", "static", "--quick", "--starts", "1", "--reps",
            "1", "--workers", "1", "--methods", "mexgen"]
    assert main([*base, "--min-alt", "60", "--out", str(tmp_path / "bad")]) == 2
    assert "--min-alt must be below the search altitude 50 m" in capsys.readouterr().err
    assert not (tmp_path / "bad" / "runs.csv").exists()
    assert main([*base, "--min-alt", "20", "--out", str(tmp_path / "ok")]) == 0
    ident = json.loads((tmp_path / "ok" / "experiment.json").read_text())
    assert ident["settings"]["static"]["min_alt_m"] == 20.0
    assert "--min-alt 20" in (tmp_path / "ok" / "commands.log").read_text()
