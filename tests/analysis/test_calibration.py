"""Path-loss calibration: exact on noiseless data, robust to clutter, and on a real SITL flight
it recovers the simulator's radio model (the mission's radio section: P0 -7 dB, n 1.5,
noise 2.5 dB).

Stated tolerance on the 150 s SITL flight (~1400 detections, 60-900 m): P0 within 2.5 dB and
n within 0.1 (both about 3 standard errors of the fit: P0 at d0 = 1 m is extrapolated two
decades below the data), noise std within 0.35 dB, and the fitted curve within 0.5 dB of the
simulator's over 100-800 m, where the detections are.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.analysis import calibrate, fit_path_loss, load_flight, load_truth
from mexgen_gcs.analysis.cli import cmd_analyze
from mexgen_gcs.config import parse_mission
from mexgen_gcs.errors import EstimationError

TRUE_P0_DB, TRUE_N, TRUE_SIGMA_DB = -7.0, 1.5, 2.5


@settings(max_examples=30, deadline=None)
@given(p0=st.floats(-30.0, 10.0), n=st.floats(1.0, 4.0), gain=st.floats(-3.0, 0.0))
def test_noiseless_data_is_fitted_exactly(p0: float, n: float, gain: float) -> None:
    d = np.geomspace(20.0, 2000.0, 50)
    z = p0 - 10.0 * n * np.log10(d) + gain
    fit = fit_path_loss(d, z, gain_db=gain)
    assert fit.p0_db == pytest.approx(p0, abs=1e-6)
    assert fit.path_loss_exponent == pytest.approx(n, abs=1e-7)
    assert fit.noise_std_db < 1e-6 and fit.outliers == 0


def test_noise_and_clutter_are_separated() -> None:
    rng = np.random.default_rng(12)
    d = np.exp(rng.uniform(np.log(50.0), np.log(1500.0), 3000))
    z = TRUE_P0_DB - 10 * TRUE_N * np.log10(d) + rng.normal(0.0, TRUE_SIGMA_DB, d.size)
    clutter = rng.random(d.size) < 0.05
    z[clutter] = rng.uniform(-90.0, 0.0, clutter.sum())
    fit = fit_path_loss(d, z)
    assert fit.p0_db == pytest.approx(TRUE_P0_DB, abs=1.0)
    assert fit.path_loss_exponent == pytest.approx(TRUE_N, abs=0.04)
    assert fit.noise_std_db == pytest.approx(TRUE_SIGMA_DB, abs=0.15)
    # clutter inside the +-4 sigma band (20 of 90 dB) is indistinguishable from signal
    assert 0.6 * clutter.sum() <= fit.outliers <= clutter.sum() + 3


def test_degenerate_input_is_refused() -> None:
    with pytest.raises(EstimationError, match="at least"):
        fit_path_loss(np.array([100.0, 200.0]), np.array([-40.0, -45.0]))
    with pytest.raises(EstimationError, match="range of distances"):
        fit_path_loss(np.full(50, 300.0), np.full(50, -45.0))


@pytest.mark.e2e
def test_sitl_flight_recovers_the_simulators_radio_model(demo_log: Path) -> None:
    flight = load_flight(demo_log)
    fit = calibrate(flight, flight.tag_ids, "truth", load_truth(demo_log))
    assert fit.used > 500
    assert fit.p0_db == pytest.approx(TRUE_P0_DB, abs=2.5)
    assert fit.path_loss_exponent == pytest.approx(TRUE_N, abs=0.1)
    assert fit.noise_std_db == pytest.approx(TRUE_SIGMA_DB, abs=0.35)
    d = np.geomspace(100.0, 800.0, 20)
    true_curve = TRUE_P0_DB - 10 * TRUE_N * np.log10(d)
    assert np.abs(fit.predict_db(d) - true_curve).max() < 0.5


@pytest.mark.e2e
def test_calibrate_prints_a_radio_block_the_mission_file_accepts(
        demo_log: Path, capsys: pytest.CaptureFixture[str], make_args: Any,
        missions_dir: Path) -> None:
    assert cmd_analyze(make_args(log=str(demo_log), out=str(demo_log / "cal-report"),
                                 calibrate="T3")) == 0
    out = capsys.readouterr().out
    block = out[out.index("# fitted from"):]
    doc = yaml.safe_load(block)
    radio = doc["radio"]
    assert radio["p0_db"] == pytest.approx(TRUE_P0_DB, abs=5.0)
    # one tag calibrated: its own power is printed as a tight per-tag prior
    (tag,) = doc["tags"]
    assert tag["id"] == "T3" and tag["p0_db"] == radio["p0_db"] and 0.5 <= tag["p0_std_db"] < 3
    mission = yaml.safe_load((missions_dir / "demo.yaml").read_text())
    mission["radio"] = radio
    mission["tags"] = [tag if t["id"] == "T3" else t for t in mission["tags"]]
    parsed = parse_mission(yaml.safe_dump(mission), source="calibrated")
    assert parsed.radio.path_loss_exponent == radio["path_loss_exponent"]
    prior = parsed.tag_radio_priors()["T3"]
    assert prior.offset_db == pytest.approx(tag["p0_db"] - radio["p0_db"])
    assert prior.std_db == tag["p0_std_db"]


@pytest.mark.e2e
def test_calibrate_with_a_surveyed_position_and_bad_requests(
        demo_log: Path, capsys: pytest.CaptureFixture[str], make_args: Any) -> None:
    flight = load_flight(demo_log)
    lat, lon, _ = flight.frame.to_geodetic(-200.0, 150.0, 0.0)  # T3's true position
    out_dir = str(demo_log / "cal-report")
    assert cmd_analyze(make_args(log=str(demo_log), out=out_dir, calibrate="T3",
                                 tag_position=f"{float(lat):.8f},{float(lon):.8f}")) == 0
    assert "given positions" in capsys.readouterr().out
    assert cmd_analyze(make_args(log=str(demo_log), out=out_dir, calibrate="T9")) == 2
    assert "no tag 'T9'" in capsys.readouterr().err
    assert cmd_analyze(make_args(log=str(demo_log), out=out_dir, calibrate="T3",
                                 tag_position="north,east")) == 2
    assert cmd_analyze(make_args(log=str(demo_log), out=out_dir, calibrate="all",
                                 tag_position="-34.9,138.6")) == 2
