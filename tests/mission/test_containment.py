"""Failure containment: one fault per branch, each against the fake vehicle port, each ending in
its phase's documented safe action with a `result` record (see mission/controller.py):
preflight -> nothing armed; takeoff and search -> return to launch; return -> re-command once;
signals -> return and land; log I/O errors, dead terminals, late planners -> the flight goes on.
The fake's invariant holds in every test: never in offboard without a setpoint for > 1 s.
"""

from __future__ import annotations

import errno
import itertools
import sys
import threading
import time

import pytest

from mexgen_gcs.io.plans import MissionPlanner
from mexgen_gcs.mission import views
from tests.mission.fake_flight import fly, make_mission
from tests.mission.fake_vehicle import FakeVehicle, Scripted


def _vehicle(*script: Scripted, **kw) -> FakeVehicle:
    return FakeVehicle(make_mission().local_frame(), script=list(script), **kw)


def _names(fake: FakeVehicle) -> list[str]:
    return [c.name for c in fake.commands]


def _returned(f, reason: str, *, error: str | None = None) -> None:
    """The search/takeoff safe action: return to launch, landed, exit 1, a result record."""
    assert f.result.end_reason == reason, f.result.events[-12:]
    assert f.result.exit_code == 1
    rec = f.result_record
    assert rec["end_reason"] == reason and rec["exit_code"] == 1
    if error is not None:
        assert error in (rec["error"] or ""), rec["error"]
    assert "return_to_launch" in _names(f.vehicle)
    assert "landed_and_disarmed" in f.kinds()
    assert f.vehicle.offboard_violations == []


# -- signals ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("signal", "reason"), [("signal:SIGHUP", "signal_sighup"),
                                                ("signal:SIGTERM", "signal_sigterm"),
                                                ("abort", "operator_abort")])
async def test_signals_return_the_vehicle_and_land(tmp_path, signal, reason):
    f = await fly(tmp_path / "log", requests=(("offboard", 8.0, signal),))
    _returned(f, reason)


# -- search: exceptions anywhere -> return to launch --------------------------------------------


async def test_an_exception_in_the_telemetry_stream_returns(tmp_path):
    fake = _vehicle(Scripted("offboard", 8.0, lambda v: v.raise_in_telemetry(
        RuntimeError("stream broke"))))
    f = await fly(tmp_path / "log", fake)
    _returned(f, "error", error="RuntimeError: stream broke")
    assert fake.telemetry_runs >= 2  # restarted so the landing could be watched
    assert f.events("fault")[0]["where"] == "telemetry"


async def test_an_exception_in_the_planner_returns(tmp_path, monkeypatch):
    def broken(self, request, method, rng):
        raise IndexError("planner bug")

    monkeypatch.setattr(MissionPlanner, "plan", broken)
    f = await fly(tmp_path / "log")
    _returned(f, "error", error="IndexError: planner bug")


async def test_a_log_write_bug_returns(tmp_path):
    """A value the log cannot take (TypeError, a bug) is a fault like any other."""
    class Buggy:
        def __init__(self, real):
            self.real, self.armed = real, False

        def write(self, type, **fields):
            if type == "setpoint" and self.armed:
                raise TypeError("cannot write a Foo to a flight log")
            if type == "event" and fields.get("kind") == "offboard_started":
                self.armed = True
            return self.real.write(type, **fields)

    f = await fly(tmp_path / "log", wrap_log=Buggy)
    _returned(f, "error", error="TypeError")


# -- degraded, never stopped --------------------------------------------------------------------


async def test_a_full_disk_loses_records_not_the_flight(tmp_path):
    """Writes fail with ENOSPC for a while: counted, warned, and the flight goes on; once the
    disk has room again a log_loss record says how many were lost."""
    class FullDisk:
        def __init__(self, real):
            self.real, self.full_from, self.full_until = real, None, None

        def write(self, type, **fields):
            now = time.monotonic()
            if type == "event" and fields.get("kind") == "offboard_started":
                self.full_from, self.full_until = now + 0.2, now + 1.5
            if self.full_from is not None and self.full_from <= now < self.full_until:
                raise OSError(errno.ENOSPC, "No space left on device")
            return self.real.write(type, **fields)

    f = await fly(tmp_path / "log", wrap_log=FullDisk, requests=(("offboard", 30.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl" and f.result.error is None
    lost = f.result.counters["log_records_lost"]
    assert lost > 10
    loss = [r for r in f.records if r["type"] == "log_loss"]
    assert loss and loss[0]["lost"] == lost
    assert "landed_and_disarmed" in f.kinds() and f.vehicle.offboard_violations == []


async def test_a_dead_terminal_never_stops_the_flight(tmp_path, monkeypatch):
    class DeadTerminal:
        def write(self, text):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    from mexgen_gcs.mission.controller import ControllerOptions

    monkeypatch.setattr(sys, "stdout", DeadTerminal())
    opts = ControllerOptions(connect_timeout_s=5, ready_timeout_s=5, radio_wait_s=5,
                             clock_wait_s=5, landing_timeout_s=300, print_progress=True,
                             headless_progress_s=0.2)
    f = await fly(tmp_path / "log", options=opts, requests=(("offboard", 20.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl" and f.result.error is None
    assert "progress_output_lost" in f.kinds()
    assert "landed_and_disarmed" in f.kinds()


async def test_a_failing_view_never_stops_the_flight(tmp_path, monkeypatch):
    def broken(ctx):
        raise KeyError("a view bug")

    monkeypatch.setattr(views, "build_snapshot", broken)
    f = await fly(tmp_path / "log", requests=(("offboard", 15.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl" and f.result.error is None
    assert f.result.counters["snapshot_failures"] > 3


async def test_a_late_planner_is_skipped_never_queued(tmp_path, monkeypatch):
    """Each plan takes 1.5 s of wall time, the interval is 0.25 s (5 s of vehicle time at
    20x): due plans are skipped while one runs, the worker never has a queue, the vehicle
    holds meanwhile."""
    running = []
    overlaps = []
    calls = []
    real = MissionPlanner.plan

    def slow(self, request, method, rng):
        running.append(1)
        overlaps.append(len(running))
        calls.append(time.monotonic())
        try:
            time.sleep(1.5)
            return real(self, request, method, rng)
        finally:
            running.pop()

    monkeypatch.setattr(MissionPlanner, "plan", slow)
    t0 = time.monotonic()
    f = await fly(tmp_path / "log", requests=(("offboard", 40.0, "rtl"),))
    wall = time.monotonic() - t0
    assert f.result.end_reason == "operator_rtl" and f.result.error is None
    assert max(overlaps) == 1  # never two at once: nothing queued behind a late plan
    gaps = [b - a for a, b in itertools.pairwise(calls)]
    assert all(g >= 1.45 for g in gaps), gaps  # a new plan only once the last one finished
    assert f.result.counters["plans_skipped"] >= 4
    assert "plan_skipped" in f.kinds() and "planner_overrun" in f.kinds()
    assert len(calls) < wall / 1.5 + 2
    held = [r for r in f.records if r["type"] == "setpoint" and r["reason"] == "hold"]
    assert held
    assert threading.active_count() < 50


async def test_a_stalled_loop_restarts_the_plan_schedule_without_a_double_plan(tmp_path):
    """The event loop blocked for 0.5 s of wall time (10 s of vehicle time at 20x): the
    planner plans once when it wakes and the next one an interval later, not at once for
    the tick it missed (a CI run on a busy machine planned twice 0.26 s apart)."""
    stall = Scripted("offboard", 20.0, lambda v: time.sleep(0.5))
    f = await fly(tmp_path / "log", _vehicle(stall), requests=(("offboard", 45.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl" and f.result.error is None
    plan_t = [r["t"] for r in f.records if r["type"] == "plan"]
    gaps = [b - a for a, b in itertools.pairwise(plan_t)]
    assert max(gaps) > 8.0, gaps  # the stall happened between two plans
    assert min(gaps) > 4.0, gaps


# -- the operator's land ------------------------------------------------------------------------


async def test_the_operators_land_is_never_overridden_by_a_return(tmp_path):
    """Land asked during the search; then the telemetry stream fails during the descent:
    the safe action re-commands the LAND, not a return."""
    fake = _vehicle(Scripted("offboard", 9.0, lambda v: v.raise_in_telemetry(
        RuntimeError("stream broke while landing"))))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 8.0, "land"),))
    assert f.result.end_reason == "operator_land"
    names = _names(fake)
    assert "return_to_launch" not in names and names.count("land") >= 1
    assert "landed_and_disarmed" in f.kinds() and fake.offboard_violations == []


# -- preflight: nothing armed -------------------------------------------------------------------


async def test_a_preflight_exception_ends_on_the_ground(tmp_path):
    fake = _vehicle(fail_with={"wait_ready": RuntimeError("health stream bug")})
    f = await fly(tmp_path / "log", fake)
    assert f.result.end_reason == "error" and f.result.exit_code == 1
    assert "RuntimeError: health stream bug" in f.result_record["error"]
    assert "arm" not in _names(fake)


async def test_a_vehicle_home_far_from_the_area_refuses_to_arm(tmp_path):
    fake = _vehicle(home_en_m=(3000.0, 0.0))
    f = await fly(tmp_path / "log", fake)
    assert f.result.end_reason == "home_too_far_from_area" and f.result.exit_code == 1
    assert f.result_record["end_reason"] == "home_too_far_from_area"
    assert "arm" not in _names(fake) and "upload_geofence" not in _names(fake)


async def test_a_home_mismatch_warns_and_heights_come_from_the_vehicle(tmp_path, capsys):
    """The vehicle armed 60 m from the mission's home, 100 m AMSL, home.alt_m says 0: both
    warned (event and stderr); the receiver's height is the vehicle's height above ITS home
    (the mission altitude, 20 m), not 100 + 20 m."""
    fake = _vehicle(home_en_m=(60.0, 0.0), home_alt_amsl_m=100.0)
    f = await fly(tmp_path / "log", fake, overrides={"home.alt_m": 0.0},
                  requests=(("offboard", 12.0, "rtl"),), receiver_kw={"tag_en_m": (100.0, 50.0)})
    kinds = f.kinds()
    assert "home_mismatch" in kinds and "home_alt_mismatch" in kinds
    assert "WARNING: home.alt_m = 0 m but the vehicle's home is at 100.0 m" in (
        capsys.readouterr().err)
    dets = [r for r in f.records if r["type"] == "detection" and r.get("rx_en_m")]
    assert dets
    heights = [r["rx_en_m"][2] for r in dets]
    assert max(heights) < 25.0 and max(heights) > 15.0
    fence = f.events("geofence_uploaded")[0]["fence_en_m"]
    assert max(x for x, _ in fence) >= 350.0  # the area (300 m) plus the 50 m margin


# -- takeoff and return -------------------------------------------------------------------------


async def test_a_failed_takeoff_returns(tmp_path):
    fake = _vehicle(fail={"takeoff": 1})
    f = await fly(tmp_path / "log", fake)
    assert f.result.end_reason == "vehicle_error" and f.result.exit_code == 1
    assert "takeoff" in (f.result_record["error"] or "")
    assert "return_to_launch" in _names(fake)  # armed on the ground: RTL disarms it
    assert "landed_and_disarmed" in f.kinds()


async def test_a_refused_return_is_retried_while_holding(tmp_path):
    """RTL refused twice: retried, and zero-velocity setpoints keep offboard alive meanwhile."""
    fake = _vehicle(fail={"return_to_launch": 2})
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 8.0, "rtl"),))
    assert _names(fake).count("return_to_launch") == 3
    assert len(f.events("rtl_failed")) == 2
    assert "landed_and_disarmed" in f.kinds() and fake.offboard_violations == []


async def test_a_fault_during_the_return_recommands_it_once(tmp_path):
    fake = _vehicle(Scripted("offboard", 12.0, lambda v: v.raise_in_telemetry(
        RuntimeError("stream broke on the way home"))))
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 8.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl"
    assert _names(fake).count("return_to_launch") == 2
    assert "return_recommanded" in f.kinds() and "landed_and_disarmed" in f.kinds()
    assert "stream broke on the way home" in f.result_record["error"]


async def test_a_refused_setpoint_stream_is_not_fatal(tmp_path):
    fake = _vehicle(fail={"set_velocity_ned": 5})
    f = await fly(tmp_path / "log", fake, requests=(("offboard", 12.0, "rtl"),))
    assert f.result.end_reason == "operator_rtl"
    assert "setpoint_failed" in f.kinds() and "landed_and_disarmed" in f.kinds()


async def test_an_abort_during_the_preflight_wait_ends_on_the_ground_at_once(tmp_path):
    """The operator aborts while the GCS waits for a radio that never comes: the wait ends
    at once, nothing is armed."""
    from mexgen_gcs.mission.controller import ControllerOptions

    fake = _vehicle()
    opts = ControllerOptions(connect_timeout_s=5, ready_timeout_s=5, radio_wait_s=30,
                             clock_wait_s=5, print_progress=False)
    t0 = time.monotonic()
    f = await fly(tmp_path / "log", fake, options=opts, receiver_kw={"silent": True},
                  requests=(("start", 40.0, "abort"),))
    assert time.monotonic() - t0 < 15.0
    assert f.result.end_reason == "operator_abort" and f.result.exit_code == 1
    assert "arm" not in _names(fake) and f.result_record["end_reason"] == "operator_abort"
