"""The simulator's radio over a real UDP socket: wire format v1, the model, and the truth log."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.io.wire import Detection, Heartbeat, decode
from tests.sim.sim_helpers import SimFactory, udp_socket, write_mission

SPEEDUP = 20.0
TAGS = [{"id": "NEAR", "freq_hz": 150_100_000}, {"id": "MID", "freq_hz": 150_200_000},
        {"id": "FAR", "freq_hz": 150_300_000}]
POSITIONS = {"NEAR": 300.0, "MID": 3400.0, "FAR": 8000.0}  # metres north of home


def test_datagrams_follow_wire_v1_the_model_and_the_truth(sim_factory: SimFactory,
                                                          tmp_path: Path) -> None:
    mission = write_mission(
        tmp_path / "radio.yaml", tags=TAGS,
        sim_tags=[{"id": k, "position_m": f"[0.0, {v}]", "motion": "static"}
                  for k, v in POSITIONS.items()])
    sock = udp_socket(timeout_s=0.2)
    sim = sim_factory(mission, radio_port=sock.getsockname()[1], speedup=SPEEDUP)
    received: list[Detection | Heartbeat] = []
    sources = set()
    deadline = time.monotonic() + 6.0
    while time.monotonic() < deadline:
        try:
            data, addr = sock.recvfrom(2048)
        except TimeoutError:
            continue
        assert len(data) <= 1400
        received.append(decode(data))  # raises WireError if not valid v1
        sources.add(addr[0])
    assert sim.stop() == 0
    sock.close()
    assert sources == {"127.0.0.1"}

    heartbeats = [e for e in received if isinstance(e, Heartbeat)]
    detections = [e for e in received if isinstance(e, Detection)]
    assert len(heartbeats) >= 6 * SPEEDUP * 0.5  # one per sim second
    assert all(h.listening == ("NEAR", "MID", "FAR") for h in heartbeats)
    # Timestamps are sim time mapped to unix: they advance ~SPEEDUP x faster than the wall.
    span = heartbeats[-1].t - heartbeats[0].t
    assert span > 6.0 * SPEEDUP * 0.5
    # The receiver pose: the vehicle sits at home (20 m AMSL), facing north.
    d0 = detections[0]
    assert (d0.lat, d0.lon, d0.alt_m, d0.yaw_deg) == pytest.approx((-34.9212, 138.6011, 20.0,
                                                                    0.0), abs=1e-6)

    records = read_truth_file(sim.truth_path).records
    pulses = [r for r in records if r["type"] == "pulse"]
    sent = {(r["t_sent"], r["tag"], r["rssi_db"]) for r in records
            if r["type"] in ("pulse", "clutter") and r["sent"]}
    got = {(d.t, d.tag, d.rssi_db) for d in detections}
    assert got <= sent  # everything received was sent, exactly as logged
    assert len(got) >= 0.99 * len(sent) - 2  # loopback loses (almost) nothing
    # Detection rate and mean power per distance agree with the mission's radio model.
    model = RadioModel()
    for tag, north in POSITIONS.items():
        mine = [r for r in pulses if r["tag"] == tag]
        assert len(mine) > 40
        power = float(model.power_db(np.array([0.0, north]), np.zeros(3), 0.0))
        assert all(r["power_db"] == pytest.approx(power) for r in mine)
        pd = float(model.detection_probability(np.array(power)))
        rate = sum(r["detected"] for r in mine) / len(mine)
        assert abs(rate - pd) <= 4 * math.sqrt(pd * (1 - pd) / len(mine)) + 0.02, (tag, rate)
        rssi = [d.rssi_db for d in detections if d.tag == tag]
        if pd > 0.9:
            mean_err = np.mean(rssi) - power
            assert abs(mean_err) < 4 * model.noise_std_db / math.sqrt(len(rssi)) + 0.5
