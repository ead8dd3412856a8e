"""The pure parts of the panels: the braille map and the text formatting (ENU metres)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mexgen_gcs.ui.format import (
    age_text,
    bar,
    clock_text,
    compass_name,
    new_events,
    reward_fractions,
)
from mexgen_gcs.ui.map_canvas import (
    DOTS_X,
    DOTS_Y,
    BrailleCanvas,
    MapScene,
    MapTag,
    Viewport,
    draw_map,
    ellipse_points,
    fit_viewport,
    heading_arrow,
    scale_bar,
)
from mexgen_gcs.ui.planner_panel import planner_text
from mexgen_gcs.ui.status_bar import status_text
from mexgen_gcs.ui.tags_table import tag_row


def test_braille_dots_set_the_right_bits():
    c = BrailleCanvas(2, 1)
    c.plot(np.array([0.5, 1.5, 0.5]), np.array([0.5, 3.5, 3.5]), "red")  # dots 1, 8, 7
    assert c.dots[0, 0] == 0x01 | 0x80 | 0x40
    row = c.rows()[0]
    assert row.plain == chr(0x2800 + 0xC1) + " "
    c.plot(np.array([-1.0, 100.0]), np.array([0.0, 0.0]), "red")  # off canvas: ignored
    assert c.dots[0, 1] == 0


@given(st.floats(-2000, 2000), st.floats(-2000, 2000), st.floats(1, 5000), st.floats(1, 5000),
       st.integers(10, 200), st.integers(5, 60))
def test_fitted_viewport_shows_every_point(e0, n0, w_m, h_m, wc, hc):
    pts = np.array([[e0, n0], [e0 + w_m, n0 + h_m]])
    view = fit_viewport(pts, wc, hc)
    col, row = view.to_dots(pts[:, 0], pts[:, 1], wc, hc)
    assert np.all((col >= 0) & (col <= wc * DOTS_X) & (row >= 0) & (row <= hc * DOTS_Y))


def test_viewport_zoom_and_pan_are_exact():
    v = Viewport(10.0, 20.0, 4.0)
    assert v.zoomed(2.0).m_per_dot == 2.0
    p = v.panned(5.0, -3.0)
    assert (p.centre_e_m, p.centre_n_m) == (15.0, 17.0)
    col, row = v.to_dots(np.array([10.0 + 8.0]), np.array([20.0 + 8.0]), 10, 5)
    assert col[0] == 10 + 2 and row[0] == 10 - 2  # east is right, north is up


def test_ellipse_is_the_95_percent_contour():
    pts = ellipse_points(100.0, -50.0, (400.0, 0.0, 100.0))  # sd 20 m east, 10 m north
    r_e = np.max(np.abs(pts[:, 0] - 100.0))
    r_n = np.max(np.abs(pts[:, 1] + 50.0))
    assert math.isclose(r_e, 20.0 * 2.4477, rel_tol=0.01)
    assert math.isclose(r_n, 10.0 * 2.4477, rel_tol=0.01)
    assert len(ellipse_points(0, 0, (math.nan, 0.0, 1.0))) == 0


def test_heading_arrows_and_compass_names():
    assert [heading_arrow(h) for h in (0, 44, 46, 90, 180, 270, 359)] == list("↑↗↗→↓←↑")
    assert [compass_name(h) for h in (0, 45, 90, 135, 180, 225, 270, 315, 350)] == [
        "N", "NE", "E", "SE", "S", "SW", "W", "NW", "N"]


def test_scale_bar_is_a_round_length_that_fits():
    label, cells = scale_bar(m_per_dot=5.0, width_cells=80)  # 200 m fits in 20 cells
    assert label == "200 m" and cells == 20
    assert scale_bar(100.0, 80)[0] == "2 km"


def test_map_draws_every_layer_in_place():
    scene = MapScene(
        area_en_m=((-100.0, -100.0), (100.0, -100.0), (100.0, 100.0), (-100.0, 100.0)),
        vehicle_en_m=(50.0, 0.0), vehicle_yaw_deg=90.0,
        tags=(MapTag("A", -50.0, 50.0, (25.0, 0.0, 25.0), 0.9, True, ((-50.0, 50.0),),
                     (-40.0, 40.0)),),
        heading_deg=90.0)
    view = Viewport(0.0, 0.0, 2.0)  # 60 x 30 cells = 240 m x 240 m
    rows = [r.plain for r in draw_map(scene, view, 60, 30, show_truth=True)]
    assert len(rows) == 30 and all(len(r) == 60 for r in rows)
    # home H at the centre cell, vehicle arrow 50 m east = 25 dots = 12 cells right
    assert rows[15][30] == "H"
    assert rows[15][42] == "→"
    assert "◉A✓" in rows[15 - 7]  # 50 m north = 25 dots = 6.25 -> row 8
    assert "×" in "".join(rows)
    assert rows[0].endswith("N↑ ")
    hidden = [r.plain for r in draw_map(scene, view, 60, 30, show_truth=False)]
    assert "×" not in "".join(hidden)


def test_new_events_finds_the_overlap():
    assert new_events([], ["a", "b"]) == ["a", "b"]
    assert new_events(["a", "b", "c"], ["b", "c", "d", "e"]) == ["d", "e"]
    assert new_events(["a", "b"], ["a", "b"]) == []
    assert new_events(["x"], ["y"]) == ["y"]


def test_reward_bars():
    f = reward_fractions([1.0, 3.0, -math.inf, 2.0])
    assert f[1] == 1.0 and f[2] is None and 0 < f[0] < f[3] < 1.0
    assert reward_fractions([-math.inf] * 8) == [None] * 8
    assert bar(1.0, 5) == "█████" and bar(0.0, 5) == "     " and len(bar(0.33, 7)) == 7


def test_text_formats():
    assert clock_text(3725) == "1:02:05" and clock_text(65) == "1:05"
    assert age_text(math.inf) == "never" and age_text(0.42) == "0.4s" and age_text(30) == "30s"


def test_panel_texts(snapshot):
    s = status_text(snapshot, width=60).plain
    assert all(len(line) <= 60 for line in s.splitlines()) and len(s.splitlines()) >= 2
    assert "alt 49.6 m" in s and "bat 87%" in s  # whole items, never split
    p = planner_text(snapshot.plan, "pim", 40, snapshot.next_plan_in_s).plain
    assert "→ pim" in p  # switching method shows until the next plan
    assert "pruned" in p and "◀" in p
    assert "next re-plan in 3.2 s" in p
    assert planner_text(None, "mexgen", 40, 0.0).plain.startswith("mexgen  no plan yet")
    cells = [c.plain for c in tag_row(snapshot.tags[2])]
    assert cells[0] == "T3" and cells[6] == "0" and cells[7] == "--" and cells[8] == "no"


def test_planner_panel_with_altitude_actions(snapshot):
    """16 actions (8 headings at 50 m and 20 m): one row per heading with its best altitude,
    and the altitude flown to beside the heading."""
    plan = snapshot.plan.model_copy(update={
        "headings_deg": [45.0 * i for i in range(8)] * 2,
        "rewards": [1.0] * 8 + [2.0, 0.5, None, 1.5, 0.2, 0.1, 0.1, 0.1],
        "alts_m": [50.0] * 8 + [20.0] * 8, "chosen_heading_deg": 0.0, "chosen_alt_m": 20.0})
    lines = planner_text(plan, plan.method, 48, 1.0).plain.splitlines()
    assert "000° N  alt 20 m" in lines[1]
    rows = lines[2:10]
    assert len(rows) == 8 and sum("◀" in r for r in rows) == 1 and "◀" in rows[0]
    assert "@20" in rows[0] and "@50" in rows[1] and "@50" in rows[2] and "@20" in rows[3]
    assert "pruned" not in rows[2]  # 90 deg pruned at 20 m, flyable at 50 m


def test_tags_table_says_why_a_tag_was_reported(snapshot):
    from dataclasses import replace

    from mexgen_gcs.ui.tags_table import COLUMNS

    tag = snapshot.tags[2]
    col = COLUMNS.index("Reported")
    assert tag_row(tag)[col].plain == "-"
    cell = tag_row(replace(tag, reported="stalled"))[col]
    assert cell.plain == "stalled" and "yellow" in str(cell.style)
    assert tag_row(replace(tag, reported="reached"))[col].plain == "reached"
