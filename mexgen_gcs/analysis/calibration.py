"""Path-loss calibration: fit P0, n and the noise std from a flight's detections against
known or estimated tag positions, and print them as the mission file's ``radio:`` block.

Frame: local ENU metres about home (tags on the ground, z = 0); yaw is a compass heading.

Model (core.radio, paper eq. range-measurement)::

    z = P0 - 10 n log10(max(d, d_min) / d0) + g_dir + noise,   noise ~ N(0, sigma^2)

with 3-D distance d and the antenna gain ``g_dir`` of :class:`core.radio.RadioModel` (its
``front_back_db``; pass 0 to ignore it). P0 and n enter linearly, so the fit is a robust linear
least-squares problem: ``scipy.optimize.least_squares`` with a soft-L1 loss (clutter, i.e.
spurious detections uniform in dB, must not drag the fit), then the points within
``OUTLIER_SIGMAS`` robust standard deviations are refitted by ordinary least squares, whose
residual standard deviation is the noise estimate.

Caveat for real receivers: the simulator decides detection from the noiseless power, so its
detections are an unbiased sample; a real receiver detects on the noisy power, which censors
weak pulses and biases the fit at long range. Restrict the fit (``max_distance_m``) when the
far detections sit near the sensitivity.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.optimize import least_squares

from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.truth import Truth
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.errors import EstimationError

FloatArray = NDArray[np.float64]

OUTLIER_SIGMAS = 4.0
"""Residuals beyond this many robust (MAD) standard deviations are treated as clutter."""
MIN_DETECTIONS = 10
_MAD_TO_SIGMA = 1.4826

PositionFn = Callable[[FloatArray], FloatArray]
"""times (K,) -> tag positions (K, 2) ENU."""


TAG_PRIOR_FLOOR_DB = 0.5
"""Least uncertainty given to a surveyed tag's P0 (antenna orientation, battery, weather)."""


@dataclass(frozen=True, slots=True)
class PathLossFit:
    """A fitted path-loss model and how well it is determined."""

    p0_db: float
    path_loss_exponent: float
    noise_std_db: float
    p0_se_db: float
    """Standard error of P0 (dB)."""
    n_se: float
    """Standard error of n."""
    d0_m: float
    used: int
    """Detections in the final fit."""
    outliers: int
    """Detections rejected as clutter."""
    distance_min_m: float
    distance_max_m: float
    tags: tuple[str, ...] = ()
    source: str = ""
    """Where the tag positions came from: truth | estimate | given."""

    def predict_db(self, distance_m: FloatArray) -> FloatArray:
        """Gain-free fitted power at these 3-D distances."""
        d = np.maximum(np.asarray(distance_m, dtype=np.float64), 1e-9)
        return self.p0_db - 10.0 * self.path_loss_exponent * np.log10(d / self.d0_m)

    def radio_block(self, base: Mapping[str, Any] | None = None) -> str:
        """The mission file's ``radio:`` section with the fitted values (other fields from
        ``base``, the mission's resolved radio section), with a comment saying how it was
        fitted."""
        radio = dict(base or {})
        radio.update(p0_db=round(self.p0_db, 2), path_loss_exponent=round(
            self.path_loss_exponent, 3), noise_std_db=round(self.noise_std_db, 2),
            d0_m=self.d0_m)
        head = (f"# fitted from {self.used} detections of {', '.join(self.tags) or '-'} "
                f"({self.source} positions, {self.distance_min_m:.0f}-"
                f"{self.distance_max_m:.0f} m, {self.outliers} rejected as clutter);\n"
                f"# standard errors: p0_db {self.p0_se_db:.2f} dB, path_loss_exponent "
                f"{self.n_se:.3f}\n")
        return head + yaml.safe_dump({"radio": radio}, sort_keys=False)

    def tag_block(self, tag_id: str, freq_hz: int, floor_db: float = TAG_PRIOR_FLOOR_DB) -> str:
        """A mission ``tags:`` entry that carries this fit's P0 as the tag's own prior: a tag
        measured before take-off needs no wide p0_std_db. Its std is the fit's standard error
        combined with ``floor_db`` (what changes between the survey and the mission)."""
        std = math.hypot(self.p0_se_db, floor_db)
        entry = {"id": tag_id, "freq_hz": int(freq_hz), "p0_db": round(self.p0_db, 2),
                 "p0_std_db": round(std, 2)}
        return (f"# {tag_id} measured: its own received power as a tight prior (p0_std_db = "
                f"standard error {self.p0_se_db:.2f} dB with a {floor_db:g} dB floor)\n"
                + yaml.safe_dump({"tags": [entry]}, sort_keys=False, default_flow_style=None))


def fit_path_loss(
    distance_m: FloatArray,
    rssi_db: FloatArray,
    gain_db: FloatArray | float = 0.0,
    *,
    d0_m: float = 1.0,
    min_distance_m: float = 1.0,
    noise_guess_db: float = 2.5,
) -> PathLossFit:
    """Fit P0, n and sigma to (K,) distances and received powers; ``gain_db`` (K,) or scalar
    is the antenna gain to take out. Raises EstimationError with too few usable points or a
    degenerate geometry (all at one distance)."""
    d = np.asarray(distance_m, dtype=np.float64)
    z = np.asarray(rssi_db, dtype=np.float64)
    g = np.broadcast_to(np.asarray(gain_db, dtype=np.float64), d.shape)
    ok = np.isfinite(d) & np.isfinite(z) & np.isfinite(g)
    d, z, g = d[ok], z[ok], g[ok]
    if d.size < MIN_DETECTIONS:
        raise EstimationError(f"calibration needs at least {MIN_DETECTIONS} detections with a "
                              f"known receiver position, found {d.size}")
    x = -10.0 * np.log10(np.maximum(d, min_distance_m) / d0_m)
    y = z - g
    if np.ptp(x) < 0.05:  # < ~1 % spread in distance: P0 and n cannot be separated
        raise EstimationError("calibration needs detections over a range of distances; all "
                              f"are at about {float(np.median(d)):.0f} m")
    design = np.column_stack([np.ones_like(x), x])
    start, *_ = np.linalg.lstsq(design, y, rcond=None)
    robust = least_squares(lambda p: design @ p - y, start, loss="soft_l1",
                           f_scale=max(2.0 * noise_guess_db, 0.5))
    resid = y - design @ robust.x
    centre = float(np.median(resid))
    sigma_robust = _MAD_TO_SIGMA * float(np.median(np.abs(resid - centre)))
    inlier = np.abs(resid) <= OUTLIER_SIGMAS * max(sigma_robust, 1e-6)
    if inlier.sum() < MIN_DETECTIONS:
        raise EstimationError("calibration: too few detections agree with any path-loss curve")
    coef, *_ = np.linalg.lstsq(design[inlier], y[inlier], rcond=None)
    r_in = y[inlier] - design[inlier] @ coef
    dof = max(int(inlier.sum()) - 2, 1)
    sigma = float(math.sqrt(float(r_in @ r_in) / dof))
    cov = sigma**2 * np.linalg.inv(design[inlier].T @ design[inlier])
    return PathLossFit(
        p0_db=float(coef[0]), path_loss_exponent=float(coef[1]), noise_std_db=sigma,
        p0_se_db=float(math.sqrt(cov[0, 0])), n_se=float(math.sqrt(cov[1, 1])), d0_m=d0_m,
        used=int(inlier.sum()), outliers=int((~inlier).sum()),
        distance_min_m=float(d[inlier].min()), distance_max_m=float(d[inlier].max()))


def tag_positions(flight: FlightData, tag_id: str, source: str, truth: Truth | None = None,
                  given_en_m: tuple[float, float] | None = None) -> PositionFn:
    """Where the tag was at any time, from ``source``:

    - ``given``: a fixed surveyed position (``given_en_m``);
    - ``truth``: the simulator's track, interpolated;
    - ``estimate``: the final estimate for a filter that assumes a (nearly) stationary tag
      (static or rw), else the estimate track interpolated in time.
    """
    if source == "given":
        if given_en_m is None:
            raise EstimationError("a given tag position is needed")
        fixed = np.asarray(given_en_m, dtype=np.float64)
        return lambda t: np.broadcast_to(fixed, (np.size(t), 2)).copy()
    if source == "truth":
        if truth is None or tag_id not in truth.tags:
            raise EstimationError(f"no ground truth for tag {tag_id}")
        return truth.tags[tag_id].position_at
    if source == "estimate":
        series = flight.estimates.get(tag_id)
        if series is None or len(series) == 0:
            raise EstimationError(f"no estimate of tag {tag_id} in the log")
        if flight.mission.filter.motion in ("static", "rw"):
            final = np.array([series.east_m[-1], series.north_m[-1]])
            return lambda t: np.broadcast_to(final, (np.size(t), 2)).copy()
        return series.position_at
    raise ValueError(f"unknown position source {source!r}")


def detection_geometry(flight: FlightData, tag_id: str, position: PositionFn,
                       front_back_db: float | None = None,
                       only_when_localised: bool = False) -> tuple[FloatArray, FloatArray,
                                                                    FloatArray]:
    """(distance_m, gain_db, rssi_db) of a tag's detections against its positions.

    ``only_when_localised``: keep detections only while the tag's estimate radius is within
    the mission's localisation radius (for an estimated track of a moving tag)."""
    det = flight.detections
    sel = det.of_tag(tag_id) & np.all(np.isfinite(det.rx_enu_m), axis=1)
    t = det.pose_times()[sel]
    if only_when_localised:
        series = flight.estimates.get(tag_id)
        if series is not None and len(series):
            r = np.interp(t, series.t, series.radius_m)
            keep = r <= flight.mission.localisation.radius_m
            t, sel_idx = t[keep], np.flatnonzero(sel)[keep]
            sel = np.zeros_like(sel)
            sel[sel_idx] = True
    rx = det.rx_enu_m[sel]
    yaw = np.radians(det.rx_yaw_deg[sel])
    yaw = np.where(np.isfinite(yaw), yaw, 0.0)
    xy = position(t)
    radio = flight.mission.radio_model()
    dist = np.sqrt(((xy - rx[:, :2]) ** 2).sum(axis=1) + rx[:, 2] ** 2)
    fb = radio.front_back_db if front_back_db is None else front_back_db
    gain_model = replace(radio, p0_db=0.0, path_loss_exponent=0.0, front_back_db=fb)
    gain = gain_model.power_db(xy, rx, yaw) if len(t) else np.zeros(0)
    return dist, np.asarray(gain, dtype=np.float64), det.rssi_db[sel]


def calibration_data(flight: FlightData, tags: tuple[str, ...], source: str,
                     truth: Truth | None = None,
                     given_en_m: tuple[float, float] | None = None,
                     front_back_db: float | None = None) -> tuple[FloatArray, FloatArray,
                                                                  FloatArray]:
    """(distance_m, gain_db, rssi_db) of the detections of ``tags`` (pooled), positions from
    ``source`` (see :func:`tag_positions`). Tags without a position are left out; if none
    has one, the first tag's EstimationError is raised."""
    ds, gs, zs = [np.zeros(0)], [np.zeros(0)], [np.zeros(0)]
    moving_estimate = source == "estimate" and flight.mission.filter.motion not in ("static",
                                                                                    "rw")
    missing: list[EstimationError] = []
    for tid in tags:
        try:
            pos = tag_positions(flight, tid, source, truth, given_en_m)
        except EstimationError as exc:  # pooled: use the tags that have positions
            missing.append(exc)
            continue
        d, g, z = detection_geometry(flight, tid, pos, front_back_db,
                                     only_when_localised=moving_estimate)
        ds.append(d)
        gs.append(g)
        zs.append(z)
    if missing and len(missing) == len(tags):
        raise missing[0]
    return np.concatenate(ds), np.concatenate(gs), np.concatenate(zs)


def calibrate(flight: FlightData, tags: tuple[str, ...], source: str,
              truth: Truth | None = None,
              given_en_m: tuple[float, float] | None = None,
              front_back_db: float | None = None,
              max_distance_m: float | None = None) -> PathLossFit:
    """Fit the path loss to the detections of ``tags`` (pooled), positions from ``source``."""
    return calibrate_flights([(flight, truth, given_en_m)], tags, source, front_back_db,
                             max_distance_m)


def calibrate_flights(
    flights: list[tuple[FlightData, Truth | None, tuple[float, float] | None]],
    tags: tuple[str, ...], source: str, front_back_db: float | None = None,
    max_distance_m: float | None = None,
) -> PathLossFit:
    """One fit pooled over several flights (e.g. of one site): (flight, truth, given tag
    position in that flight's ENU frame) each. The radio model's d0 and distance clamp are
    the first flight's."""
    if not flights:
        raise EstimationError("calibration needs at least one flight")
    parts = [calibration_data(f, tuple(t for t in tags if t in f.tag_ids), source, truth,
                              given, front_back_db) for f, truth, given in flights]
    d = np.concatenate([p[0] for p in parts])
    g = np.concatenate([p[1] for p in parts])
    z = np.concatenate([p[2] for p in parts])
    if max_distance_m is not None:
        keep = d <= max_distance_m
        d, g, z = d[keep], g[keep], z[keep]
    radio = flights[0][0].mission.radio_model()
    fit = fit_path_loss(d, z, g, d0_m=radio.d0_m, min_distance_m=radio.min_distance_m,
                        noise_guess_db=radio.noise_std_db)
    return replace(fit, tags=tuple(tags), source=source)


def model_of(fit: PathLossFit, base: RadioModel) -> RadioModel:
    """The radio model with the fitted P0, n and noise."""
    return replace(base, p0_db=fit.p0_db, path_loss_exponent=fit.path_loss_exponent,
                   noise_std_db=max(fit.noise_std_db, 1e-3), d0_m=fit.d0_m)
