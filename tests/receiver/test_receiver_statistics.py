"""The detector against its theory on synthetic IQ (seeded): probability of detection against
SNR at 1e-3 false alarms per tag-second within 1 dB of the theoretical curve, false alarms
in noise alone and with CW interferers, and the calibrated power's bias."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from mexgen_gcs.receiver import study
from mexgen_gcs.receiver.threshold import pd_theory, pfa_per_test


def test_pd_against_snr_is_within_one_db_of_theory():
    res = study.pd_curve(np.arange(-4.0, 3.1, 1.0), pulses_per_tag=12, seed=5)
    assert abs(res["snr50_measured_db"] - res["snr50_theory_db"]) < 1.0, res
    rx = study._receiver(1e-3)
    scale = rx.channels.bins * (study.WIDTH_S / rx.channels.frame_s) * rx.channels.capture
    for row in res["rows"]:
        n = row["pulses"]
        lo = float(pd_theory(scale * 10 ** ((row["snr_db"] - 1.0) / 10), res["dof"],
                             res["threshold_factor"]))
        hi = float(pd_theory(scale * 10 ** ((row["snr_db"] + 1.0) / 10), res["dof"],
                             res["threshold_factor"]))
        slack = 3.0 * math.sqrt(0.25 / n)  # three binomial sigmas at worst
        assert lo - slack <= row["pd"] <= hi + slack, row


def test_false_alarms_in_noise_and_with_cw_stay_at_the_chosen_rate():
    for cw in (False, True):
        res = study.false_alarms(100.0, cw=cw, seed=11)
        expected = res["target_per_tag_hour"] * res["tag_seconds"] / 3600.0  # 0.8
        assert res["false_alarms"] <= stats.poisson.ppf(0.999, expected), res
        if cw:
            assert res["cw_rejected"] >= 10  # the keyed carrier's every onset, and the steady
            assert res["by_tag"]["S0"] == res["by_tag"]["S1"] == 0


def test_power_estimate_is_unbiased_within_half_a_db():
    res = study.power_bias([6.0, 10.0, 20.0], pulses_per_tag=8, seed=3)
    for row in res["rows"]:
        assert row["n"] >= 60
        assert abs(row["bias_db"]) < 0.5, row
        assert row["std_db"] < 1.0, row


def test_threshold_spreads_the_rate_over_the_tests():
    p = pfa_per_test(1e-3, 500.0)
    assert abs(1.0 - (1.0 - p) ** 500 - 1e-3) < 1e-12
