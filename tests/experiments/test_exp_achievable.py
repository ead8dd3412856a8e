"""Success is reachable by design: with the vehicle circling the true object (the best place
to be, whatever the planner), each model's filter gets below the localisation criterion."""

import numpy as np
import pytest

from mexgen_gcs.core.likelihood import detection_table
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.experiments.achievable import circling_radius
from mexgen_gcs.experiments.scenario import (
    MODELS,
    PAPER_SENSITIVITY_DB,
    mission_for,
    scenario,
    weakest_power_db,
)


@pytest.mark.parametrize("preset", ["paper", "field"])
@pytest.mark.parametrize("model", MODELS)
def test_circling_the_object_the_radius_gets_below_the_criterion(model, preset):
    """Three starts, 300 s each at a 30 m circle (11 m/s, the acceleration limit's speed):
    the radius drops to 50 m within a minute, and the best tenth of the last 200 s is below
    it. (Medians, seen: RW 12-15 m, CV 31-36 m, CV-IFT 39-45 m, mismatch 49-55 m.)"""
    sc = scenario("localise", model, preset=preset)
    runs = [circling_radius(sc, circle_m=30.0, seconds=300, start=s) for s in range(3)]
    for r in runs:
        assert np.all(np.isfinite(r))
        assert r[:60].min() <= sc.localised_radius_m
    steady = np.concatenate([r[100:] for r in runs])
    assert np.percentile(steady, 10) < sc.localised_radius_m
    if model == "rw":  # only a random walk lets the filter reach the tight reading
        assert np.median(steady) < sc.tight_radius_m


def test_far_from_the_object_the_radius_stays_wide():
    """The check can fail: circling 1.5 km away, a CV tag is never localised."""
    r = circling_radius(scenario("localise", "cv"), circle_m=1500.0, seconds=200)
    assert r.min() > 50.0


@pytest.mark.parametrize("kind", ["localise", "follow"])
def test_paper_preset_hears_every_pulse_in_the_area(kind):
    """The paper's sensor: omnidirectional, pD exactly 1 down to the weakest power in the
    operating area (its diagonal at the flight altitude), table included."""
    sc = scenario(kind, "cv")
    radio = mission_for(sc, "mexgen").radio_model()
    assert radio.front_back_db == 0.0 and radio.pd_max == 1.0
    assert radio.sensitivity_db == PAPER_SENSITIVITY_DB
    weakest = weakest_power_db(sc)
    assert weakest == pytest.approx(-63.29 if kind == "localise" else -70.45, abs=0.01)
    assert (weakest - radio.sensitivity_db) / radio.detection_spread_db >= 24.0
    assert radio.detection_probability(np.array([weakest])) == 1.0
    assert detection_table(radio).pd(np.float32([weakest, -7.0])).tolist() == [1.0, 1.0]
    field = mission_for(scenario(kind, "cv", preset="field"), "mexgen").radio_model()
    assert field == RadioModel()  # the mission defaults
