"""The simulated receiver against the core radio model, in-process (many pulses, no sockets).

Detection rate and mean reported power per distance agree with RadioModel; clutter, faults and
the truth log behave as documented.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mexgen_gcs.core.motion import ConstantVelocity, RandomWalk
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.io.wire import Detection, Heartbeat, decode
from sim.faults import Fault, FaultSchedule
from sim.radios import RadioSim, ReceiverPose, TagTruth
from sim.truth import TruthWriter

T0_UNIX = 1.7e9
GROUND = ReceiverPose(0.0, 0.0, 0.0, 0.0, -34.9, 138.6, 20.0)


def static_tag(tag_id: str, freq_hz: int, east_m: float, north_m: float) -> TagTruth:
    return TagTruth(tag_id, freq_hz, RandomWalk(0.0), np.array([[east_m, north_m, 0.0, 0.0]]),
                    np.zeros(1, np.int8))


def run(radio: RadioSim, duration_s: float, pose: ReceiverPose = GROUND, step_s: float = 0.25,
        faults: FaultSchedule | None = None) -> list[tuple[float, Detection | Heartbeat]]:
    """Advance like the runner does (faults first, then the radio); decode what it sends."""
    out: list[tuple[float, Detection | Heartbeat]] = []
    t = 0.0
    while t <= duration_s:
        if faults is not None:
            faults.update(t, t)
        out.extend((t, decode(d)) for d in radio.advance(t, t, pose))
        t += step_s
    return out


def written(directory: Path) -> list[dict[str, Any]]:
    """The records a bare TruthWriter wrote (no 'sim' header, so not a truth file to read)."""
    return [json.loads(line) for line in (directory / "truth.jsonl").read_text().splitlines()]


def make_radio(tags: list[TagTruth], model: RadioModel, tmp_path: Path | None = None,
               faults: list[Fault] | None = None, seed: int = 3) -> tuple[RadioSim, FaultSchedule]:
    schedule = FaultSchedule(faults or [])
    truth = TruthWriter(tmp_path)
    radio = RadioSim(tags, model, 1.0, schedule, truth, lambda t: T0_UNIX + t,
                     np.random.default_rng(seed))
    return radio, schedule


def test_detection_rate_and_mean_power_follow_the_model() -> None:
    model = RadioModel(clutter_rate=0.0)
    # Tags due north (antenna gain 0 dB) at distances spanning the detection threshold.
    distances = {"A": 300.0, "B": 2800.0, "C": 3400.0, "D": 4200.0, "E": 9000.0}
    tags = [static_tag(k, 150_000_000 + 100_000 * i, 0.0, d)
            for i, (k, d) in enumerate(distances.items())]
    radio, faults = make_radio(tags, model)
    pulses = 3000
    got = run(radio, pulses - 0.5, faults=faults)
    dets = [e for _, e in got if isinstance(e, Detection)]
    for tag_id, dist in distances.items():
        power = float(model.power_db(np.array([0.0, dist]), np.zeros(3), 0.0))
        pd = float(model.detection_probability(np.array(power)))
        rssi = np.array([d.rssi_db for d in dets if d.tag == tag_id])
        rate = len(rssi) / pulses
        sigma = math.sqrt(pd * (1 - pd) / pulses)
        assert abs(rate - pd) <= 4 * sigma + 2e-3, (tag_id, rate, pd)
        if len(rssi) > 200 and pd > 0.9:
            # Far above the threshold, detection does not bias the reported power.
            assert abs(rssi.mean() - power) < 4 * model.noise_std_db / math.sqrt(len(rssi))
            assert rssi.std() == pytest.approx(model.noise_std_db, rel=0.1)


def test_antenna_pattern_and_pose_in_datagrams() -> None:
    model = RadioModel(clutter_rate=0.0, noise_std_db=0.5, pd_max=1.0)
    def radio() -> RadioSim:
        return make_radio([static_tag("T", 150_000_000, 0.0, 200.0)], model)[0]

    facing = ReceiverPose(0.0, 0.0, 50.0, 0.0, -34.9, 138.6, 70.0)
    away = ReceiverPose(0.0, 0.0, 50.0, 180.0, -34.9, 138.6, 70.0)
    front = [e for _, e in run(radio(), 200, facing) if isinstance(e, Detection)]
    back = [e for _, e in run(radio(), 200, away) if isinstance(e, Detection)]
    gain = np.mean([d.rssi_db for d in front]) - np.mean([d.rssi_db for d in back])
    cos_elev = 200.0 / math.hypot(200.0, 50.0)
    assert gain == pytest.approx(model.front_back_db * cos_elev, abs=0.2)
    d = front[0]
    assert (d.lat, d.lon, d.alt_m, d.yaw_deg) == (-34.9, 138.6, 70.0, 0.0)
    assert d.tag == "T" and d.freq_hz == 150_000_000


def test_truth_log_matches_what_was_sent(tmp_path: Path) -> None:
    model = RadioModel(clutter_rate=0.2)
    tags = [static_tag("T1", 150_100_000, 100.0, 2000.0), static_tag("T2", 150_200_000, 0, 3500)]
    radio, faults = make_radio(tags, model, tmp_path)
    got = run(radio, 300, faults=faults)
    sent = [e for _, e in got if isinstance(e, Detection)]
    records = written(tmp_path)
    pulses = [r for r in records if r["type"] == "pulse"]
    clutter = [r for r in records if r["type"] == "clutter"]
    assert 600 <= len(pulses) <= 602  # each tag pulses once a second, at its own phase
    logged = sorted([(r["t_sent"], r["tag"], r["rssi_db"]) for r in pulses + clutter
                     if r["sent"]])
    assert logged == sorted((d.t, d.tag, d.rssi_db) for d in sent)
    assert 0 < len(clutter) < 0.2 * len(pulses) + 40
    for r in pulses:
        expected = float(model.power_db(np.array([r["x_m"], r["y_m"]]), np.zeros(3), 0.0))
        assert r["power_db"] == pytest.approx(expected)
        assert r["detected"] == (r["rssi_db"] is not None)
    tag_records = [r for r in records if r["type"] == "tag"]
    assert len(tag_records) == 2 * 301
    heartbeats = [e for _, e in got if isinstance(e, Heartbeat)]
    assert len(heartbeats) == pytest.approx(301, abs=2)
    assert all(h.listening == ("T1", "T2") for h in heartbeats)


def test_faults_silence_dropout_clutter_clock_offset() -> None:
    model = RadioModel(clutter_rate=0.0, pd_max=1.0)
    tag = static_tag("T", 150_000_000, 0.0, 100.0)
    faults = [Fault("radio_silence", at_s=10.0, duration_s=10.0),
              Fault("detection_dropout", at_s=30.0, duration_s=10.0, probability=1.0),
              Fault("clutter", at_s=50.0, duration_s=100.0, rate_per_s=2.0),
              Fault("clock_offset", at_s=200.0, offset_s=-7.5)]
    radio, schedule = make_radio([tag], model, faults=faults)
    got = run(radio, 260.0, faults=schedule)

    def in_window(lo: float, hi: float, kind: type) -> list[Detection | Heartbeat]:
        return [e for t, e in got if lo <= t < hi and isinstance(e, kind)]

    assert not in_window(10.5, 19.5, Heartbeat) and not in_window(10.5, 19.5, Detection)
    assert in_window(30.5, 39.5, Heartbeat) and not in_window(30.5, 39.5, Detection)
    clutter = len(in_window(50.0, 150.0, Detection)) - 100  # minus one real pulse a second
    assert clutter == pytest.approx(200, abs=4 * math.sqrt(200))
    late = [(t, e) for t, e in got if t > 201.0]
    assert all(e.t == pytest.approx(T0_UNIX + t - 7.5, abs=0.3) for t, e in late)


def test_clock_drift_and_offset_stamp_the_receivers_clock() -> None:
    """A receiver 600 s off and 2000 ppm fast from sim time 0: every timestamp, heartbeats and
    detections alike, is the vehicle's time plus 600 s plus 2e-3 of the elapsed sim time."""
    model = RadioModel(clutter_rate=0.0, pd_max=1.0)
    faults = [Fault("clock_offset", at_s=0.0, offset_s=600.0),
              Fault("clock_drift", at_s=0.0, ppm=2000.0)]
    radio, schedule = make_radio([static_tag("T", 150_000_000, 0.0, 100.0)], model,
                                 faults=faults)
    got = run(radio, 300.0, faults=schedule, step_s=0.01)
    assert any(isinstance(e, Detection) for _, e in got)
    assert any(isinstance(e, Heartbeat) for _, e in got)
    for t, e in got:
        assert e.t == pytest.approx(T0_UNIX + t + 600.0 + 2e-3 * t, abs=0.02)


def test_gps_loss_leaves_pose_out() -> None:
    radio, _ = make_radio([static_tag("T", 150_000_000, 0.0, 100.0)],
                          RadioModel(clutter_rate=0.0, pd_max=1.0))
    blind = ReceiverPose(0.0, 0.0, 30.0, 90.0, None, None, None)
    dets = [e for _, e in run(radio, 20, blind) if isinstance(e, Detection)]
    assert dets and all(d.lat is None and d.alt_m is None and d.yaw_deg is None for d in dets)


def test_moving_tag_truth_follows_its_model(tmp_path: Path) -> None:
    tag = TagTruth("M", 150_000_000, ConstantVelocity(accel_std_m_s2=0.0),
                   np.array([[0.0, 0.0, 3.0, 4.0]]), np.zeros(1, np.int8), "cv")
    radio, _ = make_radio([tag], RadioModel(), tmp_path)
    run(radio, 100)
    tracks = [r for r in written(tmp_path) if r["type"] == "tag"]
    last = tracks[-1]
    elapsed = last["t"] - T0_UNIX
    assert (last["x_m"], last["y_m"]) == pytest.approx((3.0 * elapsed, 4.0 * elapsed))
    pulse = [r for r in written(tmp_path) if r["type"] == "pulse"][-1]
    assert (pulse["x_m"], pulse["y_m"]) == pytest.approx(
        (3.0 * (pulse["t"] - T0_UNIX), 4.0 * (pulse["t"] - T0_UNIX)), abs=1e-3)
