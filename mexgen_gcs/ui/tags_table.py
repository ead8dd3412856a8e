"""The tags table: per tag its frequency, existence probability, estimate (lat/lon), 95 %
uncertainty radius, detections in the last minute, last RSSI, whether (and when) it was
localised and whether it was reported (reached, stalled, budget: the vehicle has moved on from
it; core.mission_core.ReportRule). Selecting a row asks for the map to centre on that tag
(``TagSelected``).

Positions WGS84 degrees; the ENU estimate travels in the message for the map.
"""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.message import Message
from textual.widgets import DataTable

from mexgen_gcs.io.snapshot import TagView
from mexgen_gcs.ui.format import freq_mhz, num

COLUMNS = ("Tag", "MHz", "P(exist)", "Lat", "Lon", "±m", "det/min", "RSSI dB", "Localised",
           "Reported")

REPORT_STYLES = {"reached": "bold green", "stalled": "bold yellow", "budget": "bold yellow"}


def tag_row(tag: TagView) -> tuple[Text, ...]:
    """The table cells for one tag."""
    exist_style = "bold green" if tag.existence >= 0.5 else "dim"
    if tag.localised:
        when = f" @{tag.localised_at_s:.0f}s" if tag.localised_at_s is not None else ""
        loc = Text(f"yes{when}", style="bold black on green")
    else:
        loc = Text("no", style="dim")
    return (
        Text(tag.tag_id, style="bold"),
        Text(freq_mhz(tag.freq_hz)),
        Text(num(tag.existence, ".2f"), style=exist_style, justify="right"),
        Text(num(tag.lat_deg, ".5f"), justify="right"),
        Text(num(tag.lon_deg, ".5f"), justify="right"),
        Text(num(tag.radius_m, ".0f"), justify="right"),
        Text(str(tag.detections_last_min), justify="right"),
        Text(num(tag.last_rssi_db, ".1f"), justify="right"),
        loc,
        Text(tag.reported, style=REPORT_STYLES.get(tag.reported, "")) if tag.reported
        else Text("-", style="dim"),
    )


class TagsTable(DataTable[Text]):
    """One row per mission tag, refreshed in place."""

    class TagSelected(Message):
        """The operator picked a tag (Enter on its row)."""

        def __init__(self, tag_id: str, east_m: float, north_m: float) -> None:
            super().__init__()
            self.tag_id = tag_id
            self.east_m = east_m
            self.north_m = north_m

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id, cursor_type="row", zebra_stripes=True)
        self.tags: tuple[TagView, ...] = ()
        self._shown: dict[str, tuple[Text, ...]] = {}

    def on_mount(self) -> None:
        for name in COLUMNS:
            self.add_column(name, key=name)

    def show(self, tags: Sequence[TagView]) -> None:
        self.tags = tuple(tags)
        for tag in self.tags:
            cells = tag_row(tag)
            shown = self._shown.get(tag.tag_id)
            if shown is None:
                self.add_row(*cells, key=tag.tag_id)
            else:
                for name, cell, old in zip(COLUMNS, cells, shown, strict=True):
                    if cell != old:  # only what changed
                        self.update_cell(tag.tag_id, name, cell)
            self._shown[tag.tag_id] = cells

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        tid = str(event.row_key.value)
        for tag in self.tags:
            if tag.tag_id == tid:
                self.post_message(self.TagSelected(tid, tag.east_m, tag.north_m))
