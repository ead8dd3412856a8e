"""Loading mission files: the examples load, and every kind of mistake gives a message that
names the file, the line, the key path, what was found and what is expected."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from mexgen_gcs.config import (
    Mission,
    MissionFileError,
    dump_resolved,
    load_mission,
    parse_mission,
)
from mexgen_gcs.config.loader import format_key_path
from mexgen_gcs.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
MISSIONS = REPO / "missions"
DEMO_TEXT = (MISSIONS / "demo.yaml").read_text(encoding="utf-8")
EXAMPLES = ["demo.yaml", "follow_cv.yaml", "localise_cv_ift.yaml", "localise_mismatch.yaml"]


def line_of(text: str, needle: str) -> int:
    """1-based line of the first line containing needle."""
    for n, line in enumerate(text.splitlines(), start=1):
        if needle in line:
            return n
    raise AssertionError(f"{needle!r} not in text")


def load_text(tmp_path: Path, text: str, name: str = "bad.yaml") -> ConfigError:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_mission(path)
    return info.value


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_missions_load(name: str) -> None:
    mission = load_mission(MISSIONS / name)
    assert isinstance(mission, Mission)
    assert mission.source_path == str(MISSIONS / name)
    assert mission.source_text == (MISSIONS / name).read_text(encoding="utf-8")
    assert mission.search_area().contains(mission.search_area().centre_m)


def test_example_missions_say_what_the_brief_asks() -> None:
    demo = load_mission(MISSIONS / "demo.yaml")
    assert demo.kind == "localise" and demo.tag_ids == ("T1", "T2", "T3", "T4")
    assert demo.sim.faults == ()
    follow = load_mission(MISSIONS / "follow_cv.yaml")
    assert follow.kind == "follow" and follow.follow is not None and follow.follow.tag == "T1"
    assert follow.search_area().bounds == (-2000.0, 2000.0, -2000.0, 2000.0)
    assert follow.filter.motion == "cv"
    assert (follow.planner.lookahead_s, follow.planner.replan_interval_s) == (10.0, 5.0)
    assert follow.sim_tag("T1").motion == "cv" and follow.sim_tag("T1").speed_m_s == (5.0, 6.0)
    cv_ift = load_mission(MISSIONS / "localise_cv_ift.yaml")
    mismatch = load_mission(MISSIONS / "localise_mismatch.yaml")
    for m in (cv_ift, mismatch):
        w, e, s, n = m.search_area().bounds
        assert (e - w, n - s) == (1000.0, 1000.0)
        assert len(m.tags) == 4
        assert all(m.sim_tag(t).motion == "cv-ift" for t in m.tag_ids)
        assert all(m.sim_tag(t).speed_m_s == (2.5, 3.0) for t in m.tag_ids)
    assert cv_ift.filter.motion == "cv-ift" and mismatch.filter.motion == "cv-mismatch"


def test_defaults_fill_every_optional_section() -> None:
    minimal = """
version: 1
name: minimal
kind: localise
home: {lat_deg: -34.9212, lon_deg: 138.6011}
area:
  rectangle_m: {west_m: -500, east_m: 500, south_m: -100, north_m: 900}
tags:
  - {id: T1, freq_hz: 150100000}
"""
    m = parse_mission(minimal, "minimal.yaml")
    assert m.flight.alt_m == 50.0 and m.flight.speed_m_s == 10.0
    assert m.receiver.listen == "udp://0.0.0.0:14600"
    assert m.receiver.allowed_sources == ("127.0.0.1/32",)
    assert m.filter.n_particles == 2000 and m.planner.samples == 512
    assert m.safety.home_max_distance_m == 500.0 and m.sim.seed == 7
    assert m.follow is None and m.home.alt_m is None


def test_demo_matches_the_documented_defaults() -> None:
    """demo.yaml writes every default out; the schema's defaults must agree with it."""
    demo = load_mission(MISSIONS / "demo.yaml")
    bare = Mission.model_validate({k: dump_resolved(demo)[k]
                                   for k in ("version", "name", "kind", "home", "area", "tags")})
    for section in ("flight", "radio", "receiver", "planner", "localisation", "safety"):
        assert getattr(bare, section) == getattr(demo, section), section
    # the filter defaults differ only in what demo leaves out (speed_min_m_s)
    assert bare.filter == demo.filter


def test_resolved_dump_loads_back_as_yaml() -> None:
    for name in EXAMPLES:
        m = load_mission(MISSIONS / name)
        dumped = dump_resolved(m)
        again = parse_mission(yaml.safe_dump(dumped, sort_keys=False), "resolved.yaml")
        assert dump_resolved(again) == dumped


def test_polygon_area_loads_and_converts() -> None:
    text = DEMO_TEXT.replace(
        "  rectangle_m: {west_m: -500, east_m: 500, south_m: -100, north_m: 900}",
        "  polygon_deg: [[-34.9222, 138.5956], [-34.9222, 138.6066], [-34.9130, 138.6066],"
        " [-34.9130, 138.5956]]",
    )
    m = parse_mission(text, "poly.yaml")
    w, e, s, n = m.search_area().bounds
    assert -510 < w < -490 and 490 < e < 510 and -120 < s < -100 and 900 < n < 920


# -- mistakes --------------------------------------------------------------------------------

BAD_CASES = [
    # (name, old, new, key path, expected fragments)
    ("unknown_key", "  speed_m_s: 10.0", "  sped_m_s: 10.0", "flight.sped_m_s",
     ["unknown key 'sped_m_s'", "did you mean 'speed_m_s'"]),
    ("unit_missing", "  speed_m_s: 10.0", "  speed: 10.0", "flight.speed",
     ["unknown key 'speed'", "did you mean 'speed_m_s'"]),
    ("wrong_type", "  alt_m: 50.0  ", "  alt_m: fifty  ", "flight.alt_m",
     ["expected a valid number", "found 'fifty'"]),
    ("bool_number", "  alt_m: 50.0  ", "  alt_m: true  ", "flight.alt_m",
     ["expected a valid number", "found True"]),
    ("quoted_number", "  speed_m_s: 10.0", "  speed_m_s: '10'", "flight.speed_m_s",
     ["expected a valid number", "found '10'"]),
    ("bad_enum", "  method: mexgen ", "  method: mexgn ", "planner.method",
     ["expected 'mexgen', 'pim' or 'mc'", "found 'mexgn'", "did you mean 'mexgen'"]),
    ("yaml_bool_enum", "on_link_regained: resume", "on_link_regained: no",
     "safety.on_link_regained", ["expected 'resume' or 'rtl'", "quote the value"]),
    ("out_of_range", "  pd_max: 0.95", "  pd_max: 1.5", "radio.pd_max",
     ["less than or equal to 1", "found 1.5"]),
    ("negative_speed", "  speed_m_s: 10.0", "  speed_m_s: -3", "flight.speed_m_s",
     ["greater than 0", "found -3"]),
    ("int_with_point", "freq_hz: 150100000}", "freq_hz: 150100000.0}", "tags[0].freq_hz",
     ["expected a valid integer", "without a decimal point"]),
    ("exponent_text", "  speed_m_s: 10.0", "  speed_m_s: 1e1", "flight.speed_m_s",
     ["YAML reads this as text"]),
    ("nan", "  noise_std_db: 2.5", "  noise_std_db: .nan", "radio.noise_std_db",
     ["finite number"]),
    ("duplicate_tag", "{id: T2, freq_hz", "{id: T1, freq_hz", "tags[1].id",
     ["duplicate tag id 'T1'", "tags[0]"]),
    ("close_freqs", "150220000", "150108000", "tags[1].freq_hz",
     ["2 x receiver.freq_tolerance_hz", "further apart"]),
    ("sim_tag_unknown", "{id: T4, position_m", "{id: T9, position_m", "sim.tags[3].id",
     ["'T9' is not a mission tag", "expected one of T1, T2, T3, T4"]),
    ("sim_position_outside", "[350.0, 250.0]", "[3500.0, 250.0]", "sim.tags[3].position_m",
     ["outside the search area", "east -500..500 m"]),
    ("bad_tag_id", "{id: T3,", "{id: 'T 3',", "tags[2].id",
     ["expected a tag id: 1-32 letters", "found 'T 3'"]),
    ("bad_cidr", "127.0.0.1/32", "10.0.0.1/8", "receiver.allowed_sources[0]",
     ["has host bits set", "did you mean 10.0.0.0/8"]),
    ("bad_url", "udp://0.0.0.0:14600", "tcp://0.0.0.0:14600", "receiver.listen",
     ["expected udp://HOST:PORT"]),
    ("bad_port", "udp://0.0.0.0:14600", "udp://0.0.0.0:99999", "receiver.listen",
     ["0..65535"]),
    ("rectangle_order", "west_m: -500, east_m: 500", "west_m: 500, east_m: -500",
     "area.rectangle_m.east_m", ["expected east_m > west_m"]),
    ("home_far", "south_m: -100, north_m: 900", "south_m: 800, north_m: 900", "home",
     ["800 m outside the search area", "safety.home_max_distance_m = 500"]),
    ("bad_version", "version: 1", "version: 2", "version", ["expected 1", "found 2"]),
    ("bool_version", "version: 1", "version: true", "version", ["expected 1", "found True"]),
    ("float_version", "version: 1", "version: 1.0", "version", ["expected 1", "found 1.0"]),
    ("step_too_long", "  step_s: 1.0", "  step_s: 30.0", "planner.step_s",
     ["expected step_s <= lookahead_s"]),
    ("alpha_one", "  alpha: 0.1", "  alpha: 1.0", "planner.alpha", ["expected alpha != 1"]),
    ("bad_fault_kind", "  faults: []", "  faults:\n    - {kind: link_dorp, at_s: 3.0}",
     "sim.faults[0].kind", ["expected one of link_drop", "did you mean 'link_drop'"]),
    ("fault_unknown_key", "  faults: []",
     "  faults:\n    - {kind: link_drop, at_s: 3.0, duration_s: 1.0, length_s: 2}",
     "sim.faults[0].length_s", ["unknown key 'length_s'", "at_s, kind, duration_s"]),
    ("fault_missing_field", "  faults: []", "  faults:\n    - {kind: battery_sag, at_s: 3.0}",
     "sim.faults[0].percent", ["missing required key 'percent'"]),
    ("sim_speed_range", "motion: static}", "motion: cv, speed_m_s: [6, 5]}",
     "sim.tags[0].speed_m_s", ["[min, max]", "found [6, 5]"]),
    ("both_areas", "area:                          # exactly one",
     "area:\n  polygon_deg: [[1.0, 2.0], [1.0, 2.1], [1.1, 2.0]]\n  #", "area",
     ["expected exactly one of rectangle_m, polygon_deg or from; found both"]),
]


@pytest.mark.parametrize(("name", "old", "new", "key", "fragments"), BAD_CASES,
                         ids=[c[0] for c in BAD_CASES])
def test_bad_missions_name_file_line_key_and_fix(
    tmp_path: Path, name: str, old: str, new: str, key: str, fragments: list[str]
) -> None:
    assert old in DEMO_TEXT, f"test case {name}: {old!r} not in demo.yaml"
    text = DEMO_TEXT.replace(old, new, 1)
    err = load_text(tmp_path, text, f"{name}.yaml")
    assert isinstance(err, MissionFileError)
    message = str(err)
    problem = next((p for p in err.problems if format_key_path(p.path) == key), None)
    assert problem is not None, f"no problem at {key}: {message}"
    line = problem.line
    assert line is not None
    assert f"{name}.yaml:{line}: {key}: " in message
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message}"
    # the reported line holds the key (or, for a missing key, its parent)
    leaf = str(problem.path[-1]) if problem.path and isinstance(problem.path[-1], str) else None
    if leaf and name not in ("fault_missing_field",):
        assert leaf in text.splitlines()[line - 1] or "-" in text.splitlines()[line - 1]


def test_missing_required_key_names_parent_line(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("home: {lat_deg: -34.9212, ", "home: {")
    err = load_text(tmp_path, text)
    assert f"bad.yaml:{line_of(text, 'home:')}: home.lat_deg: missing required key 'lat_deg'" \
        in str(err)


def test_missing_top_level_key(tmp_path: Path) -> None:
    err = load_text(tmp_path, DEMO_TEXT.replace("name: demo\n", ""))
    assert "name: missing required key 'name'" in str(err)


def test_follow_without_follow_section(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("kind: localise ", "kind: follow ")
    message = str(load_text(tmp_path, text))
    assert "follow: kind is 'follow', so a follow section is required" in message
    assert "tags: a follow mission has exactly the followed tag; found 4 tags" in message


def test_follow_tag_must_exist(tmp_path: Path) -> None:
    text = (MISSIONS / "follow_cv.yaml").read_text(encoding="utf-8").replace("  tag: T1",
                                                                               "  tag: T7")
    message = str(load_text(tmp_path, text))
    assert f"bad.yaml:{line_of(text, 'tag: T7')}: follow.tag: unknown tag 'T7'" in message


def test_all_problems_reported_sorted_by_line(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("  speed_m_s: 10.0", "  speed_m_s: fast").replace(
        "  method: mexgen ", "  method: nope ")
    err = load_text(tmp_path, text)
    assert isinstance(err, MissionFileError)
    assert [format_key_path(p.path) for p in err.problems] == ["flight.speed_m_s",
                                                               "planner.method"]
    assert "(2 problems)" in str(err)


def test_duplicate_yaml_key(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("  speed_m_s: 10.0", "  speed_m_s: 10.0\n  speed_m_s: 11.0")
    message = str(load_text(tmp_path, text))
    first = line_of(text, "speed_m_s: 10.0")
    assert f"bad.yaml:{first + 1}: flight.speed_m_s: duplicate key (first at line {first})" \
        in message


def test_yaml_syntax_error_has_line(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("  p0_db: -7.0", "  p0_db: [-7.0")
    message = str(load_text(tmp_path, text))
    assert re.search(r"bad\.yaml:\d+:\d+: not valid YAML", message), message


def test_tabs_are_explained(tmp_path: Path) -> None:
    text = DEMO_TEXT.replace("  alt_m: 50.0", "\talt_m: 50.0")
    message = str(load_text(tmp_path, text))
    assert f"bad.yaml:{line_of(text, chr(9))}:" in message and "tabs" in message


@pytest.mark.parametrize(("text", "fragment"), [
    ("", "the file is empty"),
    ("# only a comment\n", "the file is empty"),
    ("- a\n- b\n", "expected a mapping of keys"),
    ("just text\n", "expected a mapping of keys"),
])
def test_not_a_mission(tmp_path: Path, text: str, fragment: str) -> None:
    message = str(load_text(tmp_path, text, "odd.yaml"))
    assert "odd.yaml" in message and fragment in message


def test_missing_file_directory_and_binary(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.yaml: no such mission file"):
        load_mission(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="is a directory"):
        load_mission(tmp_path)
    binary = tmp_path / "blob.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ConfigError, match=r"blob\.yaml: not a text file"):
        load_mission(binary)


def test_mission_is_frozen() -> None:
    m = load_mission(MISSIONS / "demo.yaml")
    with pytest.raises(ValueError, match="frozen"):
        m.flight.speed_m_s = 3.0  # type: ignore[misc]
