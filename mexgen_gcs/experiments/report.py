"""An experiment's report from its directory: summary.md and PNG plots.

Frame: plots of trajectories are in the scenario's local ENU metres (east right, north up).

- summary.md: the paper's Table II layout for localisation (Model, Method, Success, Error +-
  sigma, Time +- sigma; Error over the tags of the successful runs, Time over the successful
  runs, sigma the population standard deviation), paired comparisons against MexGen on the
  same (start, repetition) seeds, and the throughput (simulated seconds per CPU second of a
  run, i.e. per core). For following: the error and Tr(Cov) per method.
- following: ``follow-<model>.png``, median Error and Tr(Cov) over time per method;
- localisation: ``localise-time.png`` (box plot of Time), ``localise-success.png`` (bars);
- ``trajectories-<model>.png``: the truth tracks of the first start and each method's vehicle
  path on its first repetition (square: start, triangle: end), as the paper's examples.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from mexgen_gcs.experiments.scenario import METHODS, MODELS, scenario, scenario_from_settings
from mexgen_gcs.experiments.store import read_identity, read_rows, read_series
from mexgen_gcs.experiments.world import truth_for

MODEL_LABELS = {"rw": "RW", "cv": "CV", "cv-ift": "CV-IFT", "cv-ift-mismatch": "CV-IFT Mismatch"}
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


def write_report(out_dir: str | Path) -> list[Path]:
    """Write summary.md and the plots for the runs in DIR; returns the files written."""
    out = Path(out_dir)
    rows = read_rows(out)
    ident = read_identity(out) or {}
    kind = str(ident.get("scenario", rows[0]["scenario"] if rows else "localise"))
    written = [out / "summary.md"]
    written[0].write_text(summary_markdown(rows, ident), encoding="utf-8")
    if not rows:
        return written
    if kind == "localise":
        written += _localise_plots(out, rows)
    else:
        written += _follow_plots(out, rows)
    written += _trajectory_plots(out, rows, ident)
    return written


# -- tables ----------------------------------------------------------------------------------

def _groups(rows: Rows) -> list[tuple[str, str, Rows]]:
    out = []
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        for method in [m for m in METHODS if any(r["method"] == m for r in rows)]:
            sel = [r for r in rows if r["model"] == model and r["method"] == method]
            if sel:
                out.append((model, method, sel))
    return out


def _floats(values: Iterable[str]) -> np.ndarray:
    return np.array([float(v) for v in values if v != ""], dtype=np.float64)


def _pm(x: np.ndarray, digits: int = 1) -> str:
    if x.size == 0:
        return "–"
    return f"{x.mean():.{digits}f} ± {x.std():.{digits}f}"


def localise_stats(rows: Rows) -> dict[str, float | int | np.ndarray]:
    """Success rate, errors (m, per tag of the successful runs) and times (s) of runs."""
    ok = [r for r in rows if r["success"] == "1"]
    errors = _floats(e for r in ok for e in r["errors_m"].split(";"))
    return {"runs": len(rows), "success": len(ok) / len(rows) if rows else math.nan,
            "errors": errors, "times": _floats(r["time_s"] for r in ok)}


def summary_markdown(rows: Rows, ident: dict[str, object]) -> str:
    kind = str(ident.get("scenario", rows[0]["scenario"] if rows else "?"))
    lines = [f"# Experiment: {kind} ({ident.get('preset', '?')} preset, seed "
             f"{ident.get('seed', '?')})", ""]
    if not rows:
        return "\n".join([*lines, "No runs yet.", ""])
    lines += [f"{len(rows)} runs in runs.csv.", ""]
    if kind == "localise":
        lines += [*_localise_table(rows), "", *_paired_table(rows)]
    else:
        lines += _follow_table(rows)
    lines += ["", *_throughput_table(rows), ""]
    return "\n".join(lines)


def _localise_table(rows: Rows) -> list[str]:
    out = ["| Model | Method | Runs | Success | Error ± σ (m) | Time ± σ (s) | "
           "Paper: Success | Paper: Error (m) | Paper: Time (s) |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for model, method, sel in _groups(rows):
        st = localise_stats(sel)
        paper = PAPER_TABLE_II.get((model, method))
        p = (f"{paper[0]:.2f} | {paper[1]} | {paper[2]}" if paper else "– | – | –")
        out.append(f"| {MODEL_LABELS[model]} | {METHODS[method][1]} | {st['runs']} | "
                   f"{st['success']:.2f} | {_pm(st['errors'])} | {_pm(st['times'])} | {p} |")
    return out


def _paired_table(rows: Rows) -> list[str]:
    """Each method against MexGen on the same (start, rep): who finished first."""
    if not any(r["method"] == "mexgen" for r in rows):
        return []
    out = ["Paired against MexGen on the same seeds (pairs where both succeeded: mean Time "
           "difference, other - MexGen, ± standard error; MexGen faster in how many):", "",
           "| Model | Method | Pairs | Both succeeded | Time difference (s) | MexGen faster | "
           "Only MexGen succeeded | Only other succeeded |",
           "|---|---|---:|---:|---:|---:|---:|---:|"]
    for model, method, sel in _groups(rows):
        if method == "mexgen":
            continue
        mex = {(r["start"], r["rep"]): r for r in rows
               if r["model"] == model and r["method"] == "mexgen"}
        pairs = [(r, mex[(r["start"], r["rep"])]) for r in sel if (r["start"], r["rep"]) in mex]
        both = [(a, b) for a, b in pairs if a["success"] == "1" and b["success"] == "1"]
        d = np.array([float(a["time_s"]) - float(b["time_s"]) for a, b in both])
        diff = (f"{d.mean():+.1f} ± {d.std(ddof=1) / math.sqrt(d.size):.1f}" if d.size > 1
                else "–")
        faster = int((d > 0).sum())
        only_mex = sum(a["success"] != "1" and b["success"] == "1" for a, b in pairs)
        only_other = sum(a["success"] == "1" and b["success"] != "1" for a, b in pairs)
        out.append(f"| {MODEL_LABELS[model]} | {METHODS[method][1]} | {len(pairs)} | {len(both)}"
                   f" | {diff} | {faster}/{len(both)} | {only_mex} | {only_other} |")
    return out


def _follow_table(rows: Rows) -> list[str]:
    out = ["| Model | Method | Runs | Error ± σ (m) | Final error, median (m) | "
           "Tr(Cov), median of run means (m²) | Final Tr(Cov), median (m²) |",
           "|---|---|---:|---:|---:|---:|---:|"]
    for model, method, sel in _groups(rows):
        err = _floats(r["error_mean_m"] for r in sel)
        fin = _floats(r["error_final_m"] for r in sel)
        tr = _floats(r["trace_mean_m2"] for r in sel)
        trf = _floats(r["trace_final_m2"] for r in sel)
        out.append(f"| {MODEL_LABELS[model]} | {METHODS[method][1]} | {len(sel)} | {_pm(err)} | "
                   f"{np.median(fin):.1f} | {np.median(tr):.0f} | {np.median(trf):.0f} |")
    return out


def _throughput_table(rows: Rows) -> list[str]:
    out = ["Throughput (simulated seconds per second of one core; wall includes waiting for a "
           "shared core):", "",
           "| Model | Method | Simulated s | x real time per CPU s | x real time per wall s | "
           "Plan median (ms) |", "|---|---|---:|---:|---:|---:|"]
    for model, method, sel in _groups(rows):
        sim = _floats(r["sim_s"] for r in sel).sum()
        cpu = _floats(r["cpu_s"] for r in sel).sum()
        wall = _floats(r["wall_s"] for r in sel).sum()
        plan = _floats(r["plan_ms_median"] for r in sel)
        out.append(f"| {MODEL_LABELS[model]} | {METHODS[method][1]} | {sim:.0f} | "
                   f"{sim / cpu:.0f} | {sim / wall:.0f} | "
                   f"{np.median(plan) if plan.size else math.nan:.1f} |")
    return out


# -- plots -----------------------------------------------------------------------------------

def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path


def _localise_plots(out: Path, rows: Rows) -> list[Path]:
    groups = _groups(rows)
    models = list(dict.fromkeys(g[0] for g in groups))
    methods = list(dict.fromkeys(g[1] for g in groups))
    width = 0.8 / max(len(methods), 1)
    fig_t = Figure(figsize=(1.8 + 2.2 * len(models), 4.0))
    ax_t = fig_t.add_subplot()
    fig_s = Figure(figsize=(1.8 + 2.2 * len(models), 3.6))
    ax_s = fig_s.add_subplot()
    for j, method in enumerate(methods):
        xs, data, rates = [], [], []
        for i, model in enumerate(models):
            sel = [r for r in rows if r["model"] == model and r["method"] == method]
            if not sel:
                continue
            st = localise_stats(sel)
            xs.append(i + (j - (len(methods) - 1) / 2) * width)
            data.append(st["times"])
            rates.append(st["success"])
        color = f"C{j}"
        non_empty = [(x, d) for x, d in zip(xs, data, strict=True) if len(d)]
        if non_empty:
            bp = ax_t.boxplot([d for _, d in non_empty], positions=[x for x, _ in non_empty],
                              widths=0.9 * width, patch_artist=True, manage_ticks=False)
            for box in bp["boxes"]:
                box.set_facecolor(color)
                box.set_alpha(0.6)
        ax_t.plot([], [], color=color, lw=6, alpha=0.6, label=METHODS[method][1])
        ax_s.bar(xs, rates, width=0.9 * width, color=color, label=METHODS[method][1])
    for ax in (ax_t, ax_s):
        ax.set_xticks(range(len(models)), [MODEL_LABELS[m] for m in models])
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    ax_t.set_ylabel("time to localise all objects (s)")
    ax_t.set_title("Multi-object localisation: completion time (successful runs)")
    ax_s.set_ylabel("success rate")
    ax_s.set_ylim(0.0, 1.05)
    ax_s.set_title("Multi-object localisation: all objects localised within the limit")
    return [_save(fig_t, out / "localise-time.png"), _save(fig_s, out / "localise-success.png")]


def _follow_plots(out: Path, rows: Rows) -> list[Path]:
    written = []
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        fig = Figure(figsize=(10.0, 3.8), layout="constrained")
        ax_e, ax_c = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
        for j, method in enumerate(m for m in METHODS if any(
                r["model"] == model and r["method"] == m for r in rows)):
            series = [read_series(out, r) for r in rows
                      if r["model"] == model and r["method"] == method]
            series = [s for s in series if s is not None]
            if not series:
                continue
            n = min(len(s["t_s"]) for s in series)
            t = series[0]["t_s"][:n]
            err = np.median(np.stack([s["error_m"][:n, 0] for s in series]), axis=0)
            cov = np.median(np.stack([s["trace_m2"][:n, 0] for s in series]), axis=0)
            label = f"{METHODS[method][1]} ({len(series)} runs)"
            ax_e.plot(t, err, color=f"C{j}", label=label)
            ax_c.plot(t, cov, color=f"C{j}", label=label)
        ax_e.set_ylabel("median error (m)")
        ax_c.set_ylabel("median Tr(Cov) (m²)")
        ax_c.set_yscale("log")
        for ax in (ax_e, ax_c):
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        fig.suptitle(f"Object following, {MODEL_LABELS[model]}")
        written.append(_save(fig, out / f"follow-{model}.png"))
    return written


def _trajectory_plots(out: Path, rows: Rows, ident: dict[str, object]) -> list[Path]:
    written = []
    kind = str(ident.get("scenario", "localise"))
    quick = ident.get("preset") == "quick"
    seed = int(str(ident.get("seed", rows[0]["seed"])))
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        sel = [r for r in rows if r["model"] == model]
        start = min(int(r["start"]) for r in sel)
        first = {}
        for r in sorted(sel, key=lambda r: int(r["rep"])):
            if int(r["start"]) == start:
                first.setdefault(r["method"], r)
        methods = [m for m in METHODS if m in first]
        stored = ident.get("settings", {})
        sc = (scenario_from_settings(stored[model]) if isinstance(stored, dict) and model in stored
              else scenario(kind, model, quick))  # type: ignore[arg-type]
        truth = truth_for(sc, seed, start)
        fig = Figure(figsize=(4.2 * len(methods), 4.6), layout="constrained")
        for j, method in enumerate(methods):
            ax = fig.add_subplot(1, len(methods), j + 1)
            r = first[method]
            s = read_series(out, r)
            end = len(s["t_s"]) if s is not None else truth.states.shape[0] - 1
            for i in range(truth.states.shape[1]):
                xy = truth.states[: end + 1, i, :2]
                ax.plot(xy[:, 0], xy[:, 1], color="0.3", lw=1.0)
                ax.plot(*xy[0], "s", color="0.3", ms=5)
                ax.plot(*xy[-1], "^", color="0.3", ms=6)
            if s is not None:
                v = s["vehicle_en_m"]
                ax.plot(np.r_[0.0, v[:, 0]], np.r_[0.0, v[:, 1]], color=f"C{j}", lw=1.0)
                ax.plot(0.0, 0.0, "s", color=f"C{j}", ms=5)
                ax.plot(*v[-1], "^", color=f"C{j}", ms=6)
            h = sc.initial_half_m
            ax.plot([-h, h, h, -h, -h], [-h, -h, h, h, -h], color="0.7", lw=0.8, ls="--")
            ax.set_aspect("equal", adjustable="datalim")
            outcome = (f"success at {float(r['time_s']):.0f} s" if r.get("success") == "1"
                       else "not all localised" if kind == "localise" else
                       f"mean error {float(r['error_mean_m']):.0f} m")
            ax.set_title(f"{METHODS[method][1]}: start {start}, rep {r['rep']}\n{outcome}",
                         fontsize=9)
            ax.set_xlabel("east (m)")
            if j == 0:
                ax.set_ylabel("north (m)")
        fig.suptitle(f"{kind} {MODEL_LABELS[model]}: objects (grey) and vehicle paths")
        written.append(_save(fig, out / f"trajectories-{model}.png"))
    return written
