"""Compare arms of the field-finish study (docs/results/field-finish.md) run on the same seed:
per arm the Success at 50 m, the share of runs with all four tags under 50 / 75 / 100 m by the
limit, Kaplan-Meier median times, claim and final-estimate coverage, final errors and radii,
reasons, each with its 95 % interval; then every arm against the first on the same starts
(paired differences of min(time to all under R, limit)).

    python scripts/field_finish_compare.py NAME=DIR[:METHOD] NAME=DIR[:METHOD] ...
"""

from __future__ import annotations

import sys

import numpy as np

from mexgen_gcs.experiments.stats import km_median, paired_mean, success_ci
from mexgen_gcs.experiments.store import read_rows
from mexgen_gcs.experiments.summary import floats, reason_counts, under_times

LIMIT_S = 1000.0


def _arm(spec: str) -> tuple[str, list[dict[str, str]]]:
    name, where = spec.split("=", 1)
    path, _, method = where.partition(":")
    rows = [r for r in read_rows(path) if r["method"] == (method or "mexgen")]
    return name, sorted(rows, key=lambda r: int(r["start"]))


def _time(rows: list[dict[str, str]], col: str) -> tuple[np.ndarray, np.ndarray]:
    done = np.array([r.get(col, "") != "" for r in rows])
    t = np.array([float(r[col]) if d else LIMIT_S for r, d in zip(rows, done, strict=True)])
    return t, done


def main(argv: list[str]) -> int:
    arms = [_arm(a) for a in argv]
    print("| arm | runs | Success 50 m | all < 50 m | all < 75 m | all < 100 m | median to "
          "50 / 75 / 100 m (s) | all reported, median (s) | claims inside | final inside | "
          "final error median (m) | final radius median (m) | reached / stalled / budget / "
          "never |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, rows in arms:
        n = len(rows)
        ok = sum(r["success"] == "1" for r in rows)
        unders, medians = [], []
        for radius in (50, 75, 100):
            t, done = under_times(rows, radius, LIMIT_S)
            unders.append(success_ci(int(done.sum()), n).text(2))
            medians.append(km_median(t, done, LIMIT_S).text(0, beyond="> 1000"))
        ends = floats(r.get("all_reported_s", "") for r in rows)
        inside = sum(int(r["inside"]) for r in rows)
        claims = sum(int(r["n_localised"]) for r in rows)
        fr = floats(x for r in rows for x in r["final_radii_m"].split(";"))
        fe = floats(x for r in rows for x in r["final_errors_m"].split(";"))
        c = reason_counts(rows)
        held = int((fe <= fr).sum())
        print(f"| {name} | {n} | {success_ci(ok, n).text(2)} | {' | '.join(unders)} | "
              f"{' / '.join(medians)} | {f'{np.median(ends):.0f}' if ends.size else '–'} | "
              f"{inside}/{claims} {success_ci(inside, claims).text(2)} | "
              f"{held}/{fr.size} {success_ci(held, fr.size).text(2)}"
              f" | {np.median(fe):.1f} | {np.median(fr):.1f} | "
              f"{c['reached']} / {c['stalled']} / {c['budget']} / {c['']} |")
    base_name, base = arms[0]
    print()
    print(f"Paired on the same starts, arm - {base_name}: mean difference of min(time, "
          f"{LIMIT_S:g} s) with its 95 % t interval (s), and the mean final error difference (m)")
    print()
    print("| arm | pairs | Δ to all < 50 m | Δ to all < 75 m | Δ to all < 100 m | "
          "Δ final error (m) |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, rows in arms[1:]:
        by = {r["start"]: r for r in base}
        pairs = [(r, by[r["start"]]) for r in rows if r["start"] in by]
        cells = []
        for radius in (50, 75, 100):
            col = f"all_under_{radius}_s"
            a, _ = _time([p[0] for p in pairs], col)
            b, _ = _time([p[1] for p in pairs], col)
            cells.append(paired_mean(a - b).text(0))
        ea = np.array([np.mean(floats(p[0]["final_errors_m"].split(";"))) for p in pairs])
        eb = np.array([np.mean(floats(p[1]["final_errors_m"].split(";"))) for p in pairs])
        print(f"| {name} | {len(pairs)} | {' | '.join(cells)} | {paired_mean(ea - eb).text(1)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
