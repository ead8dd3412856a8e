"""The replay bar: position in the recording, speed and whether paused. No frames."""

from __future__ import annotations

from rich.console import RenderableType
from rich.text import Text
from textual.widget import Widget

from mexgen_gcs.ui.format import bar
from mexgen_gcs.ui.source import ReplayStatus


class ReplayBar(Widget):
    """Shown only when replaying a recorded flight."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.status: ReplayStatus | None = None

    def show(self, status: ReplayStatus) -> None:
        self.status = status
        self.refresh()

    def render(self) -> RenderableType:
        s = self.status
        if s is None:
            return Text("REPLAY", style="bold")
        state = "ENDED" if s.finished else ("PAUSED" if s.paused else "PLAYING")
        head = f" REPLAY {state} ×{s.speedup:g}  {s.index + 1}/{s.total} "
        width = max(self.content_size.width - len(head) - 1, 4)
        frac = s.index / max(s.total - 1, 1)
        text = Text(no_wrap=True, overflow="crop")
        text.append(head, style="bold black on bright_cyan" if not s.paused else
                    "bold black on yellow")
        text.append(" ")
        text.append(bar(frac, width), style="cyan")
        return text
