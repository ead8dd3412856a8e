"""Preflight refusals for the vehicle's set-up, against the fake vehicle port: a geofence the
vehicle refuses (a standing warning, or with safety.require_geofence a refusal to arm, exit 2),
unsafe PX4 parameters (exit 2 naming the parameter, unless accepted) and a fence another
station left on the vehicle (shown; replaced only with safety.replace_existing_geofence).
Nothing is armed in any refusal."""

from __future__ import annotations

from mexgen_gcs.mission import views
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle

PILOT_FENCE = [(-34.92, 138.60), (-34.92, 138.61), (-34.91, 138.61)]


def _vehicle(**kw) -> FakeVehicle:
    return FakeVehicle(make_mission().local_frame(), **kw)


def _names(fake: FakeVehicle) -> list[str]:
    return [c.name for c in fake.commands]


def _warnings(f) -> list[dict]:
    return [r for r in f.records if r["type"] == "warning"]


def _refused_before_arming(f, reason: str) -> None:
    assert f.result.end_reason == reason, f.result.events[-8:]
    assert f.result.exit_code == 2
    assert f.result_record["end_reason"] == reason and f.result_record["exit_code"] == 2
    assert "arm" not in _names(f.vehicle) and not f.vehicle.armed


async def test_a_refused_fence_is_a_standing_warning(tmp_path, capsys):
    fake = _vehicle(fail={"upload_geofence": 1})
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 5.0, "rtl"),))
    (warning,) = [w for w in _warnings(f) if w["kind"] == "geofence_not_accepted"]
    assert "did not take the geofence" in warning["text"]
    assert "WARNING: the vehicle did not take the geofence" in capsys.readouterr().err
    assert "arm" in _names(fake)  # flies without it
    assert "NO GEOFENCE ON THE VEHICLE" in views.build_snapshot(f.controller.ctx).warnings


async def test_a_refused_fence_with_require_geofence_refuses_to_arm(tmp_path, capsys):
    fake = _vehicle(fail={"upload_geofence": 1})
    f = await fly(tmp_path / "log", fake, overrides={"safety.require_geofence": True})
    _refused_before_arming(f, "geofence_refused")
    err = capsys.readouterr().err
    assert "REFUSED: the vehicle did not take the geofence" in err
    assert "safety.require_geofence is true" in err


async def test_unsafe_params_refuse_to_arm_naming_the_parameter(tmp_path, capsys):
    fake = _vehicle()
    fake.params.update(NAV_DLL_ACT=0.0, GF_ACTION=0.0)
    f = await fly(tmp_path / "log", fake)
    _refused_before_arming(f, "vehicle_params_unsafe")
    assert "upload_geofence" not in _names(fake)
    err = capsys.readouterr().err
    assert "REFUSED: PX4 NAV_DLL_ACT = 0 Disabled" in err and "NAV_DLL_ACT = 2 (Return)" in err
    assert "REFUSED: PX4 GF_ACTION = 0 None" in err and "GF_ACTION = 2 (Hold)" in err
    (failed,) = f.events("preflight_failed")
    assert failed["params"] == ["NAV_DLL_ACT", "GF_ACTION"]


async def test_accepted_params_fly_with_a_warning(tmp_path):
    fake = _vehicle()
    fake.params.update(NAV_DLL_ACT=0.0)
    f = await fly(tmp_path / "log", fake, overrides={"safety.accept_px4_params": ["NAV_DLL_ACT"]},
                  requests=(("offboard", 5.0, "rtl"),))
    assert "arm" in _names(fake)
    texts = [w["text"] for w in _warnings(f) if w["kind"] == "vehicle_param"]
    assert any(t.startswith("PX4 NAV_DLL_ACT = 0 Disabled") and t.endswith("(accepted)")
               for t in texts)
    assert f.events("vehicle_params")[0]["accepted"] == ["NAV_DLL_ACT"]


async def test_a_fence_on_the_vehicle_is_shown_and_not_replaced(tmp_path, capsys):
    fake = _vehicle(existing_fence=PILOT_FENCE)
    f = await fly(tmp_path / "log", fake)
    _refused_before_arming(f, "geofence_on_vehicle")
    assert "upload_geofence" not in _names(fake)
    err = capsys.readouterr().err
    assert "REFUSED: the vehicle already holds a geofence of 1 shape(s)" in err
    assert "-34.920000, 138.600000" in err
    assert "safety.replace_existing_geofence: true" in err


async def test_a_fence_on_the_vehicle_is_replaced_when_the_mission_says_so(tmp_path):
    fake = _vehicle(existing_fence=PILOT_FENCE)
    f = await fly(tmp_path / "log", fake, overrides={"safety.replace_existing_geofence": True},
                  requests=(("offboard", 5.0, "rtl"),))
    (warning,) = [w for w in _warnings(f) if w["kind"] == "geofence_replaced"]
    assert warning["shapes"] == [[list(p) for p in PILOT_FENCE]]
    assert "upload_geofence" in _names(fake) and fake.fence != PILOT_FENCE


async def test_this_missions_own_fence_from_an_earlier_flight_is_replaced_silently(tmp_path):
    """A second flight of the same mission finds the fence the first one uploaded: no refusal."""
    first = _vehicle()
    await fly(tmp_path / "first", first, requests=(("offboard", 3.0, "rtl"),))
    assert first.fence is not None
    again = _vehicle(existing_fence=first.fence)
    f = await fly(tmp_path / "again", again, requests=(("offboard", 3.0, "rtl"),))
    assert f.events("geofence_on_vehicle_is_ours") and "arm" in _names(again)
    assert not [w for w in _warnings(f) if w["kind"].startswith("geofence")]
