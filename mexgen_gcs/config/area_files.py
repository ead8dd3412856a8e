"""Search areas from the files field teams already have, and back: QGroundControl `.plan`,
KML and GeoJSON.

Reading (``read_area_file``) gives one simple polygon as ``[(lat_deg, lon_deg), ...]``, not
closed, from:

- a QGroundControl plan (JSON, ``"fileType": "Plan"``): the one inclusion polygon of
  ``geoFence.polygons`` (``{"inclusion": true, "polygon": [[lat, lon], ...]}``), or the
  version-1 ``geoFence.polygon`` list;
- KML: the one ``Polygon``'s ``outerBoundaryIs/LinearRing/coordinates``, text tuples
  ``lon,lat[,alt]`` separated by white space (namespace-aware, any KML namespace);
- GeoJSON (RFC 7946, ``[lon, lat]`` order): a Polygon, a MultiPolygon with one polygon, a
  Feature holding either, or a FeatureCollection with exactly one such feature. Holes are
  refused (the search area has none).

Every refusal is an ``AreaFileError`` naming the file, what was found and what is expected; the
mission loader turns it into a problem at ``area.from``. The polygon is checked here as a field
team's file goes wrong: too few vertices, self-intersecting, or nowhere near home (the other
hemisphere, or latitude and longitude swapped).

Writing (``plan_text``, ``kml_text``, ``geojson_text``) gives the same polygon in each format;
the plan carries home as ``mission.plannedHomePosition`` and the area as the geofence's
inclusion polygon, so the pilot opens it in QGroundControl. Frames: WGS84 degrees in the files;
the distance checks use the mission's local ENU frame about home (metres).
"""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from mexgen_gcs.core.geo import LocalFrame

MAX_AREA_FILE_BYTES = 10_000_000
MAX_VERTICES = 200
"""The mission schema's limit on polygon_deg."""
MAX_DISTANCE_FROM_HOME_M = 50_000.0
"""An area whose nearest vertex is further than this from home is refused as a wrong file."""
SUFFIXES = {".plan": "plan", ".kml": "kml", ".geojson": "geojson", ".json": "geojson"}

LatLon = tuple[float, float]


class AreaFileError(ValueError):
    """An area file that cannot be used; the message names the file."""


def read_area_file(path: str | os.PathLike[str], home_lat_deg: float, home_lon_deg: float
                   ) -> list[LatLon]:
    """The polygon in `path` as [(lat_deg, lon_deg), ...], checked against home."""
    file = Path(path)
    kind = SUFFIXES.get(file.suffix.lower())
    if kind is None:
        raise AreaFileError(f"{file}: unknown area file type {file.suffix or '(none)'!r}; "
                            "expected .plan (QGroundControl), .kml or .geojson")
    try:
        if file.stat().st_size > MAX_AREA_FILE_BYTES:
            raise AreaFileError(f"{file}: {file.stat().st_size:,} bytes; an area file is at "
                                f"most {MAX_AREA_FILE_BYTES:,}")
        raw = file.read_bytes()
    except FileNotFoundError:
        raise AreaFileError(f"{file}: no such area file") from None
    except IsADirectoryError:
        raise AreaFileError(f"{file}: is a directory; expected an area file") from None
    except OSError as exc:
        raise AreaFileError(f"{file}: cannot read the area file: {exc.strerror}") from None
    if kind == "kml":
        vertices = _from_kml(raw, file)
    else:
        try:
            doc = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise AreaFileError(f"{file}: not JSON ({exc}); expected a "
                                f"{'QGroundControl plan' if kind == 'plan' else 'GeoJSON'} "
                                "file") from None
        vertices = _from_plan(doc, file) if kind == "plan" else _from_geojson(doc, file)
    return check_polygon(vertices, file, home_lat_deg, home_lon_deg)


# -- readers -------------------------------------------------------------------------------

def _from_plan(doc: Any, file: Path) -> list[LatLon]:
    if not isinstance(doc, dict) or doc.get("fileType") != "Plan":
        found = doc.get("fileType") if isinstance(doc, dict) else type(doc).__name__
        raise AreaFileError(f"{file}: fileType is {found!r}; expected a QGroundControl plan "
                            "(\"fileType\": \"Plan\")")
    fence = doc.get("geoFence")
    if not isinstance(fence, dict):
        raise AreaFileError(f"{file}: no geoFence; expected the area as the plan's geofence "
                            "inclusion polygon (draw it in QGroundControl's Plan view, Fence)")
    if "polygons" in fence:
        polygons = fence["polygons"]
        inclusions = [p for p in polygons if isinstance(p, dict) and p.get("inclusion", True)] \
            if isinstance(polygons, list) else []
        circles = fence.get("circles") or []
        if len(inclusions) != 1:
            extra = f" (and {len(circles)} circles, which are not read)" if circles else ""
            raise AreaFileError(f"{file}: geoFence has {len(inclusions)} inclusion polygons"
                                f"{extra}; expected exactly one")
        points = inclusions[0].get("polygon")
    else:
        points = fence.get("polygon")  # plan version 1: one polygon
    return _pairs(points, file, "geoFence polygon", lat_first=True)


def _from_kml(raw: bytes, file: Path) -> list[LatLon]:
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as exc:
        raise AreaFileError(f"{file}: not XML ({exc}); expected a KML file") from None
    if _local(root.tag) != "kml":
        raise AreaFileError(f"{file}: root element <{_local(root.tag)}>; expected <kml>")
    polygons = [el for el in root.iter() if _local(el.tag) == "Polygon"]
    if len(polygons) != 1:
        lines = sum(1 for el in root.iter() if _local(el.tag) in ("LineString", "Point"))
        extra = f" ({lines} lines or points)" if lines and not polygons else ""
        raise AreaFileError(f"{file}: {len(polygons)} Polygon elements{extra}; expected "
                            "exactly one Polygon (the area)")
    polygon = polygons[0]
    if any(_local(el.tag) == "innerBoundaryIs" for el in polygon):
        raise AreaFileError(f"{file}: the Polygon has holes (innerBoundaryIs); expected a "
                            "polygon without holes")
    coords = [el for outer in polygon if _local(outer.tag) == "outerBoundaryIs"
              for el in outer.iter() if _local(el.tag) == "coordinates"]
    if len(coords) != 1 or not (coords[0].text or "").strip():
        raise AreaFileError(f"{file}: the Polygon has no outerBoundaryIs/LinearRing/"
                            "coordinates; expected 'lon,lat[,alt]' tuples")
    out: list[list[float]] = []
    for token in (coords[0].text or "").split():
        parts = token.split(",")
        try:
            if len(parts) not in (2, 3):
                raise ValueError
            out.append([float(parts[0]), float(parts[1])])
        except ValueError:
            raise AreaFileError(f"{file}: coordinate {token!r}; expected 'lon,lat' or "
                                "'lon,lat,alt' (decimal degrees)") from None
    return _pairs(out, file, "KML coordinates", lat_first=False)


def _from_geojson(doc: Any, file: Path) -> list[LatLon]:
    geometry = doc
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        features = doc.get("features")
        polys = [f for f in features if isinstance(f, dict) and isinstance(
            f.get("geometry"), dict) and f["geometry"].get("type") in ("Polygon", "MultiPolygon")
        ] if isinstance(features, list) else []
        if len(polys) != 1:
            raise AreaFileError(f"{file}: FeatureCollection with {len(polys)} polygon features; "
                                "expected exactly one")
        geometry = polys[0]["geometry"]
    elif isinstance(doc, dict) and doc.get("type") == "Feature":
        geometry = doc.get("geometry")
    kind = geometry.get("type") if isinstance(geometry, dict) else None
    rings: Any = geometry.get("coordinates") if isinstance(geometry, dict) else None
    if kind == "MultiPolygon":
        if not isinstance(rings, list) or len(rings) != 1:
            n = len(rings) if isinstance(rings, list) else 0
            raise AreaFileError(f"{file}: MultiPolygon with {n} polygons; expected exactly one")
        rings = rings[0]
    elif kind != "Polygon":
        raise AreaFileError(f"{file}: GeoJSON {kind or type(geometry).__name__!s}; expected a "
                            "Polygon (or a Feature / FeatureCollection holding one)")
    if not isinstance(rings, list) or not rings:
        raise AreaFileError(f"{file}: the Polygon has no coordinates; expected "
                            "[[[lon, lat], ...]]")
    if len(rings) > 1:
        raise AreaFileError(f"{file}: the Polygon has {len(rings) - 1} holes; expected a "
                            "polygon without holes")
    return _pairs(rings[0], file, "GeoJSON ring", lat_first=False)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _pairs(points: Any, file: Path, what: str, *, lat_first: bool) -> list[LatLon]:
    """[[a, b(, alt)], ...] -> [(lat, lon)], ring closure dropped, ranges checked."""
    order = "[lat, lon]" if lat_first else "[lon, lat]"
    if not isinstance(points, list):
        raise AreaFileError(f"{file}: {what} is {type(points).__name__}; expected a list of "
                            f"{order} pairs")
    out: list[LatLon] = []
    for i, p in enumerate(points):
        ok = isinstance(p, list | tuple) and len(p) in (2, 3) and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            for x in p)
        if not ok:
            raise AreaFileError(f"{file}: {what} point {i} is {p!r}; expected {order} in "
                                "decimal degrees")
        lat, lon = (float(p[0]), float(p[1])) if lat_first else (float(p[1]), float(p[0]))
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise AreaFileError(f"{file}: {what} point {i} has latitude {lat:g}, longitude "
                                f"{lon:g}; expected {order} with latitude in -90..90 and "
                                "longitude in -180..180")
        out.append((lat, lon))
    if len(out) >= 2 and out[0] == out[-1]:
        out.pop()  # a closed ring (KML, GeoJSON and often plans): the last vertex repeats
    return out


# -- checks --------------------------------------------------------------------------------

def check_polygon(vertices: list[LatLon], file: Path | str, home_lat_deg: float,
                  home_lon_deg: float) -> list[LatLon]:
    """Refuse what cannot be the search area: < 3 or > MAX_VERTICES vertices, zero area,
    crossing edges, or nowhere near home. Returns `vertices`."""
    if len(vertices) < 3:
        raise AreaFileError(f"{file}: {len(vertices)} distinct vertices; expected a polygon "
                            "with at least 3")
    if len(vertices) > MAX_VERTICES:
        raise AreaFileError(f"{file}: {len(vertices)} vertices; expected at most "
                            f"{MAX_VERTICES} (simplify the polygon)")
    lat = np.array([v[0] for v in vertices])
    lon = np.array([v[1] for v in vertices])
    if np.sign(lat.mean()) != np.sign(home_lat_deg) and abs(lat.mean() - home_lat_deg) > 1.0:
        hint = " (latitude and longitude swapped?)" if np.allclose(
            [lon.mean(), lat.mean()], [home_lat_deg, home_lon_deg], atol=1.0) else ""
        raise AreaFileError(f"{file}: the polygon is in the other hemisphere from home "
                            f"(latitude {lat.mean():.4f} vs home {home_lat_deg:.4f}){hint}; "
                            "expected an area around home")
    east, north, _ = LocalFrame(home_lat_deg, home_lon_deg, 0.0).to_enu(lat, lon)
    v = np.column_stack([east, north])
    nearest_m = float(np.min(np.hypot(east, north)))
    if nearest_m > MAX_DISTANCE_FROM_HOME_M:
        raise AreaFileError(f"{file}: the polygon's nearest vertex is {nearest_m / 1000:.0f} km "
                            f"from home; expected an area within "
                            f"{MAX_DISTANCE_FROM_HOME_M / 1000:.0f} km of home (a wrong file, "
                            "or home is wrong?)")
    crossing = self_intersection(v)
    if crossing is not None:
        i, j = crossing
        raise AreaFileError(f"{file}: the polygon's edges {i}-{i + 1} and {j}-"
                            f"{(j + 1) % len(v)} cross; expected a simple polygon (vertices in "
                            "order around the boundary)")
    x, y = v[:, 0], v[:, 1]
    if 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))) <= 1.0:
        raise AreaFileError(f"{file}: the polygon encloses no area (its vertices lie on a "
                            "line); expected a polygon around the search area")
    return vertices


def self_intersection(v: np.ndarray) -> tuple[int, int] | None:
    """First pair of non-adjacent polygon edges (K, 2 vertices) that cross, or None. O(K^2)."""
    k = len(v)

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
        return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    for i in range(k):
        a, b = v[i], v[(i + 1) % k]
        for j in range(i + 1, k):
            if j == i + 1 or (i == 0 and j == k - 1):
                continue  # adjacent edges share a vertex
            c, d = v[j], v[(j + 1) % k]
            d1, d2 = orient(a, b, c), orient(a, b, d)
            d3, d4 = orient(c, d, a), orient(c, d, b)
            if (d1 * d2 < 0.0) and (d3 * d4 < 0.0):
                return i, j
    return None


# -- writers -------------------------------------------------------------------------------

def plan_text(polygon: list[LatLon], home: tuple[float, float, float], *,
              cruise_speed_m_s: float = 10.0) -> str:
    """A QGroundControl plan: the area as the geofence's one inclusion polygon, home as the
    planned home position (lat, lon, alt AMSL), no mission items (this GCS flies offboard)."""
    doc = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "QGroundControl",
        "mission": {
            "version": 2, "firmwareType": 12, "vehicleType": 2,  # PX4, multirotor
            "cruiseSpeed": cruise_speed_m_s, "hoverSpeed": cruise_speed_m_s,
            "globalPlanAltitudeMode": 1, "items": [],
            "plannedHomePosition": [home[0], home[1], home[2]],
        },
        "geoFence": {
            "version": 2, "circles": [],
            "polygons": [{"inclusion": True, "version": 1,
                          "polygon": [[lat, lon] for lat, lon in polygon]}],
        },
        "rallyPoints": {"version": 2, "points": []},
    }
    return json.dumps(doc, indent=2) + "\n"


def kml_text(polygon: list[LatLon], name: str) -> str:
    """KML 2.2 with one Placemark holding the area as a closed Polygon."""
    ring = [*polygon, polygon[0]]
    coords = " ".join(f"{lon!r},{lat!r},0" for lat, lon in ring)
    safe = name.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return ("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
            "<kml xmlns=\"http://www.opengis.net/kml/2.2\"><Document>"
            f"<name>{safe}</name><Placemark><name>search area</name><Polygon>"
            "<outerBoundaryIs><LinearRing><coordinates>"
            f"{coords}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>"
            "</Document></kml>\n")


def geojson_text(polygon: list[LatLon], name: str) -> str:
    """GeoJSON (RFC 7946): a FeatureCollection with the area as one Polygon feature."""
    ring = [[lon, lat] for lat, lon in [*polygon, polygon[0]]]
    doc = {"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"name": name, "role": "search area"},
        "geometry": {"type": "Polygon", "coordinates": [ring]}}]}
    return json.dumps(doc, indent=2) + "\n"


def write_area_file(path: str | os.PathLike[str], polygon: list[LatLon],
                    home: tuple[float, float, float], name: str) -> str:
    """Write the area in the format of `path`'s suffix; returns the format written."""
    file = Path(path)
    kind = SUFFIXES.get(file.suffix.lower())
    if kind is None:
        raise AreaFileError(f"{file}: unknown output type {file.suffix or '(none)'!r}; "
                            "expected .plan, .kml or .geojson")
    text = (plan_text(polygon, home) if kind == "plan" else
            kml_text(polygon, name) if kind == "kml" else geojson_text(polygon, name))
    file.write_text(text, encoding="utf-8")
    return kind

