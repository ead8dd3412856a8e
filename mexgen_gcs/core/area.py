"""The search area: a simple polygon in the local ENU frame (metres about home).

Rectangles are polygons with four vertices. Containment is vectorised over points with a
loop over the (few) edges only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class SearchArea:
    """A simple polygon, vertices (K, 2) east/north metres, K >= 3, either orientation."""

    vertices_m: FloatArray

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices_m, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3 or not np.all(np.isfinite(v)):
            raise ValueError("a search area needs at least 3 finite (east, north) vertices")
        if self.area_m2(v) <= 0.0:
            raise ValueError("the search area polygon has zero area")
        object.__setattr__(self, "vertices_m", v)

    @classmethod
    def rectangle(cls, west_m: float, east_m: float, south_m: float, north_m: float) -> SearchArea:
        if not (east_m > west_m and north_m > south_m):
            raise ValueError("rectangle needs east > west and north > south")
        return cls(
            np.array([[west_m, south_m], [east_m, south_m], [east_m, north_m], [west_m, north_m]])
        )

    @staticmethod
    def area_m2(v: FloatArray) -> float:
        x, y = v[:, 0], v[:, 1]
        return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(west, east, south, north) of the bounding box, metres."""
        v = self.vertices_m
        return (float(v[:, 0].min()), float(v[:, 0].max()), float(v[:, 1].min()),
                float(v[:, 1].max()))

    @property
    def centre_m(self) -> FloatArray:
        w, e, s, n = self.bounds
        return np.array([(w + e) / 2.0, (s + n) / 2.0])

    def contains(self, xy: FloatArray) -> NDArray[np.bool_]:
        """Even-odd rule: (..., 2) points -> (...) bool. Points on an edge may go either way."""
        x, y = xy[..., 0], xy[..., 1]
        inside = np.zeros(np.shape(x), dtype=bool)
        v = self.vertices_m
        xj, yj = v[-1]
        for xi, yi in v:
            crosses = (yi > y) != (yj > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                x_at = (xj - xi) * (y - yi) / (yj - yi) + xi
            inside ^= crosses & (x < x_at)
            xj, yj = xi, yi
        return inside

    def distance_outside_m(self, xy: FloatArray) -> FloatArray:
        """Distance to the boundary for points outside, else 0; (..., 2) -> (...)."""
        p = np.asarray(xy, dtype=np.float64)
        v = self.vertices_m
        a, b = v, np.roll(v, -1, axis=0)
        ab = b - a  # (K, 2)
        ap = p[..., None, :] - a  # (..., K, 2)
        t = np.clip((ap * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
        closest = a + t[..., None] * ab
        d = np.sqrt(((p[..., None, :] - closest) ** 2).sum(-1)).min(axis=-1)
        return np.where(self.contains(p), 0.0, d)

    def sample_uniform(self, n: int, rng: np.random.Generator) -> FloatArray:
        """n points uniform in the polygon, (n, 2), by rejection from the bounding box."""
        w, e, s, nn = self.bounds
        frac = self.area_m2(self.vertices_m) / ((e - w) * (nn - s))
        out = np.empty((n, 2))
        filled = 0
        while filled < n:
            m = int((n - filled) / frac * 1.2) + 8
            pts = np.column_stack([rng.uniform(w, e, m), rng.uniform(s, nn, m)])
            pts = pts[self.contains(pts)][: n - filled]
            out[filled : filled + len(pts)] = pts
            filled += len(pts)
        return out
