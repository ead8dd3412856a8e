"""The simulator in a world that is not the mission's model (sim.reality): the drawn world is
in the truth header and every pulse's power follows it, not the mission's RadioModel."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.config import load_mission
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.io.truthfile import read_truth_file
from mexgen_gcs.io.wire import Detection, decode
from sim.radios import reality_world
from tests.sim.sim_helpers import SimFactory, udp_socket, write_mission

TAGS = [{"id": "A", "freq_hz": 150_100_000}, {"id": "B", "freq_hz": 150_200_000}]


def test_tx_power_world_shifts_each_tags_power_by_its_drawn_offset(
        sim_factory: SimFactory, tmp_path: Path) -> None:
    path = write_mission(
        tmp_path / "r.yaml", tags=TAGS, reality="tx-power",
        sim_tags=[{"id": "A", "position_m": "[0.0, 200.0]", "motion": "static"},
                  {"id": "B", "position_m": "[150.0, 400.0]", "motion": "static"}])
    mission = load_mission(path)
    world = reality_world(mission, 11)
    assert world is not None and np.all(np.abs(world.tx_offset_db) <= 6.0)
    sock = udp_socket(timeout_s=0.2)
    sim = sim_factory(path, radio_port=sock.getsockname()[1], speedup=20.0)
    detections = []
    deadline = time.monotonic() + 4.0
    while time.monotonic() < deadline:
        try:
            data, _ = sock.recvfrom(2048)
        except TimeoutError:
            continue
        msg = decode(data)
        if isinstance(msg, Detection):
            detections.append(msg)
    assert sim.stop() == 0
    sock.close()
    records = read_truth_file(sim.truth_path).records
    header = records[0]
    assert header["reality"]["profile"] == "tx-power"
    assert header["reality"]["tx_offset_db"] == pytest.approx(world.tx_offset_db.tolist())
    radio = RadioModel()
    pulses = [r for r in records if r["type"] == "pulse"]
    assert len(pulses) >= 20 and detections
    for r in pulses:
        i = ("A", "B").index(r["tag"])
        model = radio.power_db(np.array([r["x_m"], r["y_m"]]), np.array(r["rx_enu_m"]),
                               math.radians(r["rx_yaw_deg"]))
        assert r["power_db"] == pytest.approx(float(model) + world.tx_offset_db[i], abs=1e-6)


def test_matched_draws_no_world(tmp_path: Path) -> None:
    path = write_mission(tmp_path / "m.yaml", tags=TAGS[:1],
                         sim_tags=[{"id": "A", "position_m": "[0.0, 200.0]"}])
    assert reality_world(load_mission(path), 11) is None
