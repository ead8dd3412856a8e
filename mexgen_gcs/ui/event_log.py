"""The event log panel: mission events as they happen (connecting, armed, tag_localised,
safety actions, operator commands, errors), newest at the bottom, coloured by severity.
No frames.
"""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.widgets import RichLog

from mexgen_gcs.ui.format import event_style, new_events


class EventLog(RichLog):
    """Appends the events it has not shown yet from each snapshot's recent-events window."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id, max_lines=500, wrap=False, markup=False, auto_scroll=True)
        self.window: tuple[str, ...] = ()
        self.border_title = "Events"

    def show(self, events: Sequence[str]) -> None:
        for line in new_events(self.window, events):
            self.write(Text(line, style=event_style(line)))
        self.window = tuple(events)

    def note(self, line: str, style: str = "bold cyan") -> None:
        """A line from the UI itself (a command sent, a view change)."""
        self.write(Text(line, style=style))
