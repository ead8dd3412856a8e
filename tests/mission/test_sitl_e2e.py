"""End-to-end: real `python -m sim` child process, real MAVSDK over UDP loopback, real radio
datagrams, real flight logs. Each flight runs at --speedup to keep CI time reasonable."""

from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.config import CLASSIC_ESTIMATOR
from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.io.records import Record
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.mission.run import SitlPorts, run_sitl

pytestmark = pytest.mark.e2e

MISSIONS = Path(__file__).parents[2] / "missions"
SPEEDUP = 10.0
CLAIM_SLACK = 1.5
"""One flight's tags are each within this many claimed 95 % radii (see the hostile test)."""


def _events(log_dir: str) -> list[dict]:
    return [r for r in read_flight_log(log_dir).records if r["type"] in ("event", "error")]


def _kinds(log_dir: str) -> list[str]:
    return [r.get("kind", "") for r in _events(log_dir)]


def _truth(log_dir: str | Path) -> list[Record]:
    return read_truth_file(log_dir).records


def test_demo_mission_completes_under_hostile_datagrams(tmp_path):
    """All four tags localised near the truth, landed and disarmed, exit 0, while garbage is
    sprayed at the radio port: only the reject counters change.

    Near: within 1.5 times the claimed 95 % radius. Whether the claim itself holds is a rate
    (0.95-0.97 of tags in the experiments, docs/results/localisation.md), so one flight's four tags
    all inside it happen ~89 % of the time (one CI run: 50.7 m against a claim of 47.1 m);
    1.5 claims (3.7 sigma of an honest Gaussian estimate) fails an honest flight once in
    ~200 and still catches a claim that is wrong."""
    ports = SitlPorts.free()
    stop = threading.Event()
    sent: dict[str, int] = {}

    def spray() -> None:
        rnd = random.Random(0)
        payloads = {
            "bad_json": b'{"v": 1, "type": "detection", "t": ',
            "oversized": b'{"v":1,"type":"detection","pad":"' + b"x" * 3000 + b'"}',
            "rssi_nan": b'{"v": 1, "type": "detection", "t": 1.0, "tag": "T1", "rssi_db": NaN}',
            "not_utf8": b"\xff\xfe\xfd",
            "unknown_tag": None,  # needs a fresh timestamp, built below
        }
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not stop.is_set():
                reason = rnd.choice(list(payloads))
                data = payloads[reason] or json.dumps(
                    {"v": 1, "type": "detection", "t": time.time(), "tag": "ZZ",
                     "rssi_db": -40.0}).encode()
                s.sendto(data, ("127.0.0.1", ports.radio))
                sent[reason] = sent.get(reason, 0) + 1
                time.sleep(0.02)

    sprayer = threading.Thread(target=spray, daemon=True)
    sprayer.start()
    try:
        result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=SPEEDUP, ports=ports,
                          log_dir=tmp_path)
    finally:
        stop.set()
        sprayer.join()
    assert result.exit_code == 0, (result.end_reason, result.events[-10:])
    assert result.end_reason == "all_localised"
    assert set(result.localised) == {"T1", "T2", "T3", "T4"}
    for tid, info in result.localised.items():
        assert info["error_m"] <= CLAIM_SLACK * info["radius_m"], (tid, info)
    assert sum(sent.values()) > 50
    # every hostile datagram landed in a reject counter; none was taken as a detection
    for reason in ("bad_json", "rssi_nan", "not_utf8", "unknown_tag"):
        assert result.rejects.get(reason, 0) >= 1, (reason, result.rejects)
    log = read_flight_log(result.log_dir)
    assert {r["tag"] for r in log.of_type("detection")} <= {"T1", "T2", "T3", "T4"}
    # every rejection is accounted for in the log: the logged deltas add up to the counters
    logged: dict[str, int] = {}
    for rec in log.of_type("reject"):
        for reason, n in rec["counts"].items():
            logged[reason] = logged.get(reason, 0) + n
    assert logged == result.rejects
    kinds = _kinds(result.log_dir)
    assert "landed_and_disarmed" in kinds and kinds.count("tag_localised") == 4
    assert log.of_type("plan") and log.of_type("setpoint") and log.of_type("estimate")
    # the fence went up (the area plus its 50 m margin) and was never touched
    truth = _truth(result.log_dir)
    fences = [r for r in truth if r["type"] == "fence"]
    assert len(fences) == 1
    fence = np.array(fences[0]["inclusion_polygons_m"][0])
    assert fence[:, 0].min() <= -550.0 + 1e-6 and fence[:, 0].max() >= 550.0 - 1e-6
    assert fence[:, 1].min() <= -150.0 + 1e-6 and fence[:, 1].max() >= 950.0 - 1e-6
    autopilot = [r for r in truth if r["type"] == "event"]
    assert not [r for r in autopilot if "fence" in (r.get("kind", "") + r.get("text", ""))
                .lower()], autopilot
    assert "takeover" not in kinds
    # every autopilot STATUSTEXT is in the flight log, on the vehicle's clock
    texts = [r["text"] for r in log.of_type("statustext")]
    assert any(x.startswith("Armed") for x in texts) and any("Landing" in x for x in texts)
    # re-planned every 5 s of vehicle time (the simulator runs 10x)
    plan_t = np.array([r["t"] for r in log.of_type("plan")])
    gaps = np.diff(plan_t)
    assert abs(float(np.median(gaps)) - 5.0) < 0.1 and gaps.min() > 4.3, gaps


def test_moving_tag_is_followed(tmp_path):
    """A CV tag followed for 200 s from a home 350 m above sea level (receiver poses arrive
    in AMSL and must land in the home-anchored frame): the estimate closes in on the truth
    (it starts ~2 km off: the tag is anywhere in 4 km x 4 km, the vehicle flies 10 m/s) and
    its claimed radius shrinks.

    A flight is not reproducible (wall-clock timing of pulses, plans and MAVSDK), and the
    error after 200 s varies widely between runs: late medians of 179-555 m in 7 runs
    (radius 680-860 m), 215-869 m in 5 runs of the previous GCS; 390 m against a radius of
    371 m in a CI run; 816 m from 1987 m in another (a 2.4-fold improvement), 919 m from
    1746 m in another (1.9-fold). So this asserts a 1.5-fold improvement (a frame error gives
    none), not the radius's coverage:
    one flight's errors are correlated over its last minute, and whether a claimed radius
    holds is a statistical question, measured over many runs by the experiments
    (docs/results/localisation.md). The classic estimator: this tests the frames."""
    result = run_sitl(MISSIONS / "follow_cv.yaml", seed=2, speedup=SPEEDUP,
                      ports=SitlPorts.free(), log_dir=tmp_path,
                      overrides={"follow.duration_s": 200.0, "home.alt_m": 350.0,
                                 **CLASSIC_ESTIMATOR})
    assert result.end_reason == "follow_complete", result.events[-10:]
    assert result.exit_code == 0
    log = read_flight_log(result.log_dir)
    est = [r for r in log.of_type("estimate") if r["update"] == "detection"]
    assert len(est) > 60
    truth = {round(r.t): (r.x_m, r.y_m) for r in read_truth_file(result.log_dir).tags()}

    def error(r: Record) -> float:
        tx, ty = truth[round(r["t"])]
        return float(((r["east_m"] - tx) ** 2 + (r["north_m"] - ty) ** 2) ** 0.5)

    timed = [r for r in log.of_type("estimate") if round(r["t"]) in truth]
    first = error(timed[0])
    late = sorted(error(r) for r in timed if r["t"] > timed[-1]["t"] - 60)
    median = late[len(late) // 2]
    assert median < first / 1.5, (first, median, timed[-1]["radius_m"])
    assert timed[-1]["radius_m"] < timed[0]["radius_m"] / 2


def test_field_world_claims_hold(tmp_path):
    """The demo flown in the simulator's field world (every reality cause at once: transmit
    power, exponent, antenna, shadowing, fading, terrain, compass bias), a static filter: no
    tag it calls localised is grossly outside its claimed radius. Seed 2 put a tag 243 m
    from a 48 m claim (5x) while each miss counted in full (docs/results/localisation.md).

    One flight cannot assert a 95 % radius per claim: one claim in twenty may lie outside
    it, and these flights are not reproducible (the GCS and the simulator share the cores in
    real time). Seed 2 claimed 1-2 tags in 9 of 10 flights (12 claims, the first at 184-836
    s where the log was kept; none in one of 1200 s), and 1 of the 12 lay outside (52.9 m
    against 49.6 m); over seeds 0-9, 1 of 7 (59.5 m against 47.5 m, 1.25x). The coverage is
    asserted with statistics in tests/core/test_calibration.py and measured over flights
    and experiment runs in docs/results/localisation.md. The last estimates of the tags not
    localised hold for ~0.9 (a rate, not asserted per flight). Every tag is reported in bounded
    time (docs/mission-finish.md), so the flight ends by itself, home, exit 0."""
    result = run_sitl(MISSIONS / "demo.yaml", seed=2, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides={"sim.reality": "field",
                                                   "filter.motion": "static",
                                                   "safety.max_mission_time_s": 1500.0})
    # every tag reported (reached, stalled or budget: 4 x 240 s of work at most), then home:
    # exit 0 without the mission time limit
    assert result.end_reason in ("all_localised", "all_reported"), result.events[-10:]
    assert result.exit_code == 0
    assert set(result.reports) == {"T1", "T2", "T3", "T4"}
    for tid, rep in result.reports.items():
        assert rep["reason"] in ("reached", "stalled", "budget") and rep["radius_m"] > 0.0
        assert rep["worked_s"] <= 240.0 + 5.0 and rep["radius_over_time"], (tid, rep)
    for tid, info in result.localised.items():
        assert result.reports[tid]["reason"] == "reached"
        assert info["error_m"] <= 1.5 * info["radius_m"], (tid, info)
    assert len(result.localised) + len(result.unresolved) == 4
    assert all(info["radius_m"] > 0.0 for info in result.unresolved.values())


@pytest.mark.parametrize(("fault", "overrides", "expect"), [
    # PX4 (and the simulator) answers a lost offboard link with its failsafe, RTL without RC:
    # a mode the GCS did not command, so a takeover the GCS obeys (it does not resume)
    ("link_drop", {"sim.faults": [{"kind": "link_drop", "at_s": 90.0, "duration_s": 6.0}],
                   "safety.max_mission_time_s": 120.0},
     {"safety", "takeover", "landed_and_disarmed"}),
    ("radio_silence", {"sim.faults": [{"kind": "radio_silence", "at_s": 90.0,
                                       "duration_s": 600.0}],
                       "safety.radio_loss_timeout_s": 15.0},
     {"safety", "mission_end", "landed_and_disarmed"}),
    ("battery_sag", {"sim.faults": [{"kind": "battery_sag", "at_s": 90.0, "percent": 70.0}]},
     {"mission_end", "landed_and_disarmed"}),
])
def test_faults_lead_to_safe_logged_actions(tmp_path, fault, overrides, expect):
    result = run_sitl(MISSIONS / "demo.yaml", seed=4, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides=overrides)
    kinds = set(_kinds(result.log_dir))
    assert expect <= kinds, (fault, sorted(kinds))
    reasons = {e.get("reason") for e in _events(result.log_dir)}
    if fault == "link_drop":
        assert "link_lost" in reasons
        assert result.end_reason == "autopilot_takeover" and result.exit_code == 1
        assert result.takeover["mode"] == "RETURN_TO_LAUNCH"
        assert "offboard_resumed" not in kinds and "rtl_commanded" not in kinds
    elif fault == "radio_silence":
        assert "radio_silent" in reasons and result.end_reason == "radio_lost"
        assert result.exit_code == 1
    else:
        assert result.end_reason == "battery_low" and result.exit_code == 1
    assert "landed_and_disarmed" in kinds
    # every tag is either localised or left with its last estimate, scored against the truth
    assert not set(result.localised) & set(result.unresolved)
    assert len(result.localised) + len(result.unresolved) == 4
    for info in result.unresolved.values():
        assert info["radius_m"] > 0.0 and info["error_m"] >= 0.0 and 0 <= info["existence"] <= 1
    (rec,) = [r for r in read_flight_log(result.log_dir).records if r["type"] == "result"]
    assert set(rec["unresolved"]) == set(result.unresolved)


def test_bad_mission_exits_2_before_anything_moves(tmp_path):
    bad = tmp_path / "bad.yaml"
    text = (MISSIONS / "demo.yaml").read_text().replace("kind: localise", "kind: localize")
    bad.write_text(text)
    proc = subprocess.run([sys.executable, "-m", "mexgen_gcs", "sitl", str(bad), "--headless",
                           "--log-dir", str(tmp_path / "flights")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "bad.yaml" in proc.stderr and "kind" in proc.stderr
    assert not (tmp_path / "flights").exists()  # no log, no simulator, no motors


def test_sigint_returns_to_launch_then_exits(tmp_path):
    """Ctrl-C during the search: return to launch, land, exit 1, no simulator left behind."""
    import signal

    import psutil

    out = tmp_path / "flights"
    proc = subprocess.Popen(
        [sys.executable, "-m", "mexgen_gcs", "sitl", str(MISSIONS / "demo.yaml"), "--headless",
         "--speedup", "10", "--mavlink-port", "0", "--radio-port", "0", "--log-dir", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    children = []
    try:
        deadline = time.monotonic() + 60
        started = False
        while time.monotonic() < deadline and not started:
            time.sleep(0.5)
            logs = list(out.glob("*/flight.jsonl"))
            started = bool(logs) and "offboard_started" in logs[0].read_text()
        assert started, "the mission never reached offboard"
        children = psutil.Process(proc.pid).children(recursive=True)
        time.sleep(2.0)
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1
    assert "operator_abort" in stdout
    kinds = [r.get("kind") for r in read_flight_log(next(out.iterdir())).records
             if r["type"] == "event"]
    assert kinds.index("rtl_commanded") < kinds.index("landed_and_disarmed")
    assert all(not c.is_running() or c.status() == psutil.STATUS_ZOMBIE for c in children)


def _start_headless_sitl(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "mexgen_gcs", "sitl", str(MISSIONS / "demo.yaml"), "--headless",
         "--speedup", "10", "--mavlink-port", "0", "--radio-port", "0", "--log-dir", str(out),
         *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_offboard(out: Path, timeout_s: float = 60.0) -> Path:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.5)
        logs = list(out.glob("*/flight.jsonl"))
        if logs and "offboard_started" in logs[0].read_text():
            return logs[0]
    raise AssertionError("the mission never reached offboard")


def test_sighup_mid_flight_returns_lands_and_exits(tmp_path):
    """The terminal goes away (SIGHUP) during the search: return to launch, land, exit 1 with
    a result record naming the signal; no simulator left behind."""
    import signal

    import psutil

    out = tmp_path / "flights"
    proc = _start_headless_sitl(out)
    children = []
    try:
        log_file = _wait_for_offboard(out)
        children = psutil.Process(proc.pid).children(recursive=True)
        time.sleep(2.0)
        proc.send_signal(signal.SIGHUP)
        stdout, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1
    assert "signal_sighup" in stdout
    log = read_flight_log(log_file)
    kinds = [r.get("kind") for r in log.records if r["type"] == "event"]
    assert "signal" in kinds
    assert kinds.index("rtl_commanded") < kinds.index("landed_and_disarmed")
    result = list(log.of_type("result"))
    assert len(result) == 1 and result[0]["end_reason"] == "signal_sighup"
    assert result[0]["exit_code"] == 1
    assert all(not c.is_running() or c.status() == psutil.STATUS_ZOMBIE for c in children)


def test_pilot_takeover_mid_search_stops_all_commands(tmp_path):
    """A pilot flips the RC switch to position mode during the search (the simulator's
    pilot_takeover fault, PX4's behaviour: no STATUSTEXT), then lands 30 s later. The GCS
    notices the mode it did not command, sends nothing more (no command, no setpoint beyond
    those already in flight), keeps logging, waits for the landing and exits 1."""
    result = run_sitl(MISSIONS / "demo.yaml", seed=5, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides={"sim.faults": [
                          {"kind": "pilot_takeover", "at_s": 110.0, "mode": "POSCTL",
                           "land_after_s": 30.0}]})
    assert result.end_reason == "autopilot_takeover", result.events[-10:]
    assert result.exit_code == 1
    assert result.takeover is not None and result.takeover["mode"] == "POSCTL"
    log = read_flight_log(result.log_dir)
    takeover = [r for r in log.of_type("event") if r["kind"] == "takeover"]
    assert len(takeover) == 1 and takeover[0]["phase"] == "search"
    assert "pilot" in takeover[0]["reason"]
    kinds = _kinds(result.log_dir)
    assert "landed_and_disarmed" in kinds and "rtl_commanded" not in kinds
    results = list(log.of_type("result"))
    assert len(results) == 1 and results[0]["takeover"]["mode"] == "POSCTL"
    # the simulator's count of what reached it after the pilot took over
    truth = _truth(result.log_dir)
    end = [r for r in truth if r["type"] == "end"][-1]
    assert end["commands_after_takeover"] == 0, end
    # setpoints already on their way when the switch happened (one period of the 20 Hz
    # stream plus MAVSDK's own resend before it sees the new mode), then none
    assert end["setpoints_after_takeover"] <= 6, end
    # telemetry kept being logged until the landing
    tel_t = [r["t"] for r in log.of_type("telemetry")]
    assert tel_t[-1] >= takeover[0]["t"] + 25.0


def test_a_second_sigterm_with_the_simulator_gone_exits_within_5_s(tmp_path):
    """The vehicle is gone (its simulator process killed mid-search): the first SIGTERM asks
    for a return that cannot happen, the second exits within 5 s, the log saying why (a
    `signal_repeated` error, a result record with that end reason)."""
    import signal

    import psutil

    out = tmp_path / "flights"
    proc = _start_headless_sitl(out)
    try:
        log_file = _wait_for_offboard(out)
        sims = [c for c in psutil.Process(proc.pid).children(recursive=True)
                if "sim" in c.cmdline()]
        assert sims
        for sim in sims:
            sim.kill()
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        time.sleep(3.0)
        assert proc.poll() is None  # the first one cannot be obeyed: still waiting
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=30)
        exit_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    print(f"exit {exit_s:.2f} s after the second SIGTERM")
    assert exit_s < 5.0, exit_s
    assert proc.returncode == 1
    assert "SIGTERM after SIGTERM" in stderr
    log = read_flight_log(log_file)
    repeated = [r for r in log.records if r.get("kind") == "signal_repeated"]
    assert len(repeated) == 1 and repeated[0]["type"] == "error"
    result = list(log.of_type("result"))
    assert len(result) == 1 and result[0]["end_reason"] == "signal_repeated"


def test_the_planner_flies_low_within_the_missions_bound(tmp_path):
    """`flight.min_alt_m`: every heading is scored at 50 m and at 20 m; the simulator's
    vehicle, through MAVSDK, descends when a plan chooses 20 m and never goes below it, and
    the demo still localises every tag."""
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides={"flight.min_alt_m": 20.0})
    assert result.end_reason == "all_localised", result.events[-10:]
    assert result.exit_code == 0
    records = read_flight_log(result.log_dir).records
    plans = [r for r in records if r["type"] == "plan"]
    assert plans and all(r["alts_m"] == [50.0] * 8 + [20.0] * 8 for r in plans)
    low = [r["t"] for r in plans if r["chosen_alt_m"] == 20.0]
    assert low, "no plan chose the lower altitude"
    searching = [r["rel_alt_m"] for r in records if r["type"] == "telemetry"
                 and r["t"] > low[0] + 20.0 and r["mode"] == "OFFBOARD" and r["in_air"]]
    assert searching and min(searching) < 30.0
    assert min(searching) > 20.0 - 3.0  # the P-controlled descent settles on the bound
