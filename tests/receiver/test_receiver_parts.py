"""Smaller parts: the rtl_tcp command encoding, the datagrams against the wire schema, the
benchmark's accounting, the simulator's IQ stream and the command-line wiring."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np

from mexgen_gcs.bench.receiver import measure
from mexgen_gcs.cli import build_parser, resolve_handler
from mexgen_gcs.io import wire
from mexgen_gcs.receiver import rtltcp, synth
from mexgen_gcs.receiver.calibration import Calibration
from mexgen_gcs.receiver.convert import convert
from mexgen_gcs.receiver.detector import DetectorConfig
from mexgen_gcs.receiver.output import pulse_datagram, status_datagram
from mexgen_gcs.receiver.pipeline import Pulse, PulseReceiver, Status
from mexgen_gcs.receiver.sources import IQBlock
from mexgen_gcs.receiver.tuning import plan_tuning
from sim.iq import IqOptions, IqRadio

SCHEMA = json.loads((Path(__file__).resolve().parents[2] / "docs" / "schemas" /
                     "wire-v1.schema.json").read_text(encoding="utf-8"))


def test_rtl_tcp_commands_are_five_big_endian_bytes():
    assert rtltcp.pack_command(rtltcp.SET_FREQ, 150_280_000) == b"\x01" + (150_280_000).to_bytes(
        4, "big")
    assert rtltcp.unpack_command(rtltcp.pack_command(rtltcp.SET_FREQ_CORRECTION, -12)) == (5, -12)
    assert rtltcp.HEADER.size == 12 and rtltcp.COMMAND.size == 5


def test_receiver_datagrams_decode_and_match_the_schema():
    p = Pulse("T1", 150_100_012, 1.7e9, 12.5, -71.234, 14.2, -85.4, 0.0205, False, 1.0003)
    s = Status(1.7e9, {"T1": -85.4, "T2": float("nan")}, {"T1": 1, "T2": 0}, 0, 3)
    for data in (pulse_datagram(p), status_datagram(s)):
        obj = json.loads(data)
        jsonschema.validate(obj, SCHEMA)
        wire.decode(data)
    assert json.loads(status_datagram(s))["noise_dbm"] == {"T1": -85.4, "T2": None}
    det = wire.decode(pulse_datagram(p))
    assert isinstance(det, wire.Detection) and det.rssi_db == -71.234 and det.tag == "T1"


def test_bench_counts_its_pulses_and_cpu():
    r = measure(seconds=2.0)
    assert r["pulses"] == 4 * 3  # two per tag per second, less the first (the warm-up)
    assert 0.0 < r["cpu_share_of_one_core"] == 1.0 / r["realtime_factor"]


def test_simulated_iq_puts_a_pulse_where_and_as_strong_as_the_radio_said():
    radio = IqRadio([150.1e6, 150.22e6], 0.02, -60.0, 0.0, IqOptions(drift_hz=0.0,
                                                                      offset_std_hz=0.0),
                    np.random.default_rng(4))
    radio.restart(100.0)
    radio.command(rtltcp.SET_SAMPLE_RATE, 250_000, 100.0)
    radio.command(rtltcp.SET_FREQ, 150_160_000, 100.0)
    radio.command(rtltcp.SET_GAIN, 297, 100.0)
    radio.pulse(1, 101.25, -50.0)
    raw = radio.render(103.0)
    assert len(raw) == 2 * 3 * 250_000
    plan = plan_tuning([("A", 150.1e6), ("B", 150.22e6)], rate_hz=250_000.0,
                       centre_hz=150.16e6)
    rx = PulseReceiver(plan, DetectorConfig(), Calibration(29.7, synth.SIM_CAL_OFFSET_DB),
                       start_unix=100.0)
    s, c = convert(raw, "cu8")
    found = [e for e in rx.process(IQBlock(s, c, raw, "cu8")) if isinstance(e, Pulse)]
    assert [p.tag for p in found] == ["B"]
    assert abs(found[0].t_unix - 101.25) < 1e-3
    assert abs(found[0].rssi_dbm - -50.0) < 0.5
    noise = rx.noise_dbm()["A"]  # 33.5 dB below -60 dBm per Hz, in the channel's band
    band_hz = rx.channels.bins * rx.channels.bin_hz
    assert abs(noise - (-60.0 - 33.5 + 10 * np.log10(band_hz))) < 0.5


def test_receive_and_sitl_receiver_are_on_the_command_line():
    args = build_parser().parse_args(["receive", "m.yaml", "--source", "rtlsdr://0"])
    assert args.pfa == 1e-3 and args.gain == 29.7
    handler, why = resolve_handler("receive")
    assert handler is not None, why
    assert build_parser().parse_args(["sitl", "m.yaml", "--receiver", "iq"]).receiver == "iq"


def test_fly_takes_an_iq_source():
    args = build_parser().parse_args(["fly", "m.yaml", "--iq-source", "rtltcp://10.0.0.2:1234",
                                      "--iq-cal-offset", "-3.5"])
    assert args.iq_source == "rtltcp://10.0.0.2:1234" and args.iq_cal_offset == -3.5


def test_hardware_sources_say_what_is_missing():
    import importlib.util

    import pytest

    from mexgen_gcs.receiver.sources import SourceError
    from mexgen_gcs.receiver.urls import open_source

    if importlib.util.find_spec("SoapySDR") is None:
        with pytest.raises(SourceError, match="SoapySDR's Python bindings are not installed"):
            open_source("soapy://driver=rtlsdr")
    with pytest.raises(SourceError, match=r"rtlsdr://7: (pyrtlsdr is not installed|cannot open)"):
        open_source("rtlsdr://7")  # no dongle here (or no pyrtlsdr): a message, not a crash


def test_fly_refuses_an_iq_source_of_no_known_kind_before_connecting(tmp_path, capsys):
    from mexgen_gcs import cli
    from tests.receiver.helpers import DEMO

    code = cli.main(["fly", str(DEMO), "--headless", "--iq-source", "bogus://x",
                     "--connect", "udpin://127.0.0.1:1", "--log-dir", str(tmp_path)])
    assert code == 2
    assert "--iq-source: source 'bogus://x': unknown kind" in capsys.readouterr().err
