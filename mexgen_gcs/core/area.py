"""The search area: a simple polygon in the local ENU frame (metres about home).

Rectangles are polygons with four vertices. Containment is vectorised over points with a
loop over the (few) edges only. ``fence_polygon`` gives the geofence to upload: the convex
hull of the area (plus any extra points, e.g. home) pushed outward by a margin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.jit import kernel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class SearchArea:
    """A simple polygon, vertices (K, 2) east/north metres, K >= 3, either orientation."""

    vertices_m: FloatArray
    _box_fill: float = field(init=False, repr=False)
    """Share of the bounding box inside the polygon (rejection sampling's acceptance)."""

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices_m, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3 or not np.all(np.isfinite(v)):
            raise ValueError("a search area needs at least 3 finite (east, north) vertices")
        if self.area_m2(v) <= 0.0:
            raise ValueError("the search area polygon has zero area")
        object.__setattr__(self, "vertices_m", v)
        w, e, s, n = self.bounds
        object.__setattr__(self, "_box_fill", self.area_m2(v) / ((e - w) * (n - s)))

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
        p = np.asarray(xy, dtype=np.float64)
        out = np.empty(p.shape[:-1], dtype=np.bool_)
        polygon_distances(np.ascontiguousarray(p).reshape(-1, 2), self.vertices_m, False,
                           out.reshape(-1), np.empty(0))
        return out

    def distance_outside_m(self, xy: FloatArray) -> FloatArray:
        """Distance to the boundary for points outside, else 0; (..., 2) -> (...)."""
        p = np.asarray(xy, dtype=np.float64)
        out = np.empty(p.shape[:-1])
        polygon_distances(np.ascontiguousarray(p).reshape(-1, 2), self.vertices_m, True,
                           np.empty(out.size, np.bool_), out.reshape(-1))
        return out

    def fence_polygon(self, margin_m: float, extra_points_m: FloatArray | None = None
                      ) -> FloatArray:
        """A convex polygon (K, 2), counter-clockwise, that contains every point within
        ``margin_m`` of the area (and of ``extra_points_m``, (P, 2), e.g. home).

        It is the convex hull offset outward by ``margin_m`` with mitred corners: each hull
        edge moves out by the margin and neighbouring edges meet where their offset lines
        cross, so the polygon contains the hull dilated by a disk of radius ``margin_m``. A
        corner sharper than 90 degrees would mitre far out; it is cut by the line tangent
        to that disk (two vertices), which still contains the dilation. Convex, so it also
        contains every straight path between two of its points (e.g. a return to home).
        """
        if not (np.isfinite(margin_m) and margin_m >= 0.0):
            raise ValueError("the fence margin must be a finite number >= 0")
        pts = self.vertices_m
        if extra_points_m is not None:
            extra = np.asarray(extra_points_m, dtype=np.float64).reshape(-1, 2)
            pts = np.vstack([pts, extra[np.all(np.isfinite(extra), axis=1)]])
        hull = convex_hull(pts)
        if margin_m == 0.0:
            return hull
        edge = np.roll(hull, -1, axis=0) - hull  # edge i: hull[i] -> hull[i + 1]
        unit = edge / np.linalg.norm(edge, axis=1, keepdims=True)
        normal = np.column_stack([unit[:, 1], -unit[:, 0]])  # outward for a CCW hull
        out: list[FloatArray] = []
        k = len(hull)
        for i in range(k):  # corner at hull[i] between edge i-1 and edge i
            n_in, n_out = normal[i - 1], normal[i]
            bisector = n_in + n_out
            cos_half = float(np.linalg.norm(bisector)) / 2.0  # cos of half the turn angle
            if cos_half >= math.sqrt(0.5) - 1e-12:  # turn <= 90 deg: the mitre is short
                out.append(hull[i] + margin_m * bisector / (2.0 * cos_half ** 2))
            else:  # cut the corner on the disk's tangent perpendicular to the bisector
                b = bisector / np.linalg.norm(bisector) if cos_half > 1e-9 else n_in
                tangent_point = hull[i] + margin_m * b
                along = np.array([-b[1], b[0]])
                # where the tangent meets the two offset edge lines
                for n_edge in (n_in, n_out):
                    denom = float(np.dot(along, n_edge))
                    s = (margin_m - float(np.dot(tangent_point - hull[i], n_edge))) / denom
                    out.append(tangent_point + s * along)
        return np.asarray(out)

    def sample_uniform(self, n: int, rng: np.random.Generator) -> FloatArray:
        """n points uniform in the polygon, (n, 2), by rejection from the bounding box."""
        w, e, s, nn = self.bounds
        frac = self._box_fill
        out = np.empty((n, 2))
        filled = 0
        while filled < n:
            m = int((n - filled) / frac * 1.2) + 8
            pts = np.column_stack([rng.uniform(w, e, m), rng.uniform(s, nn, m)])
            pts = pts[self.contains(pts)][: n - filled]
            out[filled : filled + len(pts)] = pts
            filled += len(pts)
        return out


def convex_hull(points_m: FloatArray) -> FloatArray:
    """Convex hull (K, 2) of (N, 2) points, counter-clockwise, no collinear vertices
    (Andrew's monotone chain, O(N log N)). Needs three points not on one line."""
    p = np.unique(np.asarray(points_m, dtype=np.float64).reshape(-1, 2), axis=0)  # sorted
    if len(p) < 3:
        raise ValueError("a convex hull needs at least 3 distinct points")

    def cross(o: FloatArray, a: FloatArray, b: FloatArray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    def chain(seq: FloatArray) -> list[FloatArray]:
        out: list[FloatArray] = []
        for q in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], q) <= 0.0:
                out.pop()
            out.append(q)
        return out

    lower, upper = chain(p), chain(p[::-1])
    hull = np.asarray(lower[:-1] + upper[:-1])
    if len(hull) < 3:
        raise ValueError("a convex hull needs points that are not all on one line")
    return hull


@kernel
def polygon_distances(points: FloatArray, vertices: FloatArray, distances: bool,
                      inside: NDArray[np.bool_], out: FloatArray) -> None:
    """For each point (M, 2): whether the polygon (K, 2) contains it (even-odd rule, into
    ``inside``) and, if ``distances``, its distance to the boundary when outside, else 0
    (into ``out``). O(M K), compiled: the guidance asks this of a few points every setpoint,
    where numpy's per-call cost was most of the experiment runner's world time."""
    k = vertices.shape[0]
    for m in range(points.shape[0]):
        x, y = points[m, 0], points[m, 1]
        crossing = False
        best = math.inf
        xj, yj = vertices[k - 1, 0], vertices[k - 1, 1]
        for i in range(k):
            xi, yi = vertices[i, 0], vertices[i, 1]
            if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
                crossing = not crossing
            if distances:  # to the segment from vertex i to vertex i + 1
                xb, yb = vertices[(i + 1) % k, 0], vertices[(i + 1) % k, 1]
                ex, ey = xb - xi, yb - yi
                t = min(max(((x - xi) * ex + (y - yi) * ey) / (ex * ex + ey * ey), 0.0), 1.0)
                dx, dy = x - (xi + t * ex), y - (yi + t * ey)
                best = min(best, dx * dx + dy * dy)
            xj, yj = xi, yi
        inside[m] = crossing
        if distances:
            out[m] = 0.0 if crossing else np.sqrt(best)
