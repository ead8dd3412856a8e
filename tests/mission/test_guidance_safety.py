"""Guidance and safety rules (pure functions, one layer)."""

import math

import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.mission.guidance import altitude_rate_m_s, velocity_setpoint
from mexgen_gcs.mission.safety import Action, SafetyInputs, SafetyLimits, decide

AREA = SearchArea.rectangle(-500, 500, -500, 500)


def test_heading_becomes_ned_velocity_and_yaw():
    sp = velocity_setpoint(45.0, 10.0, (0.0, 0.0), 50.0, 50.0, AREA, 0.0)
    assert sp.v_north_m_s == pytest.approx(10 / math.sqrt(2))
    assert sp.v_east_m_s == pytest.approx(10 / math.sqrt(2))
    assert sp.yaw_deg == 45.0 and sp.v_down_m_s == 0.0 and sp.reason == "fly"
    west = velocity_setpoint(270.0, 5.0, (0.0, 0.0), 50.0, 50.0, AREA, 0.0)
    assert west.v_east_m_s == pytest.approx(-5.0) and abs(west.v_north_m_s) < 1e-9


def test_hold_keeps_yaw_and_zero_velocity():
    sp = velocity_setpoint(None, 10.0, (0.0, 0.0), 50.0, 50.0, AREA, 123.0)
    assert (sp.v_north_m_s, sp.v_east_m_s, sp.yaw_deg, sp.reason) == (0.0, 0.0, 123.0, "hold")


def test_guard_steers_back_inside_whatever_the_plan():
    sp = velocity_setpoint(90.0, 10.0, (700.0, 0.0), 50.0, 50.0, AREA, 90.0)
    assert sp.reason == "guard" and sp.v_east_m_s == pytest.approx(-10.0)
    held = velocity_setpoint(None, 10.0, (0.0, 650.0), 50.0, 50.0, AREA, 0.0)
    assert held.reason == "guard" and held.v_north_m_s == pytest.approx(-10.0)


def test_altitude_hold_sign_and_limit():
    assert altitude_rate_m_s(40.0, 50.0) < 0  # below target: climb = negative down
    assert altitude_rate_m_s(60.0, 50.0) > 0
    assert altitude_rate_m_s(0.0, 500.0) == -2.0
    assert altitude_rate_m_s(math.nan, 50.0) == 0.0


LIM = SafetyLimits(max_mission_time_s=600, battery_rtl_percent=25, link_loss_timeout_s=3,
                   on_link_regained="resume", radio_heartbeat_timeout_s=3,
                   radio_loss_timeout_s=15)
OK = SafetyInputs(elapsed_s=10, battery_percent=90, link_age_s=0.1, link_connected=True,
                  radio_silent_s=0.5, link_was_lost=False)



def _inp(**kw):
    fields = {f: getattr(OK, f) for f in OK.__slots__}
    fields.update(kw)
    return SafetyInputs(**fields)


@pytest.mark.parametrize(("change", "action", "reason"), [
    ({}, Action.NONE, "ok"),
    ({"battery_percent": 20.0}, Action.RTL, "battery_low"),
    ({"battery_percent": math.nan}, Action.NONE, "ok"),
    ({"elapsed_s": 601.0}, Action.RTL, "max_mission_time"),
    ({"link_age_s": 5.0}, Action.HOLD, "link_lost"),
    ({"link_connected": False}, Action.HOLD, "link_lost"),
    ({"link_was_lost": True}, Action.RESUME_OFFBOARD, "link_regained_resume"),
    ({"radio_silent_s": 5.0}, Action.HOLD, "radio_silent"),
    ({"radio_silent_s": 16.0}, Action.RTL, "radio_lost"),
])
def test_safety_rules(change, action, reason):
    d = decide(_inp(**change), LIM)
    assert (d.action, d.reason) == (action, reason)


def test_link_regained_rtl_policy():
    lim = SafetyLimits(**{f: getattr(LIM, f) for f in LIM.__slots__} | {"on_link_regained": "rtl"})
    assert decide(_inp(link_was_lost=True), lim).action is Action.RTL
