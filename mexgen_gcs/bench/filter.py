"""Filter benchmark: one predict + update (a detection) per motion model at N = 1000, 10000.

Run: `mexgen-gcs bench filter --json` (or `python -m mexgen_gcs.bench.filter --json`).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from mexgen_gcs.bench.timing import emit, pin_single_thread, time_calls
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import BernoulliFilter, FilterConfig
from mexgen_gcs.core.motion import MotionName, make_motion_model
from mexgen_gcs.core.radio import RadioModel

MODELS: tuple[MotionName, ...] = ("rw", "cv", "ctra", "cv-ift", "cv-mismatch")


def run(iterations: int = 200, sizes: tuple[int, ...] = (1000, 10000)) -> dict[str, Any]:
    radio = RadioModel()
    area = SearchArea.rectangle(-500, 500, -500, 500)
    rx = np.array([100.0, -50.0, 50.0])
    out: dict[str, Any] = {"what": "filter predict+update (one detection)", "results": []}
    for name in MODELS:
        for n in sizes:
            f = BernoulliFilter(make_motion_model(name), radio, area,
                                FilterConfig(n_particles=n), np.random.default_rng(0))
            z = np.array([-45.0])

            def step(f: BernoulliFilter = f, z: np.ndarray = z) -> None:
                f.predict(1.0)
                f.update(z, rx, 0.5)

            row = {"model": name, "n_particles": n, **time_calls(step, iterations)}
            out["results"].append(row)
    return out


def _table(result: dict[str, Any]) -> str:
    lines = [f"{result['what']}: median (min-max) ms", "model        N      median   min    max"]
    for r in result["results"]:
        lines.append(f"{r['model']:<12} {r['n_particles']:<6} {r['median_ms']:7.3f} "
                     f"{r['min_ms']:6.3f} {r['max_ms']:6.3f}")
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
