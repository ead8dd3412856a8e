"""GeoJSON and CSV exports of a real flight parse and agree with the report."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest

from mexgen_gcs.analysis import load_flight
from mexgen_gcs.analysis.cli import cmd_analyze
from mexgen_gcs.analysis.export import PATH_COLUMNS, TAG_COLUMNS

pytestmark = pytest.mark.e2e


def test_exports_parse_as_geojson_and_csv(demo_log: Path, tmp_path: Path,
                                          make_args: Any) -> None:
    assert cmd_analyze(make_args(log=str(demo_log), out=str(tmp_path), export=True)) == 0
    flight = load_flight(demo_log)
    home_lat, home_lon = flight.frame.lat0_deg, flight.frame.lon0_deg
    gj = json.loads((tmp_path / "flight.geojson").read_text())
    assert gj["type"] == "FeatureCollection"
    kinds = {f["properties"]["kind"]: f for f in gj["features"]}
    area = kinds["search_area"]["geometry"]
    assert area["type"] == "Polygon" and area["coordinates"][0][0] == area["coordinates"][0][-1]
    line = kinds["flight_path"]["geometry"]
    assert line["type"] == "LineString" and len(line["coordinates"]) == len(flight.track)
    for lon, lat in line["coordinates"]:  # RFC 7946 order: [lon, lat], within ~2 km of home
        assert abs(lon - home_lon) < 0.03 and abs(lat - home_lat) < 0.03
    points = [f for f in gj["features"] if f["properties"]["kind"] == "tag_estimate"]
    assert {p["properties"]["tag"] for p in points} == set(flight.tag_ids)
    summary = json.loads((tmp_path / "summary.json").read_text())
    by_tag = {t["tag_id"]: t for t in summary["tags"]}
    for p in points:
        lon, lat = p["geometry"]["coordinates"]
        t = by_tag[p["properties"]["tag"]]
        assert lat == pytest.approx(t["final_lat_deg"], abs=1e-6)
        assert lon == pytest.approx(t["final_lon_deg"], abs=1e-6)

    with (tmp_path / "tags.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0].keys()) == TAG_COLUMNS
    assert [r["tag"] for r in rows] == list(flight.tag_ids)
    for r in rows:
        t = by_tag[r["tag"]]
        assert float(r["east_m"]) == pytest.approx(t["final_east_m"], abs=0.01)
        assert int(r["detections"]) == t["detections"]
        assert (r["localised_after_s"] == "") == (t["localised_after_s"] is None)
    with (tmp_path / "path.csv").open(newline="") as fh:
        path_rows = list(csv.DictReader(fh))
    assert tuple(path_rows[0].keys()) == PATH_COLUMNS
    assert len(path_rows) == len(flight.track)
    times = [float(r["t_unix"]) for r in path_rows]
    assert times == sorted(times)
