"""GIS exports of a flight: GeoJSON (RFC 7946: WGS84, [lon, lat] order) and CSV.

Files: ``flight.geojson`` (the search area polygon, the flight path line and one point per
tag's final estimate with its properties), ``tags.csv`` (one row per tag) and ``path.csv``
(the receiver's track). Frame: WGS84 degrees plus local ENU metres about home in the CSVs.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mexgen_gcs.analysis.flightdata import FlightData
from mexgen_gcs.analysis.summary import FlightSummary

GEOJSON = "flight.geojson"
TAGS_CSV = "tags.csv"
PATH_CSV = "path.csv"
TAG_COLUMNS = (
    "tag", "freq_hz", "detections", "localised", "localised_after_s", "lat_deg", "lon_deg",
    "east_m", "north_m", "radius_m", "sigma_major_m", "existence", "localised_lat_deg",
    "localised_lon_deg", "error_at_localisation_m", "final_error_m",
)
PATH_COLUMNS = ("t_unix", "t_since_airborne_s", "lat_deg", "lon_deg", "alt_rel_m", "east_m",
                "north_m", "yaw_deg")


@dataclass(frozen=True, slots=True)
class Exports:
    geojson: Path
    tags_csv: Path
    path_csv: Path


def _r(x: float | None, digits: int) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), digits)


def tag_rows(summary: FlightSummary) -> list[dict[str, Any]]:
    return [{
        "tag": t.tag_id, "freq_hz": t.freq_hz, "detections": t.detections,
        "localised": t.localised, "localised_after_s": _r(t.localised_after_s, 2),
        "lat_deg": _r(t.final_lat_deg, 7), "lon_deg": _r(t.final_lon_deg, 7),
        "east_m": _r(t.final_east_m, 2), "north_m": _r(t.final_north_m, 2),
        "radius_m": _r(t.final_radius_m, 2), "sigma_major_m": _r(t.final_sigma_major_m, 2),
        "existence": _r(t.final_existence, 4), "localised_lat_deg": _r(t.localised_lat_deg, 7),
        "localised_lon_deg": _r(t.localised_lon_deg, 7),
        "error_at_localisation_m": _r(t.error_at_localisation_m, 2),
        "final_error_m": _r(t.final_error_m, 2),
    } for t in summary.tags]


def path_lat_lon(flight: FlightData) -> tuple[np.ndarray, np.ndarray]:
    tr = flight.track
    lat, lon, _ = flight.frame.to_geodetic(tr.east_m, tr.north_m, 0.0)
    return np.atleast_1d(lat), np.atleast_1d(lon)


def geojson(flight: FlightData, summary: FlightSummary) -> dict[str, Any]:
    """The flight as a GeoJSON FeatureCollection."""
    features: list[dict[str, Any]] = []
    v = flight.area.vertices_m
    alat, alon, _ = flight.frame.to_geodetic(v[:, 0], v[:, 1], 0.0)
    ring = [[round(float(x), 7), round(float(y), 7)] for x, y in zip(alon, alat, strict=True)]
    ring.append(ring[0])
    features.append({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
                     "properties": {"kind": "search_area", "mission": flight.mission.name}})
    lat, lon = path_lat_lon(flight)
    if lat.size >= 2:
        coords = [[round(float(x), 7), round(float(y), 7)] for x, y in zip(lon, lat, strict=True)]
        features.append({"type": "Feature",
                         "geometry": {"type": "LineString", "coordinates": coords},
                         "properties": {"kind": "flight_path", "method": flight.method,
                                        "distance_m": round(flight.track.distance_m(), 1)}})
    for row in tag_rows(summary):
        if row["lat_deg"] is None or row["lon_deg"] is None:
            continue
        features.append({"type": "Feature",
                         "geometry": {"type": "Point",
                                      "coordinates": [row["lon_deg"], row["lat_deg"]]},
                         "properties": {"kind": "tag_estimate", **row}})
    return {"type": "FeatureCollection", "features": features}


def write_exports(flight: FlightData, summary: FlightSummary, out_dir: Path) -> Exports:
    """Write flight.geojson, tags.csv and path.csv into out_dir (created)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    gj = out_dir / GEOJSON
    gj.write_text(json.dumps(geojson(flight, summary)), encoding="utf-8")
    tags = out_dir / TAGS_CSV
    with tags.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=TAG_COLUMNS)
        w.writeheader()
        for row in tag_rows(summary):
            w.writerow({k: "" if v is None else v for k, v in row.items()})
    path = out_dir / PATH_CSV
    tr = flight.track
    lat, lon = path_lat_lon(flight)
    since = flight.since_airborne(tr.t)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w2 = csv.writer(fh)
        w2.writerow(PATH_COLUMNS)
        for i in range(len(tr)):
            yaw = tr.yaw_deg[i]
            w2.writerow([f"{tr.t[i]:.3f}", f"{since[i]:.3f}", f"{lat[i]:.7f}", f"{lon[i]:.7f}",
                         f"{tr.up_m[i]:.2f}", f"{tr.east_m[i]:.2f}", f"{tr.north_m[i]:.2f}",
                         f"{yaw:.1f}" if math.isfinite(yaw) else ""])
    return Exports(gj, tags, path)
