"""Seeds of an experiment run, so that comparisons between methods are paired.

No frames here. Every generator of a run derives from numpy ``SeedSequence``:

- world truth: ``SeedSequence([seed, start])``. The paper runs 30 Monte Carlo simulations on
  each of 50 unique starting states (trajectories); the truth depends on the start only, so
  every repetition and every method sees the same objects;
- the radio world of a reality profile: ``SeedSequence([seed, start, REALITY_KEY])``, per
  start like the truth, so every repetition, method and estimator meets the same world;
- the run: ``SeedSequence([seed, start, rep])`` spawns two children, radio noise (0) and the
  GCS (1: filters and planner, as ``mission.run`` splits them). A method's choices consume the
  GCS stream only, so they never change the truth or the radio noise another method sees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class RunSeeds:
    radio: np.random.SeedSequence
    gcs: np.random.SeedSequence


REALITY_KEY = 0x7EA1
"""Third entropy word of a start's reality seed (differs from any repetition index used)."""


def reality_seed(seed: int, start: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([seed, start, REALITY_KEY])


def truth_seed(seed: int, start: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([seed, start])


def run_seeds(seed: int, start: int, rep: int) -> RunSeeds:
    radio, gcs = np.random.SeedSequence([seed, start, rep]).spawn(2)
    return RunSeeds(radio=radio, gcs=gcs)
