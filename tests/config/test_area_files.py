"""Areas from QGroundControl plans, KML and GeoJSON: the demo area round-trips through each
format (written by `mexgen-gcs export-plan`, read back by `area.from`), and bad files are refused
with a message naming the file, what was found and what is expected (exit 2 from `check`)."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs import cli
from mexgen_gcs.config import load_mission
from mexgen_gcs.config.area_files import (
    AreaFileError,
    read_area_file,
)
from mexgen_gcs.core.geo import LocalFrame

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "missions" / "demo.yaml"
HOME = (-34.9212, 138.6011)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """The command line in this process (the fast suite starts no Python process)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(REPO), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(list(args))
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())


def mission_from(tmp_path: Path, area_file: str) -> Path:
    """The demo mission with its area replaced by ``from: area_file`` (relative path)."""
    text = DEMO.read_text(encoding="utf-8")
    start = text.index("area:")
    end = text.index("flight:")
    path = tmp_path / "mission.yaml"
    path.write_text(text[:start] + f"area:\n  from: {area_file}\n" + text[end:], "utf-8")
    return path


def max_offset_m(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> float:
    frame = LocalFrame(*HOME, 0.0)
    pa, pb = np.asarray(a), np.asarray(b)
    ea, na, _ = frame.to_enu(pa[:, 0], pa[:, 1])
    eb, nb, _ = frame.to_enu(pb[:, 0], pb[:, 1])
    return float(np.max(np.hypot(ea - eb, na - nb)))


@pytest.mark.parametrize("suffix", [".plan", ".kml", ".geojson"])
def test_demo_area_round_trips(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"area{suffix}"
    proc = run_cli("export-plan", str(DEMO), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    demo = load_mission(DEMO)
    original = demo.area_polygon_deg()
    read = read_area_file(out, *HOME)
    assert len(read) == len(original) == 4
    assert max_offset_m(read, original) < 0.01  # 1 cm
    # and the mission flies it: same search area in its local frame
    mission = load_mission(mission_from(tmp_path, out.name))
    assert mission.area.from_file == out.name
    assert np.allclose(mission.search_area().vertices_m, demo.search_area().vertices_m,
                       atol=0.01)
    check = run_cli("check", str(mission_from(tmp_path, out.name)))
    assert check.returncode == 0, check.stderr
    assert f"(from {out.name})" in check.stdout


def test_plan_is_what_qgroundcontrol_reads(tmp_path: Path) -> None:
    out = tmp_path / "demo.plan"
    assert run_cli("export-plan", str(DEMO), "-o", str(out)).returncode == 0
    doc = json.loads(out.read_text())
    assert doc["fileType"] == "Plan" and doc["groundStation"] == "QGroundControl"
    assert doc["mission"]["plannedHomePosition"] == [-34.9212, 138.6011, 0.0]
    (poly,) = doc["geoFence"]["polygons"]
    assert poly["inclusion"] is True and len(poly["polygon"]) == 4
    assert all(-35.0 < lat < -34.9 and 138.5 < lon < 138.7 for lat, lon in poly["polygon"])


def test_fence_export_is_larger_than_the_area(tmp_path: Path) -> None:
    area, fence = tmp_path / "a.geojson", tmp_path / "f.geojson"
    assert run_cli("export-plan", str(DEMO), "-o", str(area)).returncode == 0
    assert run_cli("export-plan", str(DEMO), "--fence", "-o", str(fence)).returncode == 0
    frame = LocalFrame(*HOME, 0.0)
    a = np.asarray(read_area_file(area, *HOME))
    f = np.asarray(read_area_file(fence, *HOME))
    ea, _, _ = frame.to_enu(a[:, 0], a[:, 1])
    ef, _, _ = frame.to_enu(f[:, 0], f[:, 1])
    assert ef.max() == pytest.approx(ea.max() + 50.0, abs=0.5)  # geofence_margin_m = 50


def test_kml_with_namespace_prefix_and_altitudes(tmp_path: Path) -> None:
    path = tmp_path / "drawn.kml"
    path.write_text(
        '<?xml version="1.0"?><k:kml xmlns:k="http://www.opengis.net/kml/2.2"><k:Document>'
        "<k:Placemark><k:Polygon><k:outerBoundaryIs><k:LinearRing><k:coordinates>\n"
        "  138.600,-34.920,12 138.610,-34.920,12\n 138.610,-34.910,12 138.600,-34.910,12 "
        "138.600,-34.920,12\n</k:coordinates></k:LinearRing></k:outerBoundaryIs></k:Polygon>"
        "</k:Placemark></k:Document></k:kml>", "utf-8")
    assert read_area_file(path, *HOME) == [(-34.92, 138.6), (-34.92, 138.61), (-34.91, 138.61),
                                           (-34.91, 138.6)]


def test_geojson_feature_and_multipolygon(tmp_path: Path) -> None:
    ring = [[138.60, -34.92], [138.61, -34.92], [138.61, -34.91], [138.60, -34.92]]
    for doc in ({"type": "Feature", "properties": {}, "geometry": {
                    "type": "MultiPolygon", "coordinates": [[ring]]}},
                {"type": "FeatureCollection", "features": [
                    {"type": "Feature", "geometry": {"type": "Point", "coordinates": [0, 0]}},
                    {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}}]}):
        path = tmp_path / "a.geojson"
        path.write_text(json.dumps(doc), "utf-8")
        assert len(read_area_file(path, *HOME)) == 3


SQUARE = [[-34.92, 138.60], [-34.92, 138.61], [-34.91, 138.61], [-34.91, 138.60]]


def plan(polygons: list[dict[str, object]]) -> str:
    return json.dumps({"fileType": "Plan", "version": 1, "mission": {"items": []},
                       "geoFence": {"version": 2, "circles": [], "polygons": polygons}})


BAD_FILES = [
    # (name, content, fragments of the message)
    ("line.geojson", json.dumps({"type": "LineString", "coordinates": [[138.6, -34.92],
                                                                        [138.61, -34.91]]}),
     ["GeoJSON LineString", "expected a Polygon"]),
    ("bowtie.plan", plan([{"inclusion": True, "polygon": [SQUARE[0], SQUARE[2], SQUARE[1],
                                                          SQUARE[3]]}]),
     ["edges 0-1 and 2-3 cross", "expected a simple polygon"]),
    ("north.geojson", json.dumps({"type": "Polygon", "coordinates": [[
        [138.60, 34.92], [138.61, 34.92], [138.61, 34.91], [138.60, 34.92]]]}),
     ["other hemisphere from home", "expected an area around home"]),
    ("swapped.kml", '<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><Polygon>'
     "<outerBoundaryIs><LinearRing><coordinates>-34.92,138.60 -34.92,138.61 -34.91,138.61"
     "</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark></kml>",
     ["latitude 138.6", "expected [lon, lat]"]),
    ("far.geojson", json.dumps({"type": "Polygon", "coordinates": [[
        [139.60, -34.92], [139.61, -34.92], [139.61, -34.91], [139.60, -34.92]]]}),
     ["nearest vertex is 91 km from home", "expected an area within 50 km"]),
    ("exclusion.plan", plan([{"inclusion": False, "polygon": SQUARE}]),
     ["0 inclusion polygons", "expected exactly one"]),
    ("two.plan", plan([{"inclusion": True, "polygon": SQUARE}] * 2),
     ["2 inclusion polygons", "expected exactly one"]),
    ("mission.plan", json.dumps({"fileType": "Mission"}),
     ["fileType is 'Mission'", "expected a QGroundControl plan"]),
    ("broken.geojson", '{"type": "Polygon", ', ["not JSON", "expected a GeoJSON file"]),
    ("notes.kml", "just text", ["not XML", "expected a KML file"]),
    ("two_points.geojson", json.dumps({"type": "Polygon", "coordinates": [[
        [138.60, -34.92], [138.61, -34.92], [138.60, -34.92]]]}),
     ["2 distinct vertices", "at least 3"]),
    ("area.txt", "138.6,-34.92", ["unknown area file type '.txt'", "expected .plan"]),
]


@pytest.mark.parametrize(("name", "content", "fragments"), BAD_FILES,
                         ids=[b[0] for b in BAD_FILES])
def test_bad_area_files_are_refused(tmp_path: Path, name: str, content: str,
                                    fragments: list[str]) -> None:
    path = tmp_path / name
    path.write_text(content, "utf-8")
    with pytest.raises(AreaFileError) as info:
        read_area_file(path, *HOME)
    message = str(info.value)
    assert message.startswith(f"{path}:")
    for fragment in fragments:
        assert fragment in message


def test_check_refuses_a_bad_file_with_exit_2(tmp_path: Path) -> None:
    (tmp_path / "bowtie.plan").write_text(BAD_FILES[1][1], "utf-8")
    proc = run_cli("check", str(mission_from(tmp_path, "bowtie.plan")))
    assert proc.returncode == 2
    assert "area.from:" in proc.stderr and "bowtie.plan" in proc.stderr
    assert "cross" in proc.stderr and proc.stdout == ""


def test_missing_file_and_both_keys(tmp_path: Path) -> None:
    proc = run_cli("check", str(mission_from(tmp_path, "nowhere.kml")))
    assert proc.returncode == 2 and "no such area file" in proc.stderr
    text = mission_from(tmp_path, "a.kml").read_text().replace(
        "  from: a.kml\n", "  from: a.kml\n  rectangle_m: {west_m: 0, east_m: 1, south_m: 0, "
        "north_m: 1}\n")
    (tmp_path / "both.yaml").write_text(text, "utf-8")
    proc = run_cli("check", str(tmp_path / "both.yaml"))
    assert proc.returncode == 2
    assert "expected exactly one of rectangle_m, polygon_deg or from" in proc.stderr
