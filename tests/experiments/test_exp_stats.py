"""Summary statistics: Wilson interval, Kaplan-Meier median with censored runs, restricted
mean, paired differences; and the summary that states its criterion and both readings."""

import math

import numpy as np
import pytest
from scipy import stats as sps

from mexgen_gcs.experiments.scenario import scenario
from mexgen_gcs.experiments.stats import (
    km_median,
    paired_mean,
    restricted_mean,
    success_ci,
    survival_curve,
)
from mexgen_gcs.experiments.summary import summary_markdown


def test_wilson_interval():
    ci = success_ci(47, 50)
    assert ci.value == 0.94
    # Wilson score interval by its formula
    z = sps.norm.ppf(0.975)
    p, n = 0.94, 50
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert ci.low == pytest.approx(centre - half) and ci.high == pytest.approx(centre + half)
    assert success_ci(50, 50).high == pytest.approx(1.0) and success_ci(50, 50).low < 1.0
    assert success_ci(0, 50).low == pytest.approx(0.0) and success_ci(0, 50).high > 0.0


def test_km_median_counts_the_failed_runs():
    """4 runs done at 100, 200, 300, 400 s, 4 failed (censored at 1000 s): the median is
    where the survival S = 1 - k/8 first reaches 1/2, at 400 s, not the 250 s of the
    successful runs alone; with 5 failures it is beyond the limit."""
    t = np.array([100.0, 200.0, 300.0, 400.0, 1000.0, 1000.0, 1000.0, 1000.0])
    done = np.array([True] * 4 + [False] * 4)
    est = km_median(t, done, 1000.0)
    assert est.value == 400.0
    assert est.low is not None and est.low <= 400.0
    t5, d5 = np.r_[t, 1000.0], np.r_[done, False]
    beyond = km_median(t5, d5, 1000.0)
    assert beyond.value is None and beyond.text(beyond="> 1000").startswith("> 1000")
    x, y = survival_curve(t, done, 1000.0)
    assert y[0] == 1.0 and y[-1] == pytest.approx(0.5) and x[-1] == 1000.0
    assert restricted_mean(t, done, 1000.0).value == pytest.approx((1000 + 4000) / 8)
    assert km_median(t, np.zeros(8, bool), 1000.0).text(beyond="> 1000") == "> 1000"


def test_paired_mean_is_a_t_interval():
    rng = np.random.default_rng(0)
    d = rng.normal(20.0, 40.0, 30)
    est = paired_mean(d)
    ref = sps.ttest_1samp(d, 0.0).confidence_interval(0.95)
    assert est.value == pytest.approx(d.mean())
    assert (est.low, est.high) == pytest.approx((ref.low, ref.high))
    assert paired_mean(np.array([3.0])).low is None


def _row(model, method, start, success, time_s, tight_success="0", tight_time=""):
    return {"scenario": "localise", "model": model, "method": method, "start": str(start),
            "rep": "0", "success": success, "time_s": time_s, "errors_m": "10;12;14;16"
            if success == "1" else ";;;", "radius_m": "50.0", "tight_radius_m": "25.0",
            "tight_success": tight_success, "tight_time_s": tight_time,
            "tight_errors_m": "5;5;5;5" if tight_success == "1" else ";;;", "sim_s": "1000.0",
            "cpu_s": "4.0", "wall_s": "5.0", "plan_ms_median": "9.0"}


def test_summary_states_the_criterion_and_both_readings():
    sc = scenario("localise", "cv", preset="field")
    ident = {"scenario": "localise", "preset": "field", "seed": 0,
             "settings": {"cv": sc.describe()}}
    rows = [_row("cv", "mexgen", s, "1", str(300.0 + 10 * s), "1" if s < 2 else "0",
                 "700.0" if s < 2 else "") for s in range(4)]
    rows += [_row("cv", "pim", s, "1" if s < 2 else "0", "500.0" if s < 2 else "")
             for s in range(4)]
    text = summary_markdown(rows, ident)
    assert "95 % radius" in text and "first drops to 50 m" in text
    assert "## Localised at 50 m (criterion in use)" in text
    assert "## Localised at 25 m (tight reading, same runs)" in text
    assert "sensitivity -60 dB" in text and "front-to-back 3 dB" in text
    assert "acceleration 0.1 m/s² (truth) / 0.1 (filter)" in text
    # MexGen 4/4: Wilson [0.51, 1.00]; PIM 2/4, its KM median is 500 s, not beyond the limit
    assert "| CV | MexGen | 4 | 1.00 [0.51, 1.00] |" in text
    assert "| CV | PIM | 4 | 0.50 [0.15, 0.85] |" in text
    # paired: PIM - MexGen restricted times: 500-300, 500-310, 1000-320, 1000-330
    d = np.array([200.0, 190.0, 680.0, 670.0])
    assert f"| CV | PIM | 4 | {paired_mean(d).text(1)} | 4 | 0 | 2 |" in text
