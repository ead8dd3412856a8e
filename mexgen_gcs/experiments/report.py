"""An experiment's report from its directory: summary.md (:mod:`experiments.summary`) and PNG
plots.

Frame: plots of trajectories are in the scenario's local ENU metres (east right, north up).

- following: ``follow-<model>.png``, median Error and Tr(Cov) over time per method (the
  paper's Figure 4);
- localisation: ``localise-success.png`` (Success with its 95 % Wilson interval, per reading),
  ``localise-survival.png`` (Kaplan-Meier fraction of runs not yet complete over time, per
  model and method, both readings: failed runs stay in), ``localise-time.png`` (box plot of
  Time of the successful runs, as the paper's table);
- ``trajectories-<model>.png``: the truth tracks of the first start and each method's vehicle
  path on its first repetition (square: start, triangle: end), as the paper's examples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from mexgen_gcs.experiments.scenario import (
    MODELS,
    method_label,
    ordered_methods,
    scenario,
    scenario_from_settings,
)
from mexgen_gcs.experiments.stats import success_ci, survival_curve
from mexgen_gcs.experiments.store import read_identity, read_rows, read_series
from mexgen_gcs.experiments.summary import (
    MODEL_LABELS,
    PAPER_TABLE_II,
    READINGS,
    Rows,
    groups,
    has_reading,
    limit_of,
    localise_stats,
    outcomes,
    summary_markdown,
)
from mexgen_gcs.experiments.world import truth_for

__all__ = ["MODEL_LABELS", "PAPER_TABLE_II", "localise_stats", "summary_markdown",
           "write_report"]


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
        written += _localise_plots(out, rows, ident)
    else:
        written += _follow_plots(out, rows)
    written += _trajectory_plots(out, rows, ident)
    return written


# -- plots -----------------------------------------------------------------------------------

def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path


def _localise_plots(out: Path, rows: Rows, ident: dict[str, object]) -> list[Path]:
    groups_ = groups(rows)
    models = list(dict.fromkeys(g[0] for g in groups_))
    methods = list(dict.fromkeys(g[1] for g in groups_))
    readings = [(p, w) for p, w in READINGS if has_reading(rows, p)]
    width = 0.8 / max(len(methods), 1)
    fig_t = Figure(figsize=(1.8 + 2.2 * len(models), 4.0))
    ax_t = fig_t.add_subplot()
    fig_s = Figure(figsize=(1.8 + 2.2 * len(models), 3.2 * len(readings)), layout="constrained")
    axes_s = [fig_s.add_subplot(len(readings), 1, i + 1) for i in range(len(readings))]
    for j, method in enumerate(methods):
        color = f"C{j}"
        xs, data = [], []
        for i, model in enumerate(models):
            sel = [r for r in rows if r["model"] == model and r["method"] == method]
            if not sel:
                continue
            x = i + (j - (len(methods) - 1) / 2) * width
            st = localise_stats(sel)
            if st["times"].size:
                xs.append(x)
                data.append(st["times"])
            for ax, (prefix, _) in zip(axes_s, readings, strict=True):
                k = localise_stats(sel, prefix)
                ci = success_ci(k["successes"], k["runs"])
                assert ci.value is not None and ci.low is not None and ci.high is not None
                ax.bar([x], [ci.value], width=0.9 * width, color=color,
                       label=method_label(method) if i == 0 else None)
                ax.errorbar([x], [ci.value], yerr=[[ci.value - ci.low], [ci.high - ci.value]],
                            color="0.2", capsize=3, lw=1)
        if data:
            bp = ax_t.boxplot(data, positions=xs, widths=0.9 * width, patch_artist=True,
                              manage_ticks=False)
            for box in bp["boxes"]:
                box.set_facecolor(color)
                box.set_alpha(0.6)
        ax_t.plot([], [], color=color, lw=6, alpha=0.6, label=method_label(method))
    for ax in (ax_t, *axes_s):
        ax.set_xticks(range(len(models)), [MODEL_LABELS[m] for m in models])
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    ax_t.set_ylabel("time to localise all objects (s)")
    ax_t.set_title("Multi-object localisation: completion time (successful runs)")
    for ax, (prefix, _) in zip(axes_s, readings, strict=True):
        radius = {float(r[c]) for r in rows
                  if r.get(c := "tight_radius_m" if prefix else "radius_m", "")}
        ax.set_ylabel("success rate")
        ax.set_ylim(0.0, 1.05)
        ax.set_title(f"All objects localised within the limit, radius "
                     f"{', '.join(f'{v:g}' for v in sorted(radius)) or '50'} m (95 % Wilson "
                     "intervals)", fontsize=9)
    return [_save(fig_t, out / "localise-time.png"), _save(fig_s, out / "localise-success.png"),
            _survival_plot(out, rows, ident, models, methods, readings)]


def _survival_plot(out: Path, rows: Rows, ident: dict[str, object], models: list[str],
                   methods: list[str], readings: list[tuple[str, str]]) -> Path:
    fig = Figure(figsize=(3.6 * len(models), 3.4), layout="constrained")
    for i, model in enumerate(models):
        ax = fig.add_subplot(1, len(models), i + 1)
        limit = limit_of(ident, model)  # type: ignore[arg-type]
        for j, method in enumerate(methods):
            sel = [r for r in rows if r["model"] == model and r["method"] == method]
            if not sel:
                continue
            for prefix, style in zip((p for p, _ in readings), ("-", "--"), strict=False):
                t, done = outcomes(sel, prefix, limit)
                x, y = survival_curve(t, done, limit)
                ax.step(x, y, where="post", color=f"C{j}", ls=style,
                        label=f"{method_label(method)}{' (tight)' if prefix else ''}")
        ax.set_title(MODEL_LABELS[model], fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0.0, 1.02)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.set_ylabel("runs not yet complete (Kaplan-Meier)")
            ax.legend(fontsize=7)
    fig.suptitle("Localisation: fraction of runs not yet done (solid: criterion, dashed: "
                 "tight reading)", fontsize=10)
    return _save(fig, out / "localise-survival.png")


def _follow_plots(out: Path, rows: Rows) -> list[Path]:
    written = []
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        fig = Figure(figsize=(10.0, 3.8), layout="constrained")
        ax_e, ax_c = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
        for j, method in enumerate(ordered_methods(
                r["method"] for r in rows if r["model"] == model)):
            series = [s for s in (read_series(out, r) for r in rows
                                  if r["model"] == model and r["method"] == method)
                      if s is not None]
            if not series:
                continue
            n = min(len(s["t_s"]) for s in series)
            t = series[0]["t_s"][:n]
            err = np.median(np.stack([s["error_m"][:n, 0] for s in series]), axis=0)
            cov = np.median(np.stack([s["trace_m2"][:n, 0] for s in series]), axis=0)
            label = f"{method_label(method)} ({len(series)} runs)"
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
    label = str(ident.get("preset", "paper"))
    preset, quick = label.removesuffix("-quick"), label.endswith("-quick")
    seed = int(str(ident.get("seed", rows[0]["seed"])))
    for model in [m for m in MODELS if any(r["model"] == m for r in rows)]:
        sel = [r for r in rows if r["model"] == model]
        start = min(int(r["start"]) for r in sel)
        first: dict[str, dict[str, str]] = {}
        for r in sorted(sel, key=lambda r: int(r["rep"])):
            if int(r["start"]) == start:
                first.setdefault(r["method"], r)
        methods = ordered_methods(first)
        stored = ident.get("settings", {})
        sc = (scenario_from_settings(stored[model]) if isinstance(stored, dict) and model in stored
              else scenario(kind, model, quick,  # type: ignore[arg-type]
                            preset if preset in ("paper", "field") else "paper"))  # type: ignore[arg-type]
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
            ax.set_title(f"{method_label(method)}: start {start}, rep {r['rep']}\n{outcome}",
                         fontsize=9)
            ax.set_xlabel("east (m)")
            if j == 0:
                ax.set_ylabel("north (m)")
        fig.suptitle(f"{kind} {MODEL_LABELS[model]}: objects (grey) and vehicle paths")
        written.append(_save(fig, out / f"trajectories-{model}.png"))
    return written
