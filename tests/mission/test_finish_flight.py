"""A mission that ends usefully, flown in process against the fake vehicle and receiver: a tag
that cannot reach the radius is reported when its budget is spent, the vehicle returns, lands,
exit 0, and the flight log's result and tag_reported records say why, with the radius over
time."""

from __future__ import annotations

import math

from tests.mission.fake_flight import fly


async def test_an_unreachable_radius_ends_with_every_tag_reported(tmp_path):
    # the fake mission's 0.5 m radius is never reached; the budget reports the tag at 20 s
    f = await fly(tmp_path / "log", overrides={"localisation.tag_budget_s": 20.0,
                                               "localisation.stall_window_s": None})
    assert f.result.end_reason == "all_reported", f.result.events[-12:]
    assert f.result.exit_code == 0
    rec = f.result_record
    assert rec["end_reason"] == "all_reported" and rec["localised"] == {}
    rep = rec["reports"]["T1"]  # read back as the typed TagReport
    assert rep.reason == "budget" and rep.worked_s >= 20.0
    assert 19.0 <= rep.after_s <= 25.0 and math.isfinite(rep.radius_m)
    curve = rep.radius_over_time
    assert len(curve) >= 3 and curve[0][0] < curve[-1][0]
    assert any(abs(a - round(rep.after_s, 1)) < 1e-6 for a, _ in curve)  # the report's sample
    reported = [r for r in f.records if r["type"] == "tag_reported"]
    assert len(reported) == 1 and reported[0]["tag"] == "T1"
    assert reported[0]["reason"] == "budget"
    assert reported[0]["radius_m"] == rep.radius_m
    assert "tag_reported" in f.kinds()
    # reported before the return: the last search setpoint precedes the result
    assert f.controller.ctx.core.reported["T1"].reason == "budget"

    # analyze: the tags table says why and when the tag was reported
    from mexgen_gcs.analysis import load_flight, summarise
    from mexgen_gcs.analysis.report import write_report

    flight = load_flight(tmp_path / "log")
    (tag,) = summarise(flight).tags
    assert tag.reported_reason == "budget" and tag.reported_radius_m == rep.radius_m
    report = write_report(flight, tmp_path / "report")
    text = report.markdown.read_text(encoding="utf-8")
    assert f"budget @ {rep.after_s:.1f} s" in text

    # the mission summary printed at the end says it too
    from mexgen_gcs.mission.run import summary_text

    line = next(x for x in summary_text(f.result).splitlines() if x.strip().startswith("T1:"))
    assert "not localised" in line and f"reported budget after {rep.after_s:.0f} s" in line
