"""Mission helpers: the core objects built from a mission, warnings and the description."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mexgen_gcs.config import (
    describe,
    dump_resolved,
    load_mission,
    mission_warnings,
    parse_mission,
)
from mexgen_gcs.config.sim_schema import SimTag
from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.bernoulli import FilterConfig
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
MISSIONS = REPO / "missions"
DEMO_TEXT = (MISSIONS / "demo.yaml").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def demo():
    return load_mission(MISSIONS / "demo.yaml")


def test_core_objects(demo) -> None:
    assert demo.radio_model() == RadioModel()  # demo uses the paper's defaults
    area = demo.search_area()
    assert isinstance(area, SearchArea)
    assert area.bounds == (-500.0, 500.0, -100.0, 900.0)
    motion = demo.filter_motion_model()
    assert motion == make_motion_model("rw", rw_std_m_per_sqrt_s=0.5)
    cfg = demo.filter_config()
    assert isinstance(cfg, FilterConfig)
    assert (cfg.n_particles, cfg.localised_radius_m, cfg.localised_confidence) == (2000, 50.0,
                                                                                   0.95)


def test_local_frame_is_anchored_at_home(demo) -> None:
    frame = demo.local_frame()
    e, n, u = frame.to_enu(demo.home.lat_deg, demo.home.lon_deg, demo.home.alt_m)
    assert abs(float(e)) < 1e-6 and abs(float(n)) < 1e-6 and abs(float(u)) < 1e-6
    lat, lon, _ = frame.to_geodetic(0.0, 1000.0, 0.0)
    assert float(lat) > demo.home.lat_deg and abs(float(lon) - demo.home.lon_deg) < 1e-9


def test_polygon_area_round_trips_through_the_frame(demo) -> None:
    frame = demo.local_frame()
    corners_enu = np.array([[-400.0, -50.0], [450.0, -50.0], [300.0, 800.0], [-350.0, 700.0]])
    lat, lon, _ = frame.to_geodetic(corners_enu[:, 0], corners_enu[:, 1], 0.0)
    poly = ", ".join(f"[{a:.9f}, {b:.9f}]" for a, b in zip(lat, lon, strict=True))
    text = DEMO_TEXT.replace(
        "  rectangle_m: {west_m: -500, east_m: 500, south_m: -100, north_m: 900}",
        f"  polygon_deg: [{poly}]")
    m = parse_mission(text, "poly.yaml")
    np.testing.assert_allclose(m.search_area().vertices_m, corners_enu, atol=0.05)


def test_self_crossing_polygon_is_rejected(demo) -> None:
    frame = demo.local_frame()
    bow = np.array([[-400.0, -50.0], [400.0, 800.0], [400.0, -50.0], [-400.0, 800.0]])
    lat, lon, _ = frame.to_geodetic(bow[:, 0], bow[:, 1], 0.0)
    poly = ", ".join(f"[{a:.9f}, {b:.9f}]" for a, b in zip(lat, lon, strict=True))
    text = DEMO_TEXT.replace(
        "  rectangle_m: {west_m: -500, east_m: 500, south_m: -100, north_m: 900}",
        f"  polygon_deg: [{poly}]")
    with pytest.raises(ConfigError, match=r"area\.polygon_deg: edges 0-1 and 2-3 cross"):
        parse_mission(text, "bow.yaml")


def test_tag_lookup_by_frequency(demo) -> None:
    assert demo.tag_ids == ("T1", "T2", "T3", "T4")
    assert demo.tag_for_frequency(150_100_000) == "T1"
    assert demo.tag_for_frequency(150_104_999) == "T1"
    assert demo.tag_for_frequency(150_095_000) == "T1"
    assert demo.tag_for_frequency(150_105_001) is None
    assert demo.tag_for_frequency(150_220_400) == "T2"
    assert demo.tag_for_frequency(1) is None
    assert demo.tag("T3").freq_hz == 150_340_000
    with pytest.raises(KeyError):
        demo.tag("T9")


def test_sim_tags_and_truth_models(demo) -> None:
    assert demo.sim_tag("T1").position_m == (-300.0, 600.0)
    m = load_mission(MISSIONS / "localise_cv_ift.yaml")
    rng = np.random.default_rng(1)
    model = m.sim_motion_model("T1", rng)
    assert model.n_modes == 3 and model.speed_max_m_s == 3.0
    state, _ = model.initial(np.zeros((500, 2)), rng)
    speed = np.hypot(state[:, 2], state[:, 3])
    assert speed.min() >= 2.5 and speed.max() <= 3.0
    # a mission tag without a sim entry is static at a random position
    minimal = DEMO_TEXT.replace("    - {id: T4, position_m: [350.0, 250.0], motion: static}\n", "")
    m2 = parse_mission(minimal, "m.yaml")
    assert m2.sim_tag("T4") == SimTag(id="T4")
    assert m2.sim_tag("T4").position_m is None and m2.sim_tag("T4").motion == "static"
    with pytest.raises(KeyError):
        m2.sim_tag("T9")
    # a single speed is the degenerate range
    single = DEMO_TEXT.replace("motion: static}", "motion: cv, speed_m_s: 4, heading_deg: 90}", 1)
    assert parse_mission(single, "s.yaml").sim_tag("T1").speed_m_s == (4.0, 4.0)


def test_warnings(demo) -> None:
    assert mission_warnings(demo) == [
        "flight.max_accel_m_s2 = 4: PX4's default MPC_ACC_HOR caps horizontal acceleration "
        "at 3 m/s^2; turns will take longer than the planner assumes"]
    fast = parse_mission(DEMO_TEXT.replace("speed_m_s: 10.0", "speed_m_s: 15.0"), "f.yaml")
    assert any("PX4's default MPC_XY_VEL_MAX caps horizontal speed at 12 m/s; the vehicle will "
               "fly slower than asked" in w for w in mission_warnings(fast))
    near = parse_mission(DEMO_TEXT.replace("south_m: -100", "south_m: 100").replace(
        "[-200.0, 150.0]", "[-200.0, 350.0]"), "n.yaml")
    assert any("home is 100 m outside the search area" in w for w in mission_warnings(near))
    for name in ("follow_cv.yaml", "localise_cv_ift.yaml", "localise_mismatch.yaml"):
        assert mission_warnings(load_mission(MISSIONS / name)) == [], name


def test_more_warnings() -> None:
    text = (DEMO_TEXT.replace("motion: rw ", "motion: static ")
            .replace("{id: T1, position_m: [-300.0, 600.0], motion: static}",
                     "{id: T1, position_m: [-300.0, 600.0], motion: cv, speed_m_s: 9}")
            .replace("    - {id: T4, position_m: [350.0, 250.0], motion: static}\n", "")
            .replace("  alt_m: 50.0 ", "  alt_m: 150.0 ")
            .replace('allowed_sources: ["127.0.0.1/32"]', "allowed_sources: []")
            .replace("freq_hz: 150460000", "freq_hz: 433920000"))
    warnings = "\n".join(mission_warnings(parse_mission(text, "w.yaml")))
    for fragment in ("moves (cv) but filter.motion is static", "faster than filter.speed_max",
                     "tags T4 have no sim.tags entry", "above 120 m",
                     "detections from any address", "433920000 is not a VHF frequency"):
        assert fragment in warnings


def test_describe_says_what_it_would_fly(demo) -> None:
    text = describe(demo)
    for fragment in ("Mission 'demo'", "localise, 4 tags", "1000 m east-west x 1000 m",
                     "SW -34.92", "50 m above home at 10 m/s", "T1 150.1000 MHz",
                     "MexGen, M = 512", "within 50 m", "seed 7", "T1: static from [-300, 600] m",
                     "udp://0.0.0.0:14600 from 127.0.0.1/32"):
        assert fragment in text, fragment
    follow = describe(load_mission(MISSIONS / "follow_cv.yaml"))
    assert "follow     T1 for 600 s" in follow and "cv at 5..6 m/s from random position" in follow


def test_dump_resolved_is_plain_data(demo) -> None:
    import json

    dumped = dump_resolved(demo)
    assert json.loads(json.dumps(dumped)) == dumped
    assert dumped["planner"]["method"] == "mexgen"
    assert dumped["filter"]["speed_min_m_s"] == 0.0  # defaults are filled in
    assert dumped["follow"] is None
