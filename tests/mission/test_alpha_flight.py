"""Every Renyi order the configuration accepts flies: the fake mission (a tag heard from the
first plan on, 333 planning particles so the planner pads the particle axis) searches with
alpha 0.5, 2 and 5, every plan has finite rewards and the operator's return ends it."""

from __future__ import annotations

import math

import pytest

from tests.mission.fake_flight import fly


@pytest.mark.long  # three in-process flights of 25 s (the planner kernel is tested fast in
# tests/core/test_planner_alpha.py)
@pytest.mark.parametrize("alpha", [0.5, 2.0, 5.0])
async def test_the_mission_plans_and_flies_with_any_alpha(tmp_path, alpha):
    f = await fly(tmp_path / "log", overrides={"planner.alpha": alpha,
                                               "planner.n_particles": 333},
                  requests=(("offboard", 25.0, "rtl"),),
                  receiver_kw={"tag_en_m": (100.0, 50.0)})
    assert f.result.end_reason == "operator_rtl", f.result.events[-12:]
    assert "fault" not in f.kinds() and "flight_error" not in f.kinds()
    plans = [r for r in f.records if r["type"] == "plan"]
    assert len(plans) >= 3
    for p in plans:
        assert all(r is not None and math.isfinite(r) for r in p["rewards"]), p["rewards"]
    assert any(max(p["rewards"]) > 0.0 for p in plans)
    assert "landed_and_disarmed" in f.kinds()
