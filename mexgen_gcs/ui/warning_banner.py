"""The warning banner: active warnings (link lost, radio silent, battery, hold, geofence) in
large blinking red, and mission notices (ended, returning before quit) in amber. Hidden when
there is nothing to say. No frames.
"""

from __future__ import annotations

from rich.console import RenderableType
from rich.text import Text
from textual.widget import Widget

BLINK_S = 0.6


class WarningBanner(Widget):
    """Impossible to miss while anything is wrong; gone when all is well."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.warnings: tuple[str, ...] = ()
        self.notice: str | None = None
        self.display = False

    def on_mount(self) -> None:
        self.set_interval(BLINK_S, self._blink)

    def _blink(self) -> None:
        if self.warnings:
            self.toggle_class("-blink")

    def show(self, warnings: tuple[str, ...], notice: str | None = None) -> None:
        if tuple(warnings) == self.warnings and notice == self.notice:
            return  # unchanged: no repaint, no re-layout
        self.warnings = tuple(warnings)
        self.notice = notice
        self.set_class(bool(self.warnings), "-warning")
        self.set_class(not self.warnings and notice is not None, "-notice")
        if not self.warnings:
            self.remove_class("-blink")
        self.display = bool(self.warnings) or notice is not None
        self.refresh(layout=True)

    def render(self) -> RenderableType:
        text = Text(justify="center", no_wrap=False)
        for i, w in enumerate(self.warnings):
            if i:
                text.append("   ")
            text.append(f"⚠ {w}", style="bold")
        if self.notice:
            if self.warnings:
                text.append("\n")
            text.append(self.notice, style="bold")
        return text
