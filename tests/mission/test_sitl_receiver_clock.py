"""End-to-end: a radio receiver with a wrong clock (10 minutes off; 100 ppm fast; both) flies the
demo against the real `python -m sim` child process at the e2e speed-up: the GCS learns the
clock from the receiver's heartbeats, logs it (``receiver_clock`` records), poses the pulses on
the mission clock and localises the four tags, exit 0. Without the correction the same radio's
pulses are all refused as ``time_skew`` (the quick unit tests show that; here only the flights).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from mexgen_gcs.io.flightlog import read_flight_log
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.mission.run import SitlPorts, run_sitl

pytestmark = pytest.mark.e2e

MISSIONS = Path(__file__).parents[2] / "missions"
SPEEDUP = 10.0
CLAIM_SLACK = 1.5
"""As the hostile-datagram flight: each tag within 1.5 claimed 95 % radii."""


@pytest.mark.parametrize(("offset_s", "drift_ppm"), [(600.0, 0.0), (0.0, 100.0),
                                                     (-600.0, 100.0)])
def test_wrong_receiver_clock_is_learnt_and_the_demo_localises(
        tmp_path: Path, offset_s: float, drift_ppm: float) -> None:
    faults = [{"kind": "clock_offset", "at_s": 0.0, "offset_s": offset_s},
              {"kind": "clock_drift", "at_s": 0.0, "ppm": drift_ppm}]
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, overrides={"sim.faults": faults})
    assert result.exit_code == 0, (result.end_reason, result.events[-10:], result.rejects)
    assert set(result.localised) == {"T1", "T2", "T3", "T4"}
    for tid, info in result.localised.items():
        assert info["error_m"] <= CLAIM_SLACK * info["radius_m"], (tid, info)
    log = read_flight_log(result.log_dir)
    clocks = list(log.of_type("receiver_clock"))
    assert clocks and clocks[0]["kind"] == "first"
    assert not [r for r in clocks if r["kind"] == "jump"], clocks
    # the offset the GCS learnt against what the simulator's radio stamped (its truth log):
    # the receiver's clock minus the vehicle's at the time of the record
    last = clocks[-1]
    elapsed = last["t"] - read_truth_file(result.log_dir).records[0]["start_unix"]
    true_offset = offset_s + drift_ppm * 1e-6 * elapsed
    # no better than the mission clock it is measured against: the GCS's fit of the simulated
    # vehicle's clock wanders by its residual (a second or more on a loaded machine)
    residual = max(r["residual_rms_s"] for r in log.of_type("clock"))
    assert abs(last["offset_s"] - true_offset) < 0.5 + 3.0 * residual, (last, true_offset)
    events = [r for r in log.records if r["type"] == "event" and r["kind"] == "receiver_clock"]
    assert len(events) == 1 and abs(events[0]["offset_s"] - offset_s) < 0.5 + 3.0 * residual
    # the pulses were used, posed on the mission clock
    dets = list(log.of_type("detection"))
    used = [d for d in dets if d["used"]]
    assert len(used) > 100 and len(used) >= 0.9 * len(dets)
    assert all(abs(d["t_pulse_rx"] - d["t_pulse"] - offset_s) < 1.0 + 3.0 * residual
               for d in used)


def test_demo_flies_on_tagtracker_tunnel_pulses_from_a_companion_ten_minutes_off(
        tmp_path: Path) -> None:
    """The simulator's receiver speaks TagTracker's MAVLink TUNNEL (PulseInfo_t) on a clock
    600 s ahead; the GCS reads it with receiver.format mavlink-tunnel, learns the clock from
    the pulse reports and localises the four tags."""
    faults = [{"kind": "clock_offset", "at_s": 0.0, "offset_s": 600.0}]
    result = run_sitl(MISSIONS / "demo.yaml", seed=3, speedup=SPEEDUP, ports=SitlPorts.free(),
                      log_dir=tmp_path, sim_args=["--radio-format", "mavlink-tunnel"],
                      overrides={"sim.faults": faults, "receiver.format": "mavlink-tunnel"})
    assert result.exit_code == 0, (result.end_reason, result.events[-10:], result.rejects)
    assert set(result.localised) == {"T1", "T2", "T3", "T4"}
    log = read_flight_log(result.log_dir)
    clocks = list(log.of_type("receiver_clock"))
    residual = max(r["residual_rms_s"] for r in log.of_type("clock"))
    assert clocks and abs(clocks[-1]["offset_s"] - 600.0) < 0.5 + 3.0 * residual, clocks[-1]
    used = [d for d in log.of_type("detection") if d["used"]]
    assert len(used) > 100
    # the power came through 10 log10(noise_psd) + snr as the simulator's receiver measured
    # it (a pulse and model clutter of the same period share a timestamp: either may match)
    truth: dict[float, list[float]] = {}
    for r in read_truth_file(result.log_dir).records:
        if r["type"] in ("pulse", "clutter") and r.get("t_sent") is not None:
            truth.setdefault(round(r["t_sent"], 6), []).append(r["rssi_db"])
    matched = [any(abs(d["rssi_db"] - p) < 1e-6 for p in truth[round(d["t_pulse_rx"], 6)])
               for d in used if round(d["t_pulse_rx"], 6) in truth]
    assert len(matched) >= 0.9 * len(used) and all(matched)
