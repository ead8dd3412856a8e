"""The autopilot outranks the GCS: every takeover branch against the fake vehicle port.

Each test ends in the documented safe action (no command or setpoint after the takeover,
landed and disarmed by the autopilot or pilot, end reason autopilot_takeover, exit 1, a
`result` record) and the fake's invariant holds: never in offboard without a setpoint > 1 s.
"""

from __future__ import annotations

import pytest

from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle, Scripted


def _vehicle(*script: Scripted, **kw) -> FakeVehicle:
    return FakeVehicle(make_mission().local_frame(), script=list(script), **kw)


def _assert_takeover(f, mode: str, reason_part: str) -> None:
    assert f.result.end_reason == "autopilot_takeover", f.result.events[-12:]
    assert f.result.exit_code == 1
    takeover = f.events("takeover")
    assert takeover and takeover[0]["mode"] == mode, takeover
    assert reason_part in takeover[0]["reason"], takeover[0]
    rec = f.result_record
    assert rec["end_reason"] == "autopilot_takeover" and rec["takeover"]["mode"] == mode
    assert f.vehicle.commands_after_takeover() == []  # never commanded again
    assert f.vehicle.offboard_violations == []
    assert "landed_and_disarmed" in f.kinds()


@pytest.mark.parametrize(("mode", "text", "reason_part"), [
    ("HOLD", "Geofence breached", "Geofence breached"),           # GF_ACTION = hold
    ("POSCTL", None, "set by a pilot"),                           # the RC mode switch
    ("ALTCTL", None, "set by a pilot"),
    ("RETURN_TO_LAUNCH", "Failsafe: battery critical", "battery critical"),
    ("LAND", "Failsafe: emergency land", "emergency land"),
])
async def test_a_mode_the_gcs_did_not_command_stops_every_command(tmp_path, mode, text,
                                                                   reason_part):
    fake = _vehicle(Scripted("offboard", 20.0, lambda v: v.set_mode(mode, text)),
                    Scripted("offboard", 35.0, lambda v: v.set_mode("LAND")))
    f = await fly(tmp_path / "log", fake)
    _assert_takeover(f, mode, reason_part)
    # setpoints stopped at once: none reached the vehicle once it had left offboard
    assert sum(n for m, n in fake.setpoints_by_mode.items() if m != "OFFBOARD") == 0
    assert f.result.counters["setpoints"] >= 15  # 1 s of wall time at 20 Hz
    # every STATUSTEXT is logged as a record
    texts = [r["text"] for r in f.records if r["type"] == "statustext"]
    assert "Armed" in texts and (text is None or text in texts)


async def test_disarm_in_flight_is_a_takeover(tmp_path):
    fake = _vehicle(Scripted("offboard", 8.0, lambda v: v.disarm_in_flight()))
    f = await fly(tmp_path / "log", fake)
    _assert_takeover(f, "OFFBOARD", "kill switch")
    assert f.events("takeover")[0]["armed"] is False


async def test_no_rule_commands_after_a_takeover(tmp_path):
    """Battery low and the mission time limit come after the pilot took over: neither
    commands a return (the pilot has the vehicle)."""
    fake = _vehicle(Scripted("offboard", 5.0, lambda v: v.set_mode("POSCTL")),
                    Scripted("offboard", 8.0, lambda v: setattr(v, "battery", 5.0)),
                    Scripted("offboard", 40.0, lambda v: v.set_mode("LAND")))
    f = await fly(tmp_path / "log", fake, overrides={"safety.max_mission_time_s": 20.0})
    _assert_takeover(f, "POSCTL", "pilot")
    reasons = [e.get("reason") for e in f.events("safety")]
    assert "battery_low" not in reasons and "max_mission_time" not in reasons


async def test_takeover_during_the_climb(tmp_path):
    fake = _vehicle(Scripted("armed", 2.0, lambda v: v.set_mode("POSCTL")),
                    Scripted("armed", 12.0, lambda v: v.set_mode("LAND")))
    f = await fly(tmp_path / "log", fake)
    _assert_takeover(f, "POSCTL", "pilot")
    assert f.events("takeover")[0]["phase"] == "takeoff"
    assert "start_offboard" not in [c.name for c in fake.commands]


async def test_takeover_during_the_return_is_not_fought(tmp_path):
    """The operator ends the mission, the vehicle returns, a pilot switches to position mode
    on the way: the GCS stops commanding, keeps watching, and the pilot lands it."""
    fake = _vehicle(Scripted("offboard", 14.0, lambda v: v.set_mode("POSCTL")),
                    Scripted("offboard", 30.0, lambda v: v.set_mode("LAND")))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 10.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl" and f.result.exit_code == 1
    assert f.events("takeover")[0]["phase"] == "return"
    assert f.vehicle.commands_after_takeover() == []
    assert f.result_record["takeover"]["mode"] == "POSCTL"
    assert "landed_and_disarmed" in f.kinds()


async def test_the_operator_may_command_after_a_takeover(tmp_path):
    """After a takeover only the operator's own request commands again (Ctrl-C / UI: RTL)."""
    fake = _vehicle(Scripted("offboard", 6.0, lambda v: v.set_mode("HOLD", "Geofence breached")))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 12.0, "abort"),))
    assert f.result.end_reason == "autopilot_takeover"
    assert fake.commands_after_takeover() == ["return_to_launch"]
    assert "operator_retakes_control" in f.kinds() and "landed_and_disarmed" in f.kinds()


async def test_a_signal_after_a_takeover_ends_the_wait_without_commanding(tmp_path):
    fake = _vehicle(Scripted("offboard", 6.0, lambda v: v.set_mode("POSCTL")))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 12.0, "signal:SIGHUP"),))
    assert f.result.end_reason == "autopilot_takeover" and f.result.exit_code == 1
    assert fake.commands_after_takeover() == []
    assert "stopped_waiting" in f.kinds()
    assert f.result_record["exit_code"] == 1


async def test_offboard_loss_from_a_link_drop_is_not_a_takeover(tmp_path):
    """PX4 holds when our setpoints stop arriving (a dropped link): the link rules resume."""
    fake = _vehicle(Scripted("offboard", 8.0, lambda v: v.drop_link(2.0)))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 60.0, "rtl"),))
    kinds = f.kinds()
    assert "takeover" not in kinds, f.result.events[-15:]
    assert "offboard_resumed" in kinds
    assert f.result.end_reason == "operator_rtl" and "landed_and_disarmed" in kinds
