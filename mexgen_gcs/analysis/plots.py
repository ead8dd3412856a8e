"""PNG plots of one flight (matplotlib, Agg canvas; no pyplot, no global backend state).

Frame: local ENU metres about home on the map axes (x east, y north, equal scale). Time axes
are seconds since airborne.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse, Polygon
from scipy.stats import chi2

from mexgen_gcs.analysis.calibration import PathLossFit, detection_geometry, tag_positions
from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.series import STAGES
from mexgen_gcs.analysis.summary import FlightSummary
from mexgen_gcs.analysis.truth import Truth

DPI = 110
_TAB10 = [f"C{i}" for i in range(10)]


def new_figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    return path


def tag_colour(i: int) -> str:
    return _TAB10[i % len(_TAB10)]


def covariance_ellipse(mean_en: tuple[float, float], cov: np.ndarray, confidence: float,
                       **style: object) -> Ellipse | None:
    """The confidence ellipse of a 2-D Gaussian (ENU axes); None if the covariance is bad."""
    if not np.all(np.isfinite(cov)):
        return None
    vals, vecs = np.linalg.eigh(np.asarray(cov, dtype=np.float64))
    vals = np.maximum(vals, 0.0)
    k = math.sqrt(chi2.ppf(confidence, 2))
    angle = math.degrees(math.atan2(vecs[1, 1], vecs[0, 1]))  # major axis from east, ccw
    return Ellipse(mean_en, 2 * k * math.sqrt(vals[1]), 2 * k * math.sqrt(vals[0]),
                   angle=angle, **style)  # type: ignore[arg-type]


def draw_area(ax: object, flight: FlightData) -> None:
    v = flight.area.vertices_m
    ax.add_patch(Polygon(v, closed=True, fill=False, edgecolor="0.3", linestyle="--",  # type: ignore[attr-defined]
                         linewidth=1.0, label="search area"))


def plot_path(flight: FlightData, summary: FlightSummary, truth: Truth | None,
              path: Path) -> Path:
    """Flight path over the search area, detections coloured by RSSI, final estimates with
    their confidence ellipses, localisation points, and the truth when known."""
    fig = new_figure(8.0, 7.0)
    ax = fig.add_subplot()
    draw_area(ax, flight)
    tr = flight.track
    ax.plot(tr.east_m, tr.north_m, color="0.55", linewidth=0.8, label="flight path", zorder=1)
    ax.plot([0.0], [0.0], marker="^", color="k", markersize=8, linestyle="none", label="home")
    det = flight.detections
    ok = np.all(np.isfinite(det.rx_enu_m), axis=1) & np.isfinite(det.rssi_db)
    if ok.any():
        sc = ax.scatter(det.rx_enu_m[ok, 0], det.rx_enu_m[ok, 1], c=det.rssi_db[ok], s=6,
                        cmap="viridis", zorder=2, linewidths=0)
        fig.colorbar(sc, ax=ax, label="RSSI (dB) at the receiver", shrink=0.8)
    conf = flight.mission.localisation.confidence
    for i, ts in enumerate(summary.tags):
        colour = tag_colour(i)
        series = flight.estimates[ts.tag_id]
        if ts.final_east_m is not None and ts.final_north_m is not None:
            ax.plot(ts.final_east_m, ts.final_north_m, marker="o", color=colour, markersize=6,
                    linestyle="none", label=f"{ts.tag_id} estimate", zorder=4)
            ell = covariance_ellipse((ts.final_east_m, ts.final_north_m),
                                     series.cov_pos_m2[-1], conf, fill=False,
                                     edgecolor=colour, linewidth=1.5, zorder=4)
            if ell is not None:
                ax.add_patch(ell)
        if ts.localised_east_m is not None and ts.localised_north_m is not None:
            ax.plot(ts.localised_east_m, ts.localised_north_m, marker="x", color=colour,
                    markersize=8, linestyle="none", zorder=4)
        if truth is not None and ts.tag_id in truth.tags:
            tt = truth.tags[ts.tag_id]
            if tt.static:
                ax.plot(tt.east_m[0], tt.north_m[0], marker="*", color=colour, markersize=13,
                        markeredgecolor="k", linestyle="none", zorder=5)
            else:
                ax.plot(tt.east_m, tt.north_m, color=colour, linestyle=":", linewidth=1.2,
                        zorder=3)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east of home (m)")
    ax.set_ylabel("north of home (m)")
    title = f"{flight.mission.name}: flight path and estimates ({int(conf * 100)}% ellipses"
    title += "; x = localised, * = truth)" if truth is not None else "; x = localised)"
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", fontsize=7, framealpha=0.8)
    ax.grid(True, alpha=0.3)
    return save_figure(fig, path)


def plot_tags_over_time(flight: FlightData, summary: FlightSummary, path: Path) -> Path:
    """Uncertainty radius (log scale) and existence probability of each tag over time."""
    fig = new_figure(9.0, 6.5)
    ax_r, ax_q = fig.subplots(2, 1, sharex=True)
    for i, ts in enumerate(summary.tags):
        series = flight.estimates[ts.tag_id]
        if len(series) == 0:
            continue
        x = flight.since_airborne(series.t)
        colour = tag_colour(i)
        ax_r.plot(x, series.radius_m, color=colour, linewidth=1.2, label=ts.tag_id)
        ax_q.plot(x, series.existence, color=colour, linewidth=1.2, label=ts.tag_id)
        if ts.localised_after_s is not None:
            for ax in (ax_r, ax_q):
                ax.axvline(ts.localised_after_s, color=colour, linestyle=":", linewidth=1.0)
    loc = flight.mission.localisation
    ax_r.axhline(loc.radius_m, color="k", linestyle="--", linewidth=0.8,
                 label=f"localised at {loc.radius_m:g} m")
    ax_r.set_yscale("log")
    ax_r.set_ylabel(f"{int(loc.confidence * 100)}% uncertainty radius (m)")
    ax_r.legend(fontsize=7, ncol=2)
    ax_r.grid(True, alpha=0.3, which="both")
    ax_q.axhline(loc.min_existence, color="k", linestyle="--", linewidth=0.8)
    ax_q.set_ylim(-0.02, 1.02)
    ax_q.set_ylabel("existence probability")
    ax_q.set_xlabel("time since airborne (s); dotted: localised")
    ax_q.grid(True, alpha=0.3)
    ax_r.set_title(f"{flight.mission.name}: tag uncertainty and existence", fontsize=10)
    return save_figure(fig, path)


def plot_rssi_distance(flight: FlightData, fit: PathLossFit | None, path: Path) -> Path:
    """RSSI against distance from the receiver to each tag's estimate, with the fitted and
    the mission's path-loss curves."""
    fig = new_figure(8.0, 5.5)
    ax = fig.add_subplot()
    all_d: list[np.ndarray] = []
    for i, tid in enumerate(flight.tag_ids):
        series = flight.estimates[tid]
        if len(series) == 0:
            continue
        pos = tag_positions(flight, tid, "estimate")
        d, _, z = detection_geometry(flight, tid, pos)
        if d.size:
            ax.scatter(d, z, s=5, color=tag_colour(i), alpha=0.5, linewidths=0, label=tid)
            all_d.append(d)
    radio = flight.mission.radio_model()
    if all_d:
        dd = np.concatenate(all_d)
        lo, hi = max(float(dd.min()), radio.min_distance_m), float(dd.max())
        grid = np.geomspace(lo, max(hi, lo * 1.01), 200)
        model = radio.p0_db - 10 * radio.path_loss_exponent * np.log10(grid / radio.d0_m)
        ax.plot(grid, model, color="k", linestyle="--", linewidth=1.2,
                label=f"mission: P0 {radio.p0_db:g} dB, n {radio.path_loss_exponent:g}")
        if fit is not None:
            ax.plot(grid, fit.predict_db(grid), color="C3", linewidth=2.0,
                    label=f"fit: P0 {fit.p0_db:.1f} dB, n {fit.path_loss_exponent:.2f}, "
                          f"sigma {fit.noise_std_db:.1f} dB")
        ax.set_xscale("log")
    ax.axhline(radio.sensitivity_db, color="0.5", linestyle=":", linewidth=1.0,
               label="receiver sensitivity")
    ax.set_xlabel("3-D distance from receiver to the tag's estimate (m)")
    ax.set_ylabel("RSSI (dB)")
    ax.set_title(f"{flight.mission.name}: received power against distance", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3, which="both")
    return save_figure(fig, path)


def plot_planner_timing(flight: FlightData, path: Path) -> Path:
    """Wall time per planner stage (box plots per method), like the paper's run-time figure."""
    fig = new_figure(8.0, 4.5)
    ax = fig.add_subplot()
    methods = list(dict.fromkeys(p.method for p in flight.plans))
    width = 0.8 / max(len(methods), 1)
    handles = []
    for j, method in enumerate(methods):
        plans = [p for p in flight.plans if p.method == method]
        data = []
        for stage in STAGES:
            v = np.array([p.timing_ms.get(stage, math.nan) for p in plans], dtype=np.float64)
            v = v[np.isfinite(v) & (v > 0)]
            data.append(v if v.size else np.array([math.nan]))
        pos = np.arange(len(STAGES)) + (j - (len(methods) - 1) / 2) * width
        bp = ax.boxplot(data, positions=pos, widths=width * 0.9, patch_artist=True,
                        showfliers=False)
        for box in bp["boxes"]:
            box.set_facecolor(tag_colour(j))
            box.set_alpha(0.6)
        handles.append((bp["boxes"][0], f"{method} ({len(plans)} plans)"))
    ax.set_xticks(np.arange(len(STAGES)), STAGES)
    ax.set_yscale("log")
    ax.set_ylabel("wall time per plan (ms)")
    ax.set_title(f"{flight.mission.name}: planner time per stage", fontsize=10)
    if handles:
        ax.legend([h for h, _ in handles], [lab for _, lab in handles], fontsize=8)
    else:
        ax.text(0.5, 0.5, "no plans in this log", transform=ax.transAxes, ha="center")
    ax.grid(True, alpha=0.3, which="both", axis="y")
    return save_figure(fig, path)
