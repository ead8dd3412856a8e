"""SVG screenshots of the main screen at 120x40 and 80x24, saved into the test's tmp dir
and read back: the right size, every panel present, the keys listed, the numbers shown,
nothing cut that an operator needs."""

from __future__ import annotations

import re

import pytest

from mexgen_gcs.ui.app import build_app
from tests.ui.ui_helpers import FakeSource, make_snapshot, screen_text, svg_rows, until


@pytest.mark.parametrize("size", [(120, 40), (80, 24)])
async def test_main_screen_screenshot(tmp_path, size):
    width, height = size
    source = FakeSource()
    app = build_app(source)
    snap = make_snapshot(warnings=("RADIO SILENT",))
    async with app.run_test(size=size) as pilot:
        source.push(snap)
        await until(pilot, lambda: app.snapshot is snap)
        # the panels render after the snapshot lands (later on a loaded machine): wait for
        # the last of them, the event log's newest line and the tag table's last row
        await until(pilot, lambda: "tag_localised" in screen_text(app)
                    and "150.460" in screen_text(app))
        await pilot.pause()
        path = app.save_screenshot(f"main-{width}x{height}.svg", path=str(tmp_path))
    svg = (tmp_path / f"main-{width}x{height}.svg").read_text(encoding="utf-8")
    assert path.endswith(".svg") and svg.startswith("<svg")
    rows = svg_rows(svg, width, height)
    # the size: text drawn on the last terminal row and none below it (a row of blanks
    # draws no text, so rows are not counted), nothing drawn past the last column
    drawn_rows = {int(n) for n in re.findall(r"line-(\d+)\)", svg)}
    assert max(drawn_rows) == height - 1 and min(drawn_rows) == 0
    assert all(len(r) == width for r in rows)
    text = "\n".join(rows)
    # the warning on top, the status right under it
    assert "⚠ RADIO SILENT" in "\n".join(rows[:3])
    status = "\n".join(rows[1:5])
    for s in ("LINK OK", "OFFBOARD", "alt 49.6 m", "bat 87%", "radio 0.4s", "SEARCHING"):
        assert s in status, (s, status)
    # map, planner, tags, events
    assert "Map" in text and "H" in text and "◉T1✓" in text and "N↑" in text
    assert "heading 135° SE" in text and "0.52 ◀" in text and "pruned" in text
    for s in ("Tag", "MHz", "P(exist)", "Localised", "150.460", "yes @312s", "-47.3"):
        assert s in text, s
    assert "tag_localised tag=T1" in text
    # the footer lists the command keys
    footer = rows[-1]
    for key, label in (("p", "Pause"), ("c", "Resume"), ("r", "RTL"), ("l", "Land"),
                       ("a", "Abort"), ("m", "Method"), ("q", "Quit")):
        assert f"{key} {label}" in footer, (key, footer)
    # the map has room to be read
    map_rows = [r for r in rows if r.startswith("│") or r.startswith("╭")]
    assert len(map_rows) >= (9 if height < 30 else 20)
