"""An experiment's summary.md: what was run (sensor, motion noise, planner, the localisation
criterion) and what came out, with intervals.

No frames here. Localisation, for each of the two readings of the same runs (the criterion in
use, 50 m, and the tight 25 m): the paper's Table II layout (Success, Error +- sigma over the
tags of the successful runs, Time +- sigma over the successful runs, sigma the population
standard deviation) plus Success with its Wilson interval, the Kaplan-Meier median time and the
mean of min(Time, limit) over all runs (failed runs counted at the limit, not dropped); then
every method against MexGen on the same (start, repetition): the paired difference of
min(Time, limit) with its interval, who finished first, and the classic both-succeeded
difference. Following: Error and Tr(Cov) per method. Then the throughput.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from mexgen_gcs.experiments.scenario import MODELS, method_label, ordered_methods
from mexgen_gcs.experiments.stats import (
    km_median,
    paired_mean,
    restricted_mean,
    success_ci,
)

MODEL_LABELS = {"static": "Static", "rw": "RW", "cv": "CV", "cv-ift": "CV-IFT",
                "cv-ift-mismatch": "CV-IFT Mismatch"}
PAPER_TABLE_II: dict[tuple[str, str], tuple[float, str, str]] = {
    ("rw", "pim"): (1.0, "12.4 ± 9.2", "297.7 ± 93.7"),
    ("rw", "mc8"): (1.0, "12.4 ± 8.6", "255.6 ± 64.4"),
    ("rw", "mexgen"): (1.0, "12.1 ± 8.4", "231.0 ± 55.6"),
    ("cv", "pim"): (0.98, "11.7 ± 9.2", "444.7 ± 115.1"),
    ("cv", "mc8"): (1.0, "11.7 ± 8.9", "405.2 ± 92.0"),
    ("cv", "mexgen"): (1.0, "12.1 ± 9.7", "360.1 ± 74.8"),
    ("cv-ift", "pim"): (0.53, "12.8 ± 9.7", "645.5 ± 194.7"),
    ("cv-ift", "mc8"): (0.90, "12.5 ± 9.4", "558.6 ± 183.6"),
    ("cv-ift", "mexgen"): (0.99, "12.6 ± 9.6", "465.5 ± 159.9"),
    ("cv-ift-mismatch", "pim"): (0.22, "12.0 ± 7.4", "726.4 ± 181.4"),
    ("cv-ift-mismatch", "mc8"): (0.66, "11.5 ± 7.1", "651.0 ± 185.2"),
    ("cv-ift-mismatch", "mexgen"): (0.90, "11.5 ± 7.1", "567.4 ± 185.9"),
}
"""The paper's Table II: (success, error +- sigma m, time +- sigma s) per (model, method)."""

Rows = list[dict[str, str]]
READINGS = (("", "criterion in use"), ("tight_", "tight reading, same runs"))
"""runs.csv column prefix of each localisation reading."""


def groups(rows: Rows) -> list[tuple[str, str, Rows]]:
    """(model, method, rows) in the canonical order."""
    out: list[tuple[str, str, Rows]] = []
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        for method in ordered_methods(r["method"] for r in rows):
            sel = [r for r in rows if r["model"] == model and r["method"] == method]
            if sel:
                out.append((model, method, sel))
    return out


def floats(values: Iterable[str]) -> np.ndarray:
    return np.array([float(v) for v in values if v != ""], dtype=np.float64)


def _pm(x: np.ndarray, digits: int = 1) -> str:
    if x.size == 0:
        return "–"
    return f"{x.mean():.{digits}f} ± {x.std():.{digits}f}"


def has_reading(rows: Rows, prefix: str) -> bool:
    """Whether the rows carry this reading (format-1 runs.csv has no tight one)."""
    return any(r.get(f"{prefix}success", "") != "" for r in rows) and (
        prefix == "" or any(r.get("tight_radius_m", "") != "" for r in rows))


def outcomes(rows: Rows, prefix: str, limit_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, done) per run of one reading: done runs at their time, failed at the limit."""
    done = np.array([r.get(f"{prefix}success") == "1" for r in rows])
    t = np.array([float(r[f"{prefix}time_s"]) if d else limit_s for r, d in zip(rows, done,
                                                                              strict=True)])
    return t, done


def localise_stats(rows: Rows, prefix: str = "") -> dict[str, Any]:
    """Success rate, errors (m, per tag of the successful runs) and times (s) of runs."""
    ok = [r for r in rows if r.get(f"{prefix}success") == "1"]
    errors = floats(e for r in ok for e in r[f"{prefix}errors_m"].split(";"))
    return {"runs": len(rows), "successes": len(ok),
            "success": len(ok) / len(rows) if rows else math.nan,
            "errors": errors, "times": floats(r[f"{prefix}time_s"] for r in ok)}


def limit_of(ident: dict[str, Any], model: str) -> float:
    settings = (ident.get("settings") or {}).get(model) or {}
    return float(settings.get("duration_s", 1000.0))


def summary_markdown(rows: Rows, ident: dict[str, Any]) -> str:
    kind = str(ident.get("scenario", rows[0]["scenario"] if rows else "?"))
    lines = [f"# Experiment: {kind} ({ident.get('preset', '?')} preset, seed "
             f"{ident.get('seed', '?')})", ""]
    lines += settings_lines(ident, kind)
    if not rows:
        return "\n".join([*lines, "No runs yet.", ""])
    lines += [f"{len(rows)} runs in runs.csv.", ""]
    if kind == "localise":
        for prefix, what in READINGS:
            if not has_reading(rows, prefix):
                continue
            radius = _radius(rows, ident, prefix)
            lines += [f"## Localised at {radius} ({what})", "", *_localise_table(
                rows, ident, prefix), "", *_coverage_table(rows, prefix), "",
                *_paired_table(rows, ident, prefix), ""]
        lines += _finish_section(rows, ident)
    else:
        lines += _follow_table(rows)
    lines += ["", *_throughput_table(rows), ""]
    return "\n".join(lines)


def _radius(rows: Rows, ident: dict[str, Any], prefix: str) -> str:
    col = "tight_radius_m" if prefix else "radius_m"
    values = sorted({float(r[col]) for r in rows if r.get(col, "")})
    if not values and not prefix:  # format 1: the settings say it
        values = sorted({float(s.get("localised_radius_m", 50.0))
                         for s in (ident.get("settings") or {}).values()}) or [50.0]
    return " / ".join(f"{v:g} m" for v in values)


# -- settings ----------------------------------------------------------------------------

def settings_lines(ident: dict[str, Any], kind: str) -> list[str]:
    """What was run, from experiment.json: sensor, motion noise, planner, criterion."""
    settings: dict[str, dict[str, Any]] = ident.get("settings") or {}
    if not settings:
        return []
    s = next(iter(settings.values()))
    g = s.get
    out = ["## Settings", ""]
    fb, pd_max, sens = g("front_back_db", 3.0), g("pd_max", 0.95), g("sensitivity_db", -60.0)
    if pd_max >= 1.0 and sens <= -100.0:
        sensor = (f"every pulse inside the area detected (pD = 1: sensitivity {sens:g} dB, "
                  f"pd_max 1, far below the weakest power in the area)")
    else:
        sensor = (f"sensitivity {sens:g} dB, detection spread {g('detection_spread_db', 2.0):g}"
                  f" dB, pd_max {pd_max:g}")
    out.append(f"- Sensor: antenna front-to-back {fb:g} dB"
               f"{' (omnidirectional monopole)' if fb == 0 else ''}; {sensor}; noise 2.5 dB; "
               "P0 -7 dB at 1 m, path-loss exponent 1.5; clutter 0.01 per pulse.")
    noise = []
    for model, m in settings.items():
        if model == "static":
            noise.append("static tags (truth and filter)")
        elif model == "rw":
            noise.append(f"RW step {m.get('truth_rw_std_m_per_sqrt_s')} m/√s (truth) / "
                         f"{m.get('filter_rw_std_m_per_sqrt_s')} (filter)")
        elif model == "cv-ift-mismatch":
            noise.append(f"mismatch: truth CV-IFT {m.get('truth_accel_std_m_s2')} m/s², "
                         f"filter CV {m.get('mismatch_accel_std_m_s2')} m/s² (sized to the "
                         "turns: speed x turn rate and the IMM's turn persistence)")
        else:
            noise.append(f"{MODEL_LABELS[model]} acceleration {m.get('truth_accel_std_m_s2')}"
                         f" m/s² (truth) / {m.get('filter_accel_std_m_s2')} (filter)")
    out.append("- Motion noise per axis: " + "; ".join(noise) + f". Speeds "
               f"{g('truth_speed_m_s')} m/s, CV-IFT turn rates {g('truth_turn_rate_deg_s')} "
               "deg/s (filter IMM: their middle).")
    out.append(f"- Planner: look-ahead {g('lookahead_s'):g} s in 1 s steps"
               f"{', stretched to reach a far target' if g('planner_reach') else ''}; "
               f"detect/miss outcome {g('planner_outcome', 'collapsed')}; 8 headings at "
               f"{g('speed_m_s'):g} m/s, re-plan every {g('replan_interval_s'):g} s; "
               f"{g('planning_particles')} planning particles (filter "
               f"{g('filter_particles')}); MexGen {g('mexgen_samples')} samples, MC "
               f"{g('mc_rollouts')} rollouts.")
    reality, estimator = g("reality", "matched"), g("estimator", "classic")
    where = "the mission model itself" if reality == "matched" else "docs/results/localisation.md"
    how = ("trusts the radio model exactly" if estimator == "classic" else
           "each tag's power offset and path-loss exponent and the antenna's front-to-back "
           "ratio estimated with the position, shadowing and model-error hypotheses, "
           "outlier mixture")
    out.append(f"- Radio world: reality profile `{reality}` ({where}); estimator "
               f"`{estimator}` ({how}).")
    if kind == "localise":
        conf = g("localised_confidence", 0.95)
        tight = g("tight_radius_m")
        out.append(
            f"- Localisation criterion: a tag is localised when the {100 * conf:g} % radius "
            f"of its position estimate, from the trace of the position covariance taken as "
            f"isotropic (r = sqrt(-ln(1 - {conf:g}) tr)), first drops to "
            f"{g('localised_radius_m'):g} m (existence >= 0.5); it is then no longer "
            f"targeted. Success: all {g('n_tags')} localised within {g('duration_s'):g} s; "
            "Time: when the last one is; Error: |estimate - truth| at that moment."
            + (f" Second reading from the same runs: {tight:g} m (each run goes on after "
               f"the {g('localised_radius_m'):g} m completion, targeting the tags above "
               f"{tight:g} m, until the limit)." if tight else ""))
        if g("finish"):
            out.append(
                f"- Reporting (`--finish`): a tag is reported as reached at "
                f"{g('localised_radius_m'):g} m, stalled when its radius shrank by less than "
                f"{g('stall_min_shrink_percent'):g} % over {g('stall_window_s')} s of work on "
                f"it, or budget after {g('tag_budget_s')} s of work; the planner then moves "
                "on, and the run ends (RTL) when every tag is reported.")
    out.append("")
    return out


# -- tables ------------------------------------------------------------------------------

def _localise_table(rows: Rows, ident: dict[str, Any], prefix: str) -> list[str]:
    paper = prefix == ""
    head = ("| Model | Method | Runs | Success [95 % CI] | Error ± σ (m) | Time ± σ (s) | "
            "Median time, KM [95 % CI] (s) | Mean min(Time, limit) [95 % CI] (s) |")
    rule = "|---|---|---:|---:|---:|---:|---:|---:|"
    if paper:
        head += " Paper: Success | Paper: Error (m) | Paper: Time (s) |"
        rule += "---:|---:|---:|"
    out = [head, rule]
    for model, method, sel in groups(rows):
        limit = limit_of(ident, model)
        st = localise_stats(sel, prefix)
        t, done = outcomes(sel, prefix, limit)
        line = (f"| {MODEL_LABELS[model]} | {method_label(method)} | {st['runs']} | "
                f"{success_ci(st['successes'], st['runs']).text(2)} | {_pm(st['errors'])} | "
                f"{_pm(st['times'])} | {km_median(t, done, limit).text(beyond=f'> {limit:g}')}"
                f" | {restricted_mean(t, done, limit).text(0)} |")
        if paper:
            p = PAPER_TABLE_II.get((model, method))
            line += f" {p[0]:.2f} | {p[1]} | {p[2]} |" if p else " – | – | – |"
        out.append(line)
    out += ["", "Error and Time ± σ: over the successful runs, as the paper. The median (Kaplan-"
            "Meier) and the mean of min(Time, limit) count the failed runs at the limit."]
    return out


def coverage_stats(rows: Rows, prefix: str = "") -> dict[str, Any]:
    """Every tag localised in the runs (failed runs included): its error, its claimed radius,
    and how many lay inside their claim."""
    errors: list[float] = []
    radii: list[float] = []
    for r in rows:
        for e, rad in zip(r.get(f"{prefix}errors_m", "").split(";"),
                          r.get(f"{prefix}radii_m", "").split(";"), strict=False):
            if e != "" and rad != "":
                errors.append(float(e))
                radii.append(float(rad))
    err, claimed = np.array(errors), np.array(radii)
    return {"tags": int(err.size), "inside": int((err <= claimed).sum()), "errors": err,
            "radii": claimed}


def _coverage_table(rows: Rows, prefix: str) -> list[str]:
    """The share of localised tags inside the radius they claimed, per model and method."""
    if not any(r.get(f"{prefix}radii_m", "") for r in rows):
        return []  # format 2 and earlier: no claimed radii stored
    def head(radius: str) -> list[str]:
        return ["| Model | Method | Tags | Inside | Coverage [95 % CI] | Error median (m) | "
                f"Error 95th pct (m) | Error max (m) | {radius} median (m) |",
                "|---|---|---:|---:|---:|---:|---:|---:|---:|"]

    out = ["Coverage of the claim: localised tags (all runs, failed ones included) whose true "
           "position lay inside the 95 % radius they claimed when localised.", "",
           *head("Claimed radius"), *_coverage_rows(rows, prefix)]
    if not prefix and any(r.get("final_radii_m", "") for r in rows):  # format 4
        out += ["", "Coverage of the final estimate: every tag at the end of its run, localised "
                "or not (the estimate an operator is left with), inside its 95 % radius.", "",
                *head("Radius"), *_coverage_rows(rows, "final_")]
    return out


def _coverage_rows(rows: Rows, prefix: str) -> list[str]:
    """One coverage line per model and method, of the ``prefix``ed errors and radii."""
    out = []
    for model, method, sel in groups(rows):
        c = coverage_stats(sel, prefix)
        if not c["tags"]:
            out.append(f"| {MODEL_LABELS[model]} | {method_label(method)} | 0 | 0 | – | – | – | "
                       "– | – |")
            continue
        e = c["errors"]
        out.append(
            f"| {MODEL_LABELS[model]} | {method_label(method)} | {c['tags']} | {c['inside']} | "
            f"{success_ci(c['inside'], c['tags']).text(2)} | {np.median(e):.1f} | "
            f"{np.percentile(e, 95):.1f} | {e.max():.1f} | {np.median(c['radii']):.1f} |")
    return out


def _paired_table(rows: Rows, ident: dict[str, Any], prefix: str) -> list[str]:
    """Each method against MexGen on the same (start, rep)."""
    if not any(r["method"] == "mexgen" for r in rows):
        return []
    out = ["Paired against MexGen on the same start and repetition (other - MexGen; failed "
           "runs at the limit):", "",
           "| Model | Method | Pairs | Δ min(Time, limit) [95 % CI] (s) | MexGen first | "
           "Other first | Both succeeded | Δ Time, both succeeded [95 % CI] (s) | "
           "Only MexGen succeeded | Only other succeeded |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for model, method, sel in groups(rows):
        if method == "mexgen":
            continue
        limit = limit_of(ident, model)
        mex = {(r["start"], r["rep"]): r for r in rows
               if r["model"] == model and r["method"] == "mexgen"}
        pairs = [(r, mex[(r["start"], r["rep"])]) for r in sel if (r["start"], r["rep"]) in mex]
        if not pairs:
            continue
        ta, da = outcomes([a for a, _ in pairs], prefix, limit)
        tb, db = outcomes([b for _, b in pairs], prefix, limit)
        d = np.minimum(ta, limit) - np.minimum(tb, limit)
        both = da & db
        out.append(
            f"| {MODEL_LABELS[model]} | {method_label(method)} | {len(pairs)} | "
            f"{paired_mean(d).text(1)} | {int((d > 0).sum())} | {int((d < 0).sum())} | "
            f"{int(both.sum())} | {paired_mean(d[both]).text(1)} | {int((db & ~da).sum())} | "
            f"{int((da & ~db).sum())} |")
    return out


def _follow_table(rows: Rows) -> list[str]:
    out = ["| Model | Method | Runs | Error ± σ (m) | Final error, median (m) | "
           "Tr(Cov), median of run means (m²) | Final Tr(Cov), median (m²) |",
           "|---|---|---:|---:|---:|---:|---:|"]
    for model, method, sel in groups(rows):
        err = floats(r["error_mean_m"] for r in sel)
        fin = floats(r["error_final_m"] for r in sel)
        tr = floats(r["trace_mean_m2"] for r in sel)
        trf = floats(r["trace_final_m2"] for r in sel)
        out.append(f"| {MODEL_LABELS[model]} | {method_label(method)} | {len(sel)} | {_pm(err)} | "
                   f"{np.median(fin):.1f} | {np.median(tr):.0f} | {np.median(trf):.0f} |")
    return out


def _throughput_table(rows: Rows) -> list[str]:
    out = ["Throughput (simulated seconds per second of one core; wall includes waiting for a "
           "shared core):", "",
           "| Model | Method | Simulated s | x real time per CPU s | x real time per wall s | "
           "Plan median (ms) |", "|---|---|---:|---:|---:|---:|"]
    for model, method, sel in groups(rows):
        sim = floats(r["sim_s"] for r in sel).sum()
        cpu = floats(r["cpu_s"] for r in sel).sum()
        wall = floats(r["wall_s"] for r in sel).sum()
        plan = floats(r["plan_ms_median"] for r in sel)
        out.append(f"| {MODEL_LABELS[model]} | {method_label(method)} | {sim:.0f} | "
                   f"{sim / cpu:.0f} | {sim / wall:.0f} | "
                   f"{np.median(plan) if plan.size else math.nan:.1f} |")
    return out


# -- reporting and time to radius -------------------------------------------------------

CURVE_TIMES_S = (250.0, 500.0, 750.0, 1000.0)
"""The times at which the time-to-radius curve is tabulated."""
UNDER_RADII = (50, 75, 100)
REASONS = ("reached", "stalled", "budget")


def under_times(rows: Rows, radius: int, limit_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, done) of 'every tag's radius at most ``radius`` m at once', per run: the first
    such pulse, or the limit (not done) if never before the run ended."""
    col = f"all_under_{radius}_s"
    done = np.array([r.get(col, "") != "" for r in rows])
    t = np.array([float(r[col]) if d else limit_s for r, d in zip(rows, done, strict=True)])
    return t, done


def reason_counts(rows: Rows) -> dict[str, int]:
    """How many tags (over the runs) were reported for each reason, and never ('')."""
    counts = dict.fromkeys((*REASONS, ""), 0)
    for r in rows:
        for reason in r.get("reasons", "").split(";"):
            counts[reason if reason in counts else ""] += 1
    return counts


def _finish_section(rows: Rows, ident: dict[str, Any]) -> list[str]:
    """Time to radius (all tags under 50 / 75 / 100 m at once against time) and why tags were
    reported; format 5 runs.csv only."""
    if not any("all_under_50_s" in r for r in rows):  # format 4 and earlier
        return []
    out = ["## Time to radius and reporting", "",
           "Share of runs with every tag's 95 % radius at most R at once, by time (a run that "
           "ended, all tags reported, counts as it ended), with the Kaplan-Meier median time:",
           "", "| Model | Method | R (m) | " + " | ".join(
               f"by {t:g} s" for t in CURVE_TIMES_S) + " | Median time, KM [95 % CI] (s) |",
           "|---|---|---:|" + "---:|" * (len(CURVE_TIMES_S) + 1)]
    for model, method, sel in groups(rows):
        limit = limit_of(ident, model)
        for radius in UNDER_RADII:
            t, done = under_times(sel, radius, limit)
            cells = [success_ci(int(np.sum(done & (t <= c + 1e-9))), len(sel)).text(2)
                     for c in CURVE_TIMES_S]
            out.append(f"| {MODEL_LABELS[model]} | {method_label(method)} | {radius} | "
                       + " | ".join(cells)
                       + f" | {km_median(t, done, limit).text(beyond=f'> {limit:g}')} |")
    out += ["", "Why tags were reported (tags over all runs; 'never': not reported before the "
            "limit), and when the last one was:", "",
            "| Model | Method | Tags | Reached | Stalled | Budget | Never | All reported "
            "[95 % CI] | All reported, median (s) | Final radius median (m) |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for model, method, sel in groups(rows):
        c = reason_counts(sel)
        ends = floats(r.get("all_reported_s", "") for r in sel)
        final = floats(x for r in sel for x in r.get("final_radii_m", "").split(";"))
        out.append(
            f"| {MODEL_LABELS[model]} | {method_label(method)} | {sum(c.values())} | "
            f"{c['reached']} | {c['stalled']} | {c['budget']} | {c['']} | "
            f"{success_ci(int(ends.size), len(sel)).text(2)} | "
            f"{np.median(ends) if ends.size else float('nan'):.0f} | "
            f"{np.median(final) if final.size else float('nan'):.1f} |")
    return out
