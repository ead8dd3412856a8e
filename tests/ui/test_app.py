"""The app over a fake snapshot stream, driven by Textual's pilot: the panels show the
snapshot's numbers, the keys send the commands (dangerous ones only after confirmation),
quitting while flying asks for RTL and waits for the landing, warnings cannot be missed."""

from __future__ import annotations

import re

import pytest

from mexgen_gcs.ui.app import build_app
from mexgen_gcs.ui.confirm_screen import ConfirmScreen
from mexgen_gcs.ui.map_view import MapView
from mexgen_gcs.ui.method_screen import MethodScreen
from mexgen_gcs.ui.tags_table import TagsTable
from mexgen_gcs.ui.warning_banner import WarningBanner
from tests.ui.ui_helpers import FakeSource, later, make_snapshot, screen_rows, screen_text, until

SIZE = (120, 40)


async def started(size=SIZE, **snap_kw):
    source = FakeSource()
    app = build_app(source)
    return source, app, make_snapshot(**snap_kw)


async def test_panels_render_the_snapshot_numbers():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.pause()
        text = screen_text(app)
    # status bar
    for s in ("LINK OK", "OFFBOARD", "ARMED IN AIR", "alt 49.6 m", "10.0 m/s", "bat 87%",
              "radio 0.4s", "SEARCHING", "T+6:40", "mexgen"):
        assert s in text, s
    # planner: method, target, chosen heading, rewards, pruned heading, timings, next re-plan
    for s in ("target T2", "heading 135° SE", "0.52 ◀", "0.412", "pruned", "pred 12",
              "meas 31", "= 57", "next re-plan in 3.2 s"):
        assert s in text, s
    # tags table: frequency, existence, lat/lon, radius, detections, RSSI, localised when
    for s in ("150.100", "0.97", "-34.91579", "138.59780", "-47.3", "yes @312s"):
        assert s in text, s
    # map: home, localised tag mark, unlocalised tag labels, the vehicle heading arrow
    for s in ("H", "◉T1✓", "+T2", "+T3", "+T4", "↘", "N↑"):
        assert s in text, s
    assert re.search(r"├─+┤ \d+ m", text)  # scale bar
    # event log
    assert "tag_localised tag=T1" in text


async def test_pause_and_resume_are_sent_at_once():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("p")
        await pilot.press("c")
        await pilot.pause()
    assert source.sent == ["pause", "resume"]


@pytest.mark.parametrize(("key", "cmd"), [("r", "rtl"), ("l", "land"), ("a", "abort")])
async def test_dangerous_commands_need_confirmation(key, cmd):
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press(key)
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        assert source.sent == []  # the key alone sends nothing
        await pilot.press("n")  # cancel
        await until(pilot, lambda: not isinstance(app.screen, ConfirmScreen))
        assert source.sent == []
        await pilot.press(key)
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        await pilot.press("y")
        await until(pilot, lambda: source.sent == [cmd])
        assert not isinstance(app.screen, ConfirmScreen)


async def test_confirm_by_clicking_the_button():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("r")
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        await pilot.click("#confirm-yes")
        await until(pilot, lambda: source.sent == ["rtl"])


async def test_switch_planner_method_in_flight():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("m")
        await until(pilot, lambda: isinstance(app.screen, MethodScreen))
        await pilot.press("down", "down", "enter")  # mexgen -> pim -> mc
        await until(pilot, lambda: source.sent == ["method:mc"])
        await pilot.press("m")
        await until(pilot, lambda: isinstance(app.screen, MethodScreen))
        await pilot.press("2")
        await until(pilot, lambda: source.sent == ["method:mc", "method:pim"])
        await pilot.press("m")
        await until(pilot, lambda: isinstance(app.screen, MethodScreen))
        await pilot.press("escape")
        await until(pilot, lambda: not isinstance(app.screen, MethodScreen))
    assert source.sent == ["method:mc", "method:pim"]


async def test_quit_while_flying_commands_rtl_and_waits_for_the_landing():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("q")
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        assert source.sent == []
        await pilot.press("y")
        await until(pilot, lambda: source.sent == ["rtl"])
        assert app.is_running and app.quit_requested
        returning = later(snap, 5.0, state="returning", end_reason="operator_rtl")
        source.push(returning)
        await until(pilot, lambda: app.snapshot is returning)
        assert "the UI closes once landed" in screen_text(app)
        await pilot.press("r")  # mission commands are off while leaving
        await pilot.pause()
        assert not isinstance(app.screen, ConfirmScreen)
        source.push(make_snapshot(t=snap.t + 60.0, state="done", end_reason="operator_rtl",
                                  armed=False))
        source.push(None)  # the mission is over
        await until(pilot, lambda: not app.is_running)
    assert source.sent == ["rtl"]


async def test_quit_before_arming_aborts():
    source, app, snap = await started(state="preflight", armed=False)
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("q")
        await until(pilot, lambda: isinstance(app.screen, ConfirmScreen))
        await pilot.press("y")
        await until(pilot, lambda: source.sent == ["abort"])


async def test_mission_end_is_shown_then_any_key_closes():
    source, app, _snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(make_snapshot(state="done", end_reason="all_localised", armed=False))
        source.push(None)
        await until(pilot, lambda: app.ended)
        await pilot.pause()
        assert "MISSION ENDED: all_localised" in screen_text(app)
        await pilot.press("x")
        await until(pilot, lambda: not app.is_running)


async def test_mission_end_closes_by_itself_after_the_linger():
    source = FakeSource()
    app = build_app(source, linger_s=0.3)
    async with app.run_test(size=SIZE) as pilot:
        source.push(make_snapshot(state="done", end_reason="max_mission_time"))
        source.push(None)
        await until(pilot, lambda: not app.is_running)


async def test_warnings_are_impossible_to_miss():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        banner = app.query_one(WarningBanner)
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        assert not banner.display
        bad = later(snap, 1.0, warnings=("VEHICLE LINK LOST", "RADIO SILENT", "BATTERY 31%"))
        source.push(bad)
        await until(pilot, lambda: app.snapshot is bad)
        await pilot.pause()
        assert banner.display and banner.has_class("-warning")
        rows = screen_rows(app)
        top = "\n".join(rows[:4])
        assert "⚠ VEHICLE LINK LOST" in top and "⚠ RADIO SILENT" in top and "BATTERY 31%" in top
        assert "LINK LOST" in rows[3] or "LINK LOST" in "\n".join(rows[3:5])  # status bar
        assert banner.region.width == SIZE[0] and banner.region.height >= 3
        good = later(snap, 2.0)
        source.push(good)
        await until(pilot, lambda: app.snapshot is good)
        await pilot.pause()
        assert not banner.display


async def test_truth_toggle_zoom_and_pan():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.pause()
        map_view = app.query_one(MapView)
        assert "×" not in screen_text(app)
        await pilot.press("t")
        await pilot.pause()
        assert map_view.show_truth and "×" in screen_text(app)
        before = map_view.viewport()
        await pilot.press("plus")
        assert map_view.viewport().m_per_dot == pytest.approx(before.m_per_dot / 1.5)
        await pilot.press("right", "up")
        after = map_view.viewport()
        assert after.centre_e_m > before.centre_e_m and after.centre_n_m > before.centre_n_m
        await pilot.press("0")
        assert map_view.viewport() == before
        await pilot.press("f")  # centre on the first tag
        assert map_view.viewport().centre_e_m == pytest.approx(snap.tags[0].east_m)


async def test_truth_key_is_off_without_truth():
    source, app, snap = await started(truth=False)
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.press("t")
        await pilot.pause()
        assert not app.query_one(MapView).show_truth


async def test_clicking_a_tag_row_centres_the_map_on_it():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        await pilot.pause()
        table = app.query_one(TagsTable)
        map_view = app.query_one(MapView)
        await pilot.click(TagsTable, offset=(3, 3))  # header, T1, T2, T3 -> row T3
        await pilot.click(TagsTable, offset=(3, 3))
        await pilot.pause()
        assert table.cursor_row == 2
        assert map_view.viewport().centre_e_m == pytest.approx(snap.tags[2].east_m)
        assert map_view.viewport().centre_n_m == pytest.approx(snap.tags[2].north_m)


async def test_events_are_appended_once():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        more = later(snap, 1.0, events=(*snap.events[1:], "  320.0s safety action=hold"))
        source.push(more)
        await until(pilot, lambda: app.snapshot is more)
        await pilot.pause()
        text = screen_text(app)
    assert text.count("offboard_started") == 1
    assert "safety action=hold" in text


async def test_mission_commands_are_off_once_returning():
    source, app, snap = await started()
    async with app.run_test(size=SIZE) as pilot:
        returning = later(snap, 1.0, state="returning", end_reason="battery_low")
        source.push(returning)
        await until(pilot, lambda: app.snapshot is returning)
        await pilot.pause()
        await pilot.press("p", "c", "r", "l", "a", "m")
        await pilot.pause()
        assert source.sent == [] and len(app.screen_stack) == 1
