"""Recordings and the `receive` command: SigMF round trip with pulses as annotations, a
replay giving identical pulses, damaged recordings read up to the damage, raw files through
the command line to real UDP datagrams, bad input refused with exit 2."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import numpy as np
import pytest

from mexgen_gcs.io import wire
from mexgen_gcs.receiver.run import ReceiveOptions, run_receiver
from mexgen_gcs.receiver.sources import SourceError, open_sigmf
from mexgen_gcs.receiver.urls import open_source
from tests.receiver.helpers import DEMO, demo_mission, demo_plan, raw_url, write_cu8

PULSES = [(i, 0.3 + 0.1 * i + k, -45.0 + 3 * i) for k in range(4) for i in range(4)]


@pytest.fixture(scope="module")
def raw_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("iq") / "four.cu8"
    write_cu8(path, demo_plan(), 4.5, PULSES, np.random.default_rng(3))
    return path


def _replay(url, **kw):
    return run_receiver(demo_mission(), open_source(url), ReceiveOptions(**kw))


def test_raw_file_pulses_and_sigmf_round_trip_replays_identically(raw_file, tmp_path):
    plan = demo_plan()
    rec = tmp_path / "rec.sigmf-data"
    live = _replay(raw_url(raw_file, plan), record=rec)
    assert sorted((p.tag, round(p.t_unix - live.pulses[0].t_unix, 2)) for p in live.pulses) \
        == sorted((f"T{i + 1}", round(t - 0.3, 2)) for i, t, _ in PULSES)
    for p in live.pulses:
        i = int(p.tag[1]) - 1
        expected_dbm = -45.0 + 3 * i - 29.7  # dBFS - gain (no calibration offset)
        assert p.rssi_dbm == pytest.approx(expected_dbm, abs=1.0)
    meta = json.loads(rec.with_suffix(".sigmf-meta").read_text())
    assert meta["global"]["core:datatype"] == "cu8"
    assert meta["global"]["mexgen:sample_count"] == rec.stat().st_size // 2
    assert [a["core:label"] for a in meta["annotations"]] == [p.tag for p in
                                                              sorted(live.pulses,
                                                                     key=lambda p: p.sample)]
    replay = _replay(f"file:{rec.with_suffix('.sigmf-meta')}")
    assert replay.pulses == live.pulses  # same samples, same anchor: the same pulses


def test_sigmf_library_reads_the_recording(raw_file, tmp_path):
    sigmf = pytest.importorskip("sigmf")
    rec = tmp_path / "lib.sigmf-data"
    live = _replay(raw_url(raw_file, demo_plan()), record=rec)
    handle = sigmf.sigmffile.fromfile(str(rec.with_suffix(".sigmf-meta")))
    assert handle.get_global_field("core:sample_rate") == demo_plan().rate_hz
    assert len(handle.get_annotations()) == len(live.pulses)
    samples = handle.read_samples(0, 1000)
    assert samples.shape == (1000,) and np.iscomplexobj(samples)


def test_truncated_recording_is_read_up_to_the_damage(raw_file, tmp_path):
    rec = tmp_path / "cut.sigmf-data"
    full = _replay(raw_url(raw_file, demo_plan()), record=rec)
    data = rec.read_bytes()
    cut = len(data) // 2 + 1  # mid-sample, about 2.2 s in
    rec.write_bytes(data[:cut])
    part = _replay(f"file:{rec.with_suffix('.sigmf-meta')}")
    assert part.damage is not None and "truncated" in part.damage
    assert str(rec) in part.damage
    assert part.samples == cut // 2
    assert part.pulses == [p for p in full.pulses if p.sample + 0.02 * 960_000 < cut // 2 - 2048]


def test_broken_metadata_and_bad_urls_are_named():
    with pytest.raises(SourceError, match="rate="):
        open_source("file:/nonexistent.cu8")
    with pytest.raises(SourceError, match="unknown kind"):
        open_source("http://example")
    with pytest.raises(SourceError, match="cannot read"):
        open_sigmf("/nonexistent.sigmf-meta")


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "mexgen_gcs", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.long  # the command line as a subprocess
def test_receive_command_sends_wire_datagrams(raw_file):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.settimeout(0.5)
        port = s.getsockname()[1]
        r = _cli("receive", str(DEMO), "--source", raw_url(raw_file, demo_plan()),
                 "--to", f"udp://127.0.0.1:{port}", "--cal-offset", "10")
        assert r.returncode == 0, r.stderr
        got = []
        while True:
            try:
                got.append(s.recv(2000))
            except TimeoutError:
                break
    msgs = [wire.decode(d) for d in got]
    dets = [m for m in msgs if isinstance(m, wire.Detection)]
    beats = [json.loads(d) for d in got if b'"heartbeat"' in d]
    assert len(dets) == len(PULSES)
    assert {d.tag for d in dets} == {"T1", "T2", "T3", "T4"}
    assert all(abs(d.freq_hz - {"T1": 150.1e6, "T2": 150.22e6, "T3": 150.34e6,
                                "T4": 150.46e6}[d.tag]) < 1000 for d in dets)
    assert len(beats) == 4
    assert set(beats[0]["noise_dbm"]) == {"T1", "T2", "T3", "T4"}
    assert "4 pulses" in r.stdout and "centre 150.2800 MHz" in r.stderr


@pytest.mark.long  # the command line as a subprocess
def test_receive_refuses_a_tag_outside_the_recording(raw_file, tmp_path):
    narrow = f"file:{raw_file}?rate=250000&centre=150.28e6"
    r = _cli("receive", str(DEMO), "--source", narrow, "--to", "udp://127.0.0.1:9")
    assert r.returncode == 2
    assert "tag T1 at 150.1000 MHz is outside" in r.stderr
    r = _cli("receive", str(DEMO), "--source", "rtltcp://127.0.0.1:1")
    assert r.returncode == 2 and "cannot connect" in r.stderr


class _DroppingSource:
    """A live source (fake: a raw file read in blocks) that loses blocks 20-34 (0.75 s), with
    the clock the samples' own time plus 10 ms; the unit under test is the recorder's gap
    handling."""

    live = True
    sets_ppm = False
    gain_table = None

    def __init__(self, inner):
        self.inner = inner
        self.name = "dropping"
        self.fixed = inner.fixed
        self.delivered = 0
        self.blocks = 0

    def tune(self, tuning):
        pass

    def read(self, n):
        while True:
            block = self.inner.read(n)
            if block is None:
                return None
            self.delivered += block.samples.size
            self.blocks += 1
            if not 20 <= self.blocks < 35:
                return block

    def clock(self):
        return 1000.0 + self.delivered / self.inner.rate_hz + 0.01

    def close(self):
        self.inner.close()


def test_a_recording_with_lost_samples_replays_with_the_same_pulse_times(raw_file, tmp_path):
    src = _DroppingSource(open_source(raw_url(raw_file, demo_plan())))
    rec = tmp_path / "gap.sigmf-data"
    live = run_receiver(demo_mission(), src, ReceiveOptions(record=rec), clock=src.clock)
    assert live.dropped_samples > 0
    meta = json.loads(rec.with_suffix(".sigmf-meta").read_text())
    assert len(meta["captures"]) == 2
    assert meta["captures"][1]["core:global_index"] > meta["captures"][1]["core:sample_start"]
    replay = _replay(f"file:{rec.with_suffix('.sigmf-meta')}")
    assert replay.dropped_samples == live.dropped_samples
    assert [(p.tag, p.t_unix) for p in replay.pulses] == [(p.tag, p.t_unix) for p in live.pulses]
    assert len(live.pulses) < len(PULSES)  # the lost samples held pulses
