"""The receiver on synthetic IQ: pulse times from the sample counter, calibrated power, the
tuning plan, CW and width rejection, clipping, dropped samples."""

from __future__ import annotations

import numpy as np
import pytest

from mexgen_gcs.receiver import synth
from mexgen_gcs.receiver.calibration import Calibration, nearest_gain_db
from mexgen_gcs.receiver.convert import convert
from mexgen_gcs.receiver.detector import DetectorConfig
from mexgen_gcs.receiver.pipeline import Pulse, PulseReceiver, Status
from mexgen_gcs.receiver.sources import IQBlock
from mexgen_gcs.receiver.tuning import TuningError, plan_tuning

FS = 250_000.0
TAGS = [("A", 150_100_000.0), ("B", 150_160_000.0)]
NOISE = 1e-3


def _run(pulses, seconds=6.0, tones=(), cal=None, clock=None, drop=None, seed=1):
    """Feed cu8 blocks of 0.1 s; pulses (tag index, start s, power_fs, width s)."""
    plan = plan_tuning(TAGS, rate_hz=FS)
    rx = PulseReceiver(plan, DetectorConfig(), cal or Calibration(), clock=clock,
                       start_unix=None if clock else 1000.0)
    rng = np.random.default_rng(seed)
    spec = [(t * FS, w * FS, p, plan.channels[i].offset_hz) for i, t, p, w in pulses]
    events = []
    n = round(0.1 * FS)
    for k in range(round(seconds / 0.1)):
        first = k * n
        x = synth.pulse_train(first, n, FS, NOISE, spec, rng, list(tones))
        raw = synth.to_cu8(x).tobytes()
        if clock is not None:
            clock.now = 5000.0 + (first + n) / FS + 0.01
        if drop is not None and drop[0] <= k < drop[1]:
            continue
        s, c = convert(raw, "cu8")
        events += rx.process(IQBlock(s, c, raw, "cu8"))
    return rx, [e for e in events if isinstance(e, Pulse)], [e for e in events if
                                                             isinstance(e, Status)]


def test_pulses_are_timed_by_the_sample_counter_and_their_power_is_calibrated():
    starts = [0.7 + 1.0 * k + 0.0001234 * k for k in range(5)]
    pulses = [(0, t, 10 ** (-30 / 10), 0.02) for t in starts]  # -30 dBFS, as the noise
    cal = Calibration(gain_db=20.0, cal_offset_db=-50.0)
    rx, found, statuses = _run(pulses, cal=cal)
    assert [p.tag for p in found] == ["A"] * 5
    for p, t in zip(found, starts, strict=True):
        assert abs(p.t_unix - (1000.0 + t)) < 0.3e-3  # 75 samples, an eighth of a frame
        assert p.rssi_dbm == pytest.approx(-30.0 - 20.0 - 50.0, abs=0.5)
        assert p.snr_db > 15
        assert not p.clipped
    assert found[-1].interval_s == pytest.approx(1.0001234, abs=1e-4)
    assert statuses and all(s.heard["B"] == 0 for s in statuses)
    noise_band = 10 * np.log10(NOISE * rx.channels.bins / rx.channels.frame_len) - 70.0
    assert statuses[-1].noise_dbm["B"] == pytest.approx(noise_band, abs=0.5)


def test_a_carrier_is_rejected_and_a_short_impulse_fails_the_width_gate():
    plan = plan_tuning(TAGS, rate_hz=FS)
    cw = (10 ** (-35 / 10), plan.channels[1].offset_hz, 1.0 * FS, 3.0 * FS)
    pulses = [(0, 4.3, 10 ** (-12 / 10), 0.001)]  # a 1 ms click, 38 dB over the band's noise
    rx, found, _ = _run(pulses, tones=[cw])
    assert found == []
    assert rx.detector.stats.cw_rejected >= 1
    assert rx.detector.stats.width_rejected == 1


def test_clipping_is_flagged():
    rx, found, _ = _run([(0, 1.5, 1.2, 0.02)], seconds=2.0)
    assert [p.tag for p in found if p.tag == "A"] == ["A"]
    assert all(p.clipped for p in found)  # clipping's spurs elsewhere are flagged too
    assert rx.counters.clipped_frames > 0


class _Clock:
    now = 0.0

    def __call__(self) -> float:
        return self.now


def test_dropped_samples_are_counted_and_later_pulses_keep_their_times():
    clock = _Clock()
    starts = [0.55 + k for k in range(6)]
    rx, found, _ = _run([(0, t, 1e-3, 0.02) for t in starts], clock=clock, drop=(20, 27))
    assert rx.counters.gaps == 1
    assert 0.7 * FS <= rx.counters.dropped_samples <= 0.7 * FS + rx.channels.frame_len
    after = [p for p in found if p.t_unix > 5000.0 + 3.0]
    assert len(after) == 3  # 3.55, 4.55, 5.55 s
    for p in after:
        k = round(p.t_unix - 5000.0 - 0.55)
        # anchored once at the first block (10 ms late): the offset stays 10 ms after the gap
        assert abs(p.t_unix - (5000.0 + 0.55 + k + 0.01)) < 1e-3


def test_tuning_plan_covers_tags_off_dc_and_refuses_a_tag_out_of_band():
    plan = plan_tuning([("T1", 150.1e6), ("T2", 150.2e6), ("T3", 150.3e6)])
    assert plan.rate_hz == 960_000.0
    assert all(abs(c.offset_hz) >= 5000 for c in plan.channels)  # none on the DC spur
    with pytest.raises(TuningError, match=r"tag T9 at 151\.0000 MHz"):
        plan_tuning([("T1", 150.1e6), ("T9", 151.0e6)], rate_hz=250_000.0,
                    centre_hz=150.11e6)
    with pytest.raises(TuningError, match="T9"):
        plan_tuning([("T1", 150.1e6), ("T9", 160.0e6)])
    ppm = plan_tuning([("T1", 150.1e6)], rate_hz=FS, centre_hz=150.08e6, ppm=10.0,
                      ppm_in_software=True)
    assert ppm.channels[0].offset_hz == pytest.approx(20_000 - 1500.8, abs=1.0)


def test_gain_is_rounded_to_the_devices_table():
    from mexgen_gcs.receiver.calibration import R820T_GAINS_TENTHS_DB

    assert nearest_gain_db(30.0, R820T_GAINS_TENTHS_DB) == 29.7
    assert nearest_gain_db(30.0, None) == 30.0
    cal = Calibration(29.7, -3.0)
    assert cal.dbm(cal.power_fs(-88.0)) == pytest.approx(-88.0)
