"""The robust estimator's 95 % radius against worlds it does not model, without the planner:
one tag, a fixed inward spiral flown over it (the same flight whatever the estimate), many
seeded worlds, and the share of radii that held the tag, with its Wilson interval. The quick
check runs in the default tests; ``-m slow`` runs the 1000-survey study quoted in
docs/results/localisation.md.

Frame: local ENU metres about home (the experiment world's)."""

from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import stats

from mexgen_gcs.core.bernoulli import BernoulliFilter
from mexgen_gcs.core.reality import profile
from mexgen_gcs.experiments.scenario import PresetName, mission_for, scenario
from mexgen_gcs.experiments.world import RadioWorld

SURVEY_S = 1200
"""Pulses (seconds) of one survey: a spiral from 330 m to 30 m about a point near the tag."""


@dataclass(frozen=True)
class Coverage:
    surveys: int
    claims: int
    claims_inside: int
    final_inside: int

    def final_interval(self) -> tuple[float, float]:
        ci = stats.binomtest(self.final_inside, self.surveys).proportion_ci(method="wilson")
        return float(ci.low), float(ci.high)


def survey_coverage(reality: str, seeds: range, preset: PresetName = "paper") -> Coverage:
    """Fly the spiral once per seed in a world drawn from ``reality``; count the first
    localisation claim of each survey and whether it held, and whether the final 95 % radius
    held the tag. The estimator is the experiments' robust one with the ``preset``'s
    settings: "paper" hears every pulse, "field" a tag only within its range. The seeds are
    shared among worker processes, one per core (each survey depends only on its seed)."""
    workers = min(len(os.sched_getaffinity(0)), len(seeds))
    if workers < 2:
        return _surveys(reality, seeds, preset)
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        parts = list(pool.map(_surveys, [reality] * workers,
                              [seeds[k::workers] for k in range(workers)], [preset] * workers))
    return Coverage(*(sum(getattr(c, f) for c in parts)
                      for f in ("surveys", "claims", "claims_inside", "final_inside")))


def _surveys(reality: str, seeds: range, preset: PresetName) -> Coverage:
    """:func:`survey_coverage` in this process."""
    sc = scenario("localise", "static", preset=preset, reality="matched", estimator="robust")
    mission = mission_for(sc, "mexgen")
    radio, config = mission.radio_model(), mission.filter_config()
    claims = claims_inside = final_inside = 0
    for seed in seeds:
        rng = np.random.default_rng([seed, 7])
        world = profile(reality).realise(radio, 1, rng)
        tag_xy = rng.uniform(-250.0, 250.0, 2)
        centre = tag_xy + rng.uniform(-60.0, 60.0, 2)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        radios = RadioWorld(radio, 1, np.random.default_rng([seed, 8]), world)
        f = BernoulliFilter(mission.filter_motion_model(), radio, sc.initial_area(), config,
                            np.random.default_rng([seed, 9]))
        claim: tuple[float, float] | None = None
        for t in range(SURVEY_S):
            radius_m = 330.0 - 300.0 * t / SURVEY_S
            angle += 10.0 / radius_m  # 10 m/s along the spiral
            east, north = centre + radius_m * np.array([math.sin(angle), math.cos(angle)])
            yaw_rad = (angle + math.pi / 2.0) % (2.0 * math.pi)
            rx = np.array([east, north, 50.0])
            z = radios.pulse(tag_xy[None, :], rx, yaw_rad)[0]
            f.predict(1.0)
            f.update(np.asarray(z, dtype=np.float64), rx, yaw_rad)
            if claim is None:
                est = f.estimate()
                if est.localised:
                    claim = (math.dist(est.mean[:2], tag_xy), est.radius_m)
        if claim is not None:
            claims += 1
            claims_inside += claim[0] <= claim[1]
        est = f.estimate()
        final_inside += math.dist(est.mean[:2], tag_xy) <= est.radius_m
    return Coverage(len(seeds), claims, claims_inside, final_inside)


@pytest.mark.long
def test_the_final_radius_holds_in_the_field_world():
    """Shadowing with fading, an antenna, terrain, transmit offsets, exponent and compass the
    model does not know: 48 surveys, the final 95 % radii hold for at least 0.9 of them and
    at most one claim misses (47 of 48 and 11 of 11 on the machine that wrote this; with
    each detection conditioned on 6 neighbour cells instead of 12, 2 of 17 claims missed,
    and over 1000 surveys the final radii held for 0.88 against 0.97)."""
    cov = survey_coverage("field", range(48))
    assert cov.final_inside >= 0.9 * cov.surveys, cov
    assert cov.claims_inside >= cov.claims - 1, cov


@pytest.mark.long
def test_misses_teach_the_estimator_where_detection_is_uncertain():
    """The field preset hears a tag only within its range, and most pulses are misses: each
    miss must move the particle's belief about the offset and exponent, not only its weight
    (core.filter_kernels.miss_moments), and misses in one shadowed patch must count about
    once (core.filter_kernels.correlated_miss). 48 field-world surveys, on the machine that
    wrote this: the final radii held for 48 and 8 of 8 claims (32 and no claim when misses
    moved only the weights; 38 and 7 of 10 when each miss counted in full; over 400
    surveys: docs/results/localisation.md)."""
    cov = survey_coverage("field", range(48), preset="field")
    assert cov.final_inside >= 44, cov
    assert cov.claims >= 4 and cov.claims_inside >= cov.claims - 1, cov


@pytest.mark.long
def test_the_final_radius_holds_in_the_matched_world():
    """The model's own world: the surveys claim, and the 95 % radii hold. The bounds are the
    claim's, not a run's: the fewest held radii a true 95 % gives in all but 0.5 % of such
    batches (binomial; 1000 of 1000 surveys claimed in the slow study, 0.958 of the claims
    and 0.967 of the final radii held)."""
    cov = survey_coverage("matched", range(24))
    assert cov.claims >= 23, cov
    assert cov.claims_inside >= fewest_held(cov.claims), cov
    assert cov.final_inside >= fewest_held(cov.surveys), cov


def fewest_held(n: int, p: float = 0.95, alpha: float = 0.005) -> int:
    """The smallest count of n radii, each holding with probability p, that is not below the
    alpha quantile of Binomial(n, p): fewer is evidence (at level alpha) that p is not met."""
    return int(stats.binom.ppf(alpha, n, p))


@pytest.mark.slow
@pytest.mark.timeout(3600)  # 0.4-1.2 s a survey, by machine
@pytest.mark.parametrize("reality", ["matched", "shadowing", "field"])
def test_survey_study(reality):
    """The study in docs/results/localisation.md (1000 surveys per world)."""
    cov = survey_coverage(reality, range(1000, 2000))
    low, high = cov.final_interval()
    claims = cov.claims_inside / max(cov.claims, 1)
    print(f"\n{reality}: final {cov.final_inside / cov.surveys:.3f} [{low:.3f}, {high:.3f}]; "
          f"claims {cov.claims}, inside {claims:.3f}")
    assert low >= 0.9


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.xfail(strict=True, reason=(
    "open (docs/results/localisation.md, 'An antenna the model does not know, on a long "
    "orbit'): an "
    "error that repeats with the geometry is read as a place, and the radius keeps shrinking"))
def test_the_final_radius_after_a_long_orbit_with_an_unmodelled_antenna():
    """A known failure, kept (strict: it must fail) so that it says when it is fixed: 200
    antenna-world surveys (4-5 minutes); the final radii held for 0.155 of them and the
    claims for 0.95 when this was written, 0.770 and 0.960 with the front-to-back ratio an
    unknown (2026-11-27): the lobe off the nose and the two-lobe term are left."""
    cov = survey_coverage("antenna", range(1000, 1200))
    low, high = cov.final_interval()
    print(f"\nantenna: final {cov.final_inside / cov.surveys:.3f} [{low:.3f}, {high:.3f}]; "
          f"claims {cov.claims}, inside {cov.claims_inside / max(cov.claims, 1):.3f}")
    assert low >= 0.9
