"""Geofence geometry uploaded over MAVLink (MAV_MISSION_TYPE_FENCE), in the local ENU frame.

Frame: ENU metres about the mission home (x east, y north). The MAVLink side converts the
uploaded lat/lon vertices with the mission's LocalFrame before building a ``Fence``.
PX4 semantics: the vehicle must be inside at least one inclusion shape (if there is any) and
outside every exclusion shape.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mexgen_gcs.core.area import SearchArea

# MAV_CMD values of fence items.
FENCE_RETURN_POINT = 5000
FENCE_POLYGON_VERTEX_INCLUSION = 5001
FENCE_POLYGON_VERTEX_EXCLUSION = 5002
FENCE_CIRCLE_INCLUSION = 5003
FENCE_CIRCLE_EXCLUSION = 5004


@dataclass(frozen=True, slots=True)
class FenceItem:
    """One MISSION_ITEM_INT of a fence upload, geodetic (what was sent, kept for download)."""

    command: int
    frame: int
    param1: float
    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True, slots=True)
class Circle:
    east_m: float
    north_m: float
    radius_m: float

    def contains(self, east_m: float, north_m: float) -> bool:
        return math.hypot(east_m - self.east_m, north_m - self.north_m) <= self.radius_m


@dataclass(frozen=True, slots=True)
class Fence:
    """Inclusion/exclusion polygons and circles in ENU metres."""

    inclusion_polygons: tuple[SearchArea, ...] = ()
    exclusion_polygons: tuple[SearchArea, ...] = ()
    inclusion_circles: tuple[Circle, ...] = ()
    exclusion_circles: tuple[Circle, ...] = ()
    items: tuple[FenceItem, ...] = field(default=(), compare=False)

    @property
    def empty(self) -> bool:
        return not (self.inclusion_polygons or self.exclusion_polygons
                    or self.inclusion_circles or self.exclusion_circles)

    def allows(self, east_m: float, north_m: float) -> bool:
        """True when the point satisfies the fence (always, for an empty fence)."""
        p = np.array([east_m, north_m])
        inclusions = len(self.inclusion_polygons) + len(self.inclusion_circles)
        if inclusions:
            inside_any = any(bool(a.contains(p)) for a in self.inclusion_polygons) or any(
                c.contains(east_m, north_m) for c in self.inclusion_circles)
            if not inside_any:
                return False
        if any(bool(a.contains(p)) for a in self.exclusion_polygons):
            return False
        return not any(c.contains(east_m, north_m) for c in self.exclusion_circles)


def build_fence(
    items: list[FenceItem], to_enu: Callable[[float, float], tuple[float, float]]
) -> Fence:
    """Group uploaded items into shapes. ``to_enu(lat, lon) -> (east, north)``.

    Polygon vertices come in runs whose param1 is the vertex count. Raises ValueError for a
    malformed upload (wrong run length, polygon with < 3 vertices or zero area, bad radius).
    """
    inc_poly: list[SearchArea] = []
    exc_poly: list[SearchArea] = []
    inc_circ: list[Circle] = []
    exc_circ: list[Circle] = []
    i = 0
    while i < len(items):
        item = items[i]
        if item.command in (FENCE_POLYGON_VERTEX_INCLUSION, FENCE_POLYGON_VERTEX_EXCLUSION):
            count = int(item.param1)
            run = items[i:i + count]
            if count < 3 or len(run) != count or any(r.command != item.command for r in run):
                raise ValueError(f"polygon at item {i} needs {count} >= 3 vertices of one kind")
            vertices = np.array([to_enu(r.lat_deg, r.lon_deg) for r in run], dtype=np.float64)
            area = SearchArea(vertices)  # raises ValueError on degenerate polygons
            (inc_poly if item.command == FENCE_POLYGON_VERTEX_INCLUSION else exc_poly).append(area)
            i += count
            continue
        if item.command in (FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION):
            if not (math.isfinite(item.param1) and item.param1 > 0.0):
                raise ValueError(f"circle at item {i} has radius {item.param1}")
            e, n = to_enu(item.lat_deg, item.lon_deg)
            circle = Circle(float(e), float(n), float(item.param1))
            (inc_circ if item.command == FENCE_CIRCLE_INCLUSION else exc_circ).append(circle)
        elif item.command != FENCE_RETURN_POINT:
            raise ValueError(f"item {i} has command {item.command}, not a fence item")
        i += 1
    return Fence(tuple(inc_poly), tuple(exc_poly), tuple(inc_circ), tuple(exc_circ),
                 tuple(items))


def inclusion_items(polygon_latlon_deg: list[tuple[float, float]]) -> list[FenceItem]:
    """One inclusion polygon as the fence items a ground station uploads (MAV_FRAME_GLOBAL,
    param1 = the vertex count), e.g. a fence the pilot's station put there before ours."""
    n = len(polygon_latlon_deg)
    return [FenceItem(FENCE_POLYGON_VERTEX_INCLUSION, 0, float(n), lat, lon, 0.0)
            for lat, lon in polygon_latlon_deg]
