"""Comparison of several flights: path heat maps per planner method (like the paper's
Figure 1) and the summary tables side by side.

Frame: local ENU metres about home (x east, y north). Heat maps count time spent per cell: each
track is resampled at ``HEAT_STEP_S`` so that a hovering vehicle weighs as much as it stayed.
Flights of different missions are compared in their own home frames; the map extent is the
union of their search areas.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm

from mexgen_gcs.analysis.document import Document, fmt
from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.plots import draw_area, new_figure, save_figure
from mexgen_gcs.analysis.report import json_safe
from mexgen_gcs.analysis.summary import FlightSummary
from mexgen_gcs.analysis.truth import Truth

HEAT_STEP_S = 1.0
CELL_M = 25.0
COMPARE_MD = "compare.md"
COMPARE_HTML = "compare.html"
COMPARE_JSON = "compare.json"
HEATMAP_PNG = "heatmaps.png"


@dataclass(frozen=True, slots=True)
class Comparison:
    out_dir: Path
    markdown: Path
    html: Path
    json: Path
    heatmaps: Path
    methods: tuple[str, ...]


def label_of(flight: FlightData) -> str:
    return flight.log_dir.name or str(flight.path)


def unique_labels(flights: Sequence[FlightData]) -> list[str]:
    """One column label (and export folder name) per flight: its log directory's name, with
    -2, -3, ... appended where names repeat."""
    seen: dict[str, int] = {}
    out = []
    for f in flights:
        base = label_of(f)
        seen[base] = seen.get(base, 0) + 1
        out.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return out


def heat_counts(flights: Sequence[FlightData], extent: tuple[float, float, float, float],
                cell_m: float = CELL_M) -> np.ndarray:
    """(ny, nx) seconds spent per cell summed over the flights (airborne part only)."""
    w, e, s, n = extent
    xe = np.arange(w, e + cell_m, cell_m)
    ye = np.arange(s, n + cell_m, cell_m)
    total = np.zeros((ye.size - 1, xe.size - 1))
    for f in flights:
        tr = f.track.resampled(HEAT_STEP_S)
        if len(tr) == 0:
            continue
        keep = tr.up_m > 0.5 * f.mission.flight.alt_m  # only at mission altitude
        h, _, _ = np.histogram2d(tr.north_m[keep], tr.east_m[keep], bins=(ye, xe))
        total += h * HEAT_STEP_S
    return total


def plot_heatmaps(flights: Sequence[FlightData], path: Path,
                  truths: Sequence[Truth | None]) -> tuple[Path, tuple[str, ...]]:
    """One heat map per planner method over all flights that used it."""
    methods = tuple(dict.fromkeys(f.method for f in flights))
    bounds = np.array([f.area.bounds for f in flights])  # (west, east, south, north)
    pad = 50.0
    extent = (float(bounds[:, 0].min()) - pad, float(bounds[:, 1].max()) + pad,
              float(bounds[:, 2].min()) - pad, float(bounds[:, 3].max()) + pad)
    counts = {m: heat_counts([f for f in flights if f.method == m], extent) for m in methods}
    vmax = max((float(c.max()) for c in counts.values()), default=1.0) or 1.0
    fig = new_figure(4.6 * len(methods) + 1.0, 4.8)
    axes = fig.subplots(1, len(methods), squeeze=False)[0]
    image = None
    for ax, m in zip(axes, methods, strict=True):
        c = np.where(counts[m] > 0, counts[m], np.nan)
        image = ax.imshow(c, origin="lower", extent=extent, cmap="inferno_r",
                          norm=LogNorm(vmin=HEAT_STEP_S, vmax=max(vmax, HEAT_STEP_S * 1.01)),
                          interpolation="nearest")
        members = [i for i, f in enumerate(flights) if f.method == m]
        draw_area(ax, flights[members[0]])
        for i in members:
            truth = truths[i]
            if truth is None:
                continue
            for tt in truth.tags.values():
                if tt.static:
                    ax.plot(tt.east_m[0], tt.north_m[0], marker="*", color="C0",
                            markeredgecolor="k", markersize=10, linestyle="none")
                else:
                    ax.plot(tt.east_m, tt.north_m, color="C0", linewidth=0.8, alpha=0.6)
        ax.set_title(f"{m} ({len(members)} flight{'s' if len(members) != 1 else ''})",
                     fontsize=10)
        ax.set_xlim(extent[0], extent[1])  # truth tracks may leave the area: keep the map
        ax.set_ylim(extent[2], extent[3])
        ax.set_xlabel("east (m)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("north (m)")
    if image is not None:
        fig.colorbar(image, ax=list(axes), label=f"seconds per {CELL_M:g} m cell", shrink=0.8)
    return save_figure(fig, path), methods


def _mean(xs: Sequence[float | None]) -> float | None:
    v = [x for x in xs if x is not None and math.isfinite(x)]
    return float(np.mean(v)) if v else None


def comparison_document(flights: Sequence[FlightData],
                        summaries: Sequence[FlightSummary]) -> Document:
    doc = Document(f"Flight comparison ({len(flights)} logs)")
    labels = unique_labels(flights)
    sec = doc.section("Side by side")
    tag_ids = list(dict.fromkeys(t.tag_id for s in summaries for t in s.tags))
    has_truth = any(s.has_truth for s in summaries)
    rows: list[list[str]] = []

    def row(name: str, values: Sequence[str]) -> None:
        rows.append([name, *values])

    row("mission", [s.totals.name for s in summaries])
    row("method", [", ".join(s.totals.methods_used) for s in summaries])
    row("seed", [fmt(s.totals.seed) for s in summaries])
    row("end reason", [s.totals.end_reason for s in summaries])
    row("duration (s)", [fmt(s.totals.duration_s) for s in summaries])
    row("distance flown (km)", [fmt(s.totals.distance_flown_m / 1000, 2) for s in summaries])
    row("tags localised", [f"{s.totals.tags_localised}/{s.totals.tags_total}"
                           for s in summaries])
    row("detections", [str(s.totals.detections) for s in summaries])
    row("failsafe events", [str(len(s.safety_events)) for s in summaries])
    for tid in tag_ids:
        vals = []
        for s in summaries:
            try:
                t = s.tag(tid)
            except KeyError:
                vals.append("–")
                continue
            text = fmt(t.localised_after_s)
            if has_truth and t.error_at_localisation_m is not None:
                text += f" ({t.error_at_localisation_m:.1f} m)"
            vals.append(text)
        row(f"{tid} localised after (s)" + (" (error)" if has_truth else ""), vals)
    row("mean localisation time (s)",
        [fmt(_mean([t.localised_after_s for t in s.tags])) for s in summaries])
    if has_truth:
        row("mean error at localisation (m)",
            [fmt(_mean([t.error_at_localisation_m for t in s.tags])) for s in summaries])
    row("planner total median (ms)",
        [fmt(next((x.median_ms for x in s.timing if x.stage == "total"), None), 1)
         for s in summaries])
    row("planner total p95 (ms)",
        [fmt(next((x.p95_ms for x in s.timing if x.stage == "total"), None), 1)
         for s in summaries])
    sec.table(["", *labels], rows)

    sec = doc.section("Per method")
    methods = list(dict.fromkeys(f.method for f in flights))
    mrows = []
    for m in methods:
        ss = [s for f, s in zip(flights, summaries, strict=True) if f.method == m]
        loc = [t.localised_after_s for s in ss for t in s.tags]
        done = sum(s.totals.tags_localised for s in ss)
        total = sum(s.totals.tags_total for s in ss)
        err = [t.error_at_localisation_m for s in ss for t in s.tags]
        mrows.append([m, str(len(ss)), f"{done}/{total}", fmt(_mean(loc)),
                      fmt(_mean(err)) if has_truth else "–",
                      fmt(_mean([s.totals.distance_flown_m / 1000 for s in ss]), 2)])
    sec.table(("method", "flights", "tags localised", "mean localisation time (s)",
               "mean error (m)", "mean distance (km)"), mrows)
    sec = doc.section("Path heat maps")
    sec.image(HEATMAP_PNG, "Time spent per cell at mission altitude, per planner method "
                           "(stars/lines: true tag positions where known)")
    return doc


def write_comparison(flights: Sequence[FlightData], summaries: Sequence[FlightSummary],
                     truths: Sequence[Truth | None], out_dir: Path) -> Comparison:
    out_dir.mkdir(parents=True, exist_ok=True)
    heat, methods = plot_heatmaps(flights, out_dir / HEATMAP_PNG, truths)
    doc = comparison_document(flights, summaries)
    md = out_dir / COMPARE_MD
    md.write_text(doc.markdown(), encoding="utf-8")
    page = out_dir / COMPARE_HTML
    page.write_text(doc.html(), encoding="utf-8")
    js = out_dir / COMPARE_JSON
    js.write_text(json.dumps(json_safe({
        "logs": [str(f.path) for f in flights],
        "summaries": [s.to_dict() for s in summaries]}), indent=1), encoding="utf-8")
    return Comparison(out_dir, md, page, js, heat, methods)
