"""Vehicle paths of the planner's actions and their pruning against the search area.

Frame: local ENU metres about home (x east, y north). Headings are compass headings: 0 = north,
90 deg = east, clockwise; a heading h flies the velocity ``speed * (sin h, cos h)`` (east, north).

An action holds one heading over the look-ahead. The vehicle starts from its current
horizontal velocity and changes it towards the commanded one at ``max_accel`` along the
straight line in velocity space (what a multirotor's velocity controller with an acceleration
limit does), then holds it. Closed form, vectorised over actions and times.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.area import SearchArea

FloatArray = NDArray[np.float64]

PRUNE_SUBSTEPS = 4
"""Path points checked against the area per look-ahead step."""


def action_headings_rad(n_headings: int) -> FloatArray:
    """n equally spaced compass headings starting at north: 8 -> N, NE, E, ..., NW. (A,)."""
    if n_headings < 1:
        raise ValueError(f"n_headings must be >= 1 (got {n_headings})")
    return np.arange(n_headings, dtype=np.float64) * (2.0 * math.pi / n_headings)


def compass_bearing_rad(from_xy: FloatArray, to_xy: FloatArray) -> float:
    """Compass bearing from one point to another, [0, 2 pi); 0 (north) if they coincide."""
    d = np.asarray(to_xy, dtype=np.float64)[:2] - np.asarray(from_xy, dtype=np.float64)[:2]
    return float(math.atan2(d[0], d[1]) % (2.0 * math.pi))


def vehicle_paths(
    position_m: FloatArray,
    velocity_m_s: FloatArray,
    headings_rad: FloatArray,
    speed_m_s: float,
    max_accel_m_s2: float,
    times_s: FloatArray,
) -> FloatArray:
    """Horizontal positions of the vehicle holding each heading, at each time.

    position_m: (2,) or (3,) (only east/north used); velocity_m_s: (2,) east/north;
    headings_rad: (A,); times_s: (K,) >= 0. Returns (K, A, 2) float64. With
    ``dv = v_cmd - v0``, ``t_acc = |dv| / a`` and ``tau = min(t, t_acc)``::

        p(t) = p0 + v0 t + a (dv / |dv|) (tau t - tau^2 / 2)
    """
    p0 = np.asarray(position_m, dtype=np.float64)[:2]
    v0 = np.asarray(velocity_m_s, dtype=np.float64)[:2]
    h = np.asarray(headings_rad, dtype=np.float64)
    t = np.asarray(times_s, dtype=np.float64)[:, None, None]  # (K, 1, 1)
    v_cmd = speed_m_s * np.stack([np.sin(h), np.cos(h)], axis=-1)  # (A, 2)
    dv = v_cmd - v0
    gap = np.linalg.norm(dv, axis=-1, keepdims=True)  # (A, 1)
    if not max_accel_m_s2 > 0.0:
        raise ValueError(f"max_accel_m_s2 must be > 0 (got {max_accel_m_s2})")
    if math.isinf(max_accel_m_s2):
        return p0 + t * v_cmd
    t_acc = gap / max_accel_m_s2
    unit = np.divide(dv, gap, out=np.zeros_like(dv), where=gap > 0.0)
    tau = np.minimum(t, t_acc)  # (K, A, 1)
    return p0 + v0 * t + max_accel_m_s2 * unit * (tau * t - 0.5 * tau * tau)


def fine_times_s(horizon_s: float, step_s: float) -> FloatArray:
    """PRUNE_SUBSTEPS times per step over the horizon, (K,): every PRUNE_SUBSTEPS-th is a step
    time (step_s, 2 step_s, ...), so one path evaluation serves pruning and the rollout."""
    n = max(1, math.ceil(horizon_s / step_s - 1e-9)) * PRUNE_SUBSTEPS
    return (np.arange(n, dtype=np.float64) + 1.0) * (step_s / PRUNE_SUBSTEPS)


def inside_test(area: SearchArea) -> Callable[[FloatArray], NDArray[np.bool_]]:
    """A containment test for many points, (..., 2) -> (...) bool, equal to ``area.contains``
    away from the boundary. For a convex polygon it is the intersection of the edges'
    half-planes (one small matrix product, ~10x faster than the even-odd rule); otherwise it
    is ``area.contains``.
    """
    v = np.asarray(area.vertices_m, dtype=np.float64)
    edges = np.roll(v, -1, axis=0) - v
    # Outward normals for a counter-clockwise polygon; flip for clockwise.
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=-1)
    signed_area = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    if signed_area < 0.0:
        normals = -normals
    offsets = np.sum(normals * v, axis=-1)
    # Convex iff every vertex is on the inner side of (or on) every edge line.
    if not np.all(v @ normals.T <= offsets + 1e-9 * np.abs(offsets).max(initial=1.0)):
        return area.contains
    nt = normals.T.copy()

    def contains(points_m: FloatArray) -> NDArray[np.bool_]:
        return np.all(np.asarray(points_m) @ nt < offsets, axis=-1)

    return contains


def leaves_area(
    inside: Callable[[FloatArray], NDArray[np.bool_]], points_m: FloatArray
) -> NDArray[np.bool_]:
    """(A,) True where any of an action's path points (K, A, 2) is outside the area.

    ``inside``: a containment test (``area.contains`` or :func:`inside_test`). With
    PRUNE_SUBSTEPS points per step (2.5 m apart at 10 m/s and 1 s steps) a path can only cut a
    corner of the polygon by less than that.
    """
    return np.asarray(~inside(points_m).all(axis=0), dtype=np.bool_)
