"""Guidance and safety rules (pure functions, one layer)."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.guidance import altitude_rate_m_s, stopping_point, velocity_setpoint
from mexgen_gcs.io.vehicle import Telemetry
from mexgen_gcs.mission.commander import Expectation, judge
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


def test_stopping_point_adds_reaction_and_braking_distance():
    p = stopping_point(np.array([0.0, 0.0]), np.array([10.0, 0.0]), 3.0, 0.5)
    np.testing.assert_allclose(p, [5.0 + 100.0 / 6.0, 0.0])


def test_guard_acts_on_the_stopping_point_before_the_edge():
    """Flying east at 10 m/s, 485 m east of centre (15 m inside): 0.3 s of latency and
    braking at 3 m/s^2 take 19.7 m, so it turns now, while still inside."""
    sp = velocity_setpoint(90.0, 10.0, (485.0, 0.0), 50.0, 50.0, AREA, 90.0, (10.0, 0.0))
    assert sp.reason in ("edge", "guard") and sp.v_east_m_s < 5.0
    slow = velocity_setpoint(90.0, 2.0, (485.0, 0.0), 50.0, 50.0, AREA, 90.0, (2.0, 0.0))
    assert slow.reason == "fly"  # 1.3 m to stop: fine
    outside = velocity_setpoint(90.0, 10.0, (700.0, 0.0), 50.0, 50.0, AREA, 90.0, (0.0, 0.0))
    assert outside.reason == "guard" and outside.v_east_m_s < -9.0  # back toward the centre


def test_a_heading_out_of_the_area_slides_along_the_edge():
    """1 m inside the east edge, creeping east, the planner still wants east and the next
    setpoint comes in 0.5 s: the nearest heading whose stop stays inside is flown instead
    (along the edge, away from it), not the planner's."""
    sp = velocity_setpoint(90.0, 10.0, (499.0, 0.0), 50.0, 50.0, AREA, 90.0, (1.0, 0.0),
                           period_s=0.5)
    assert sp.reason == "edge"
    assert sp.v_east_m_s < 0.0 and abs(sp.v_north_m_s) > 5.0
    ok = velocity_setpoint(270.0, 10.0, (499.0, 0.0), 50.0, 50.0, AREA, 90.0, (1.0, 0.0),
                           period_s=0.5)
    assert ok.reason == "fly"


def test_guidance_keeps_a_simulated_flight_inside_the_area():
    """A point mass with PX4's acceleration limit, commanded every 0.5 s (reaction), chasing
    headings that keep pointing out of the area: it never leaves the area."""
    rng = np.random.default_rng(0)
    xy, v = np.array([0.0, 0.0]), np.array([0.0, 0.0])
    dt, worst = 0.05, 0.0
    heading = 45.0
    sp = velocity_setpoint(heading, 12.0, tuple(xy), 50.0, 50.0, AREA, 0.0, tuple(v))
    for k in range(20_000):
        if k % 10 == 0:  # a new setpoint every 0.5 s, acting at once
            if k % 400 == 0:
                heading = float(rng.uniform(0, 360))
            sp = velocity_setpoint(heading, 12.0, tuple(xy), 50.0, 50.0, AREA, 0.0, tuple(v),
                                   latency_s=0.0, period_s=0.5)
        want = np.array([sp.v_east_m_s, sp.v_north_m_s])
        dv = want - v
        n = np.linalg.norm(dv)
        v_new = v + (dv if n <= 3.0 * dt else dv / n * 3.0 * dt)
        xy = xy + 0.5 * (v + v_new) * dt
        v = v_new
        worst = max(worst, float(AREA.distance_outside_m(xy)))
    assert worst < 0.1  # the simulation's 50 ms steps against the model's exact ramps


@pytest.mark.parametrize(("mode", "armed", "seen", "in_grace", "takeover"), [
    ("OFFBOARD", True, True, False, False),
    ("HOLD", True, True, True, False),       # the change is still landing
    ("HOLD", True, True, False, True),       # geofence hold
    ("POSCTL", True, True, True, True),      # a pilot, even during the grace
    ("RETURN_TO_LAUNCH", True, True, False, True),
    ("UNKNOWN", True, False, False, False),  # no mode yet, before it is seen armed
    ("UNKNOWN", True, True, False, True),    # in flight: a mode MAVSDK cannot name
    ("OFFBOARD", False, True, False, True),  # disarmed in flight
    ("OFFBOARD", False, False, False, False),  # never seen armed yet: telemetry lags
])
def test_takeover_judgement(mode, armed, seen, in_grace, takeover):
    exp = Expectation(frozenset({"OFFBOARD"}), frozenset({"HOLD", "TAKEOFF"}),
                      grace_until_mono=10.0)
    now = 5.0 if in_grace else 20.0
    tel = Telemetry(flight_mode=mode, armed=armed)
    assert (judge(exp, tel, seen, now) is not None) == takeover
    assert judge(None, tel, seen, now) is None  # nothing expected (on the ground)


def test_predicted_excursion_is_its_kinematics():
    """The compiled guard equals its equations (module docstring) written with numpy."""
    from mexgen_gcs.core.guidance import predicted_excursion_m

    area = SearchArea.rectangle(-200.0, 200.0, -150.0, 150.0)
    rng = np.random.default_rng(3)
    for _ in range(50):
        xy, v = rng.uniform(-250, 250, 2), rng.uniform(-15, 15, 2)
        u = np.vstack([rng.uniform(-15, 15, (8, 2)), v, np.zeros(2)])  # incl. no change, stop
        p0 = xy + v * 0.3
        d = u - v
        gap = np.linalg.norm(d, axis=-1, keepdims=True)
        unit = np.divide(d, gap, out=np.zeros_like(d), where=gap > 1e-9)
        ramp = np.minimum(gap / 3.0, 0.05)
        v1 = v + unit * 3.0 * ramp
        p1 = p0 + v * ramp + 0.5 * unit * 3.0 * ramp**2 + v1 * (0.05 - ramp)
        stop = stopping_point(p1, v1, 3.0, 0.0)
        want = np.maximum(area.distance_outside_m(p1), area.distance_outside_m(stop))
        got = predicted_excursion_m(area, xy, v, u, 3.0, 0.3, 0.05)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
