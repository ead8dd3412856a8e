"""Run one arm of the field-finish study (docs/results/field-finish.md): the static,
field-profile, robust-estimator localisation batch with chosen scenario overrides that the CLI
has no flag for, e.g. ``planner_toward_target=true``.

    python scripts/field_finish_arm.py --out DIR --seed 31 --starts 40 [--finish]
        [--reality field] [--methods mexgen] [--set planner_toward_target=true ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys

from mexgen_gcs.experiments.cli import parse_methods, run_experiment
from mexgen_gcs.experiments.scenario import scenario


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=31)
    p.add_argument("--starts", type=int, default=40)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--reality", default="field")
    p.add_argument("--methods", default="mexgen")
    p.add_argument("--finish", action="store_true")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=JSON")
    a = p.parse_args()
    sc = scenario("localise", "static", reality=a.reality, estimator="robust", finish=a.finish)
    sc = dataclasses.replace(sc, **{k: json.loads(v) for k, v in
                                    (item.split("=", 1) for item in a.set)})
    res = run_experiment(sc, parse_methods(a.methods), starts=a.starts, reps=1, seed=a.seed,
                         out_dir=a.out, workers=a.workers,
                         command=shlex.join(["python", *sys.argv]))
    print(f"{res.completed} runs done, {len(res.failures)} failed: {a.out}/summary.md")
    return 0 if not res.failures else 1


if __name__ == "__main__":
    raise SystemExit(main())
