"""Filter benchmark: one predict + update per motion model and estimator at N = 1000, 2000
(the mission default), 10000, for a pulse detected (-45 dB) and for a pulse missed (where
detection is uncertain most pulses are misses, and the robust estimator's misses move each
particle's radio unknowns too).

The receiver flies a 300 m circle at 10 m/s, one pulse a second, so the robust estimator's
shadowing memory fills with cells and conditions each detection on its neighbours as in
flight. Estimators: ``classic`` (the radio model trusted exactly) and ``robust`` (the mission
file's defaults: per-tag P0 offset and path-loss exponent, shadowing and model-error levels,
outliers; `config.schema.RadioSection`). Frame: ENU metres.

Run: `mexgen-gcs bench filter --json` (or `python -m mexgen_gcs.bench.filter --json`).
"""

from __future__ import annotations

import argparse
import itertools
import math
from typing import Any

import numpy as np

from mexgen_gcs.bench.timing import emit, pin_single_thread, time_calls
from mexgen_gcs.config.schema import RadioSection
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import BernoulliFilter, FilterConfig
from mexgen_gcs.core.motion import MotionName, make_motion_model
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.radio_belief import RadioUncertainty

MODELS: tuple[MotionName, ...] = ("rw", "cv", "ctra", "cv-ift", "cv-mismatch")
PULSES: tuple[str, ...] = ("detection", "miss")


ESTIMATORS: dict[str, RadioUncertainty] = {
    "classic": RadioUncertainty(),
    "robust": RadioSection().uncertainty(),
}


def run(iterations: int = 200, sizes: tuple[int, ...] = (1000, 2000, 10000),
        models: tuple[MotionName, ...] = MODELS,
        estimators: tuple[str, ...] = tuple(ESTIMATORS),
        pulses: tuple[str, ...] = PULSES) -> dict[str, Any]:
    radio = RadioModel()
    area = SearchArea.rectangle(-500, 500, -500, 500)
    out: dict[str, Any] = {"what": "filter predict+update (a pulse detected at -45 dB or "
                                   "missed, receiver on a 300 m circle at 10 m/s)",
                           "results": []}
    for estimator, name, n, pulse in itertools.product(estimators, models, sizes, pulses):
        f = BernoulliFilter(make_motion_model(name), radio, area,
                            FilterConfig(n_particles=n,
                                         radio_unknowns=ESTIMATORS[estimator]),
                            np.random.default_rng(0))
        z = np.array([-45.0] if pulse == "detection" else [])
        clock = [0.0]

        def step(f: BernoulliFilter = f, z: np.ndarray = z,
                 clock: list[float] = clock) -> None:
            clock[0] += 1.0
            a = clock[0] * 10.0 / 300.0  # rad: 10 m/s on a 300 m circle
            rx = np.array([300.0 * math.cos(a), 300.0 * math.sin(a), 50.0])
            f.predict(1.0)
            f.update(z, rx, (-a) % (2.0 * math.pi))  # compass yaw along the circle

        row = {"estimator": estimator, "model": name, "n_particles": n,
               "pulse": pulse, **time_calls(step, iterations)}
        out["results"].append(row)
    return out


def _table(result: dict[str, Any]) -> str:
    lines = [f"{result['what']}: median (min-max) ms",
             "estimator model        N      pulse      median   min    max"]
    for r in result["results"]:
        lines.append(f"{r['estimator']:<9} {r['model']:<12} {r['n_particles']:<6} "
                     f"{r['pulse']:<9} "
                     f"{r['median_ms']:7.3f} {r['min_ms']:6.3f} {r['max_ms']:6.3f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    pin_single_thread()
    p = argparse.ArgumentParser(prog="mexgen-gcs bench filter")
    p.add_argument("--json", action="store_true")
    p.add_argument("--iterations", type=int, default=200)
    a = p.parse_args(argv)
    emit(run(a.iterations), a.json, _table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
