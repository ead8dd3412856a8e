"""The report's document model renders the same content as Markdown and escaped HTML; the
command line's LAT,LON parser names what is wrong."""

from __future__ import annotations

import math

import pytest

from mexgen_gcs.analysis.cli import parse_lat_lon
from mexgen_gcs.analysis.document import Document, fmt


def test_markdown_and_html_say_the_same() -> None:
    doc = Document("Report <1>")
    sec = doc.section("Tags & more")
    sec.table(("tag", "value"), [("T|1", "1.0"), ("<b>", "–")])
    sec.para("a & b")
    sec.bullets(["one", "two"])
    sec.code("radio:\n  p0_db: -7\n")
    sec.image("path.png", "Flight path")
    md = doc.markdown()
    assert md.startswith("# Report <1>\n") and "## Tags & more" in md
    assert "| T\\|1 | 1.0 |" in md and "- two" in md and "![Flight path](path.png)" in md
    assert "```\nradio:\n  p0_db: -7\n```" in md
    html = doc.html()
    assert "<title>Report &lt;1&gt;</title>" in html and "<td>&lt;b&gt;</td>" in html
    assert "<p>a &amp; b</p>" in html and '<img src="path.png"' in html
    assert "<pre>radio:\n  p0_db: -7\n</pre>" in html


@pytest.mark.parametrize(("value", "digits", "text"), [
    (None, 1, "–"), (math.nan, 1, "–"), (math.inf, 2, "–"), (1.25, 1, "1.2"), (3, 1, "3"),
    (True, 1, "yes"), ("x", 1, "x"), (-34.92120001, 6, "-34.921200"),
])
def test_fmt(value: object, digits: int, text: str) -> None:
    assert fmt(value, digits) == text  # type: ignore[arg-type]


def test_parse_lat_lon() -> None:
    assert parse_lat_lon("-34.92, 138.60") == (-34.92, 138.60)
    for bad in ("-34.92", "a,b", "95,10", "10,200", "1,2,3"):
        with pytest.raises(ValueError, match=r"LAT,LON|latitude"):
            parse_lat_lon(bad)
