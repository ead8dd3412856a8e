"""Choosing the planner method in flight (mexgen, pim, mc). Dismisses with the method, or
None when cancelled. No frames."""

from __future__ import annotations

from typing import ClassVar

from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Label, OptionList
from textual.widgets.option_list import Option

from mexgen_gcs.ui.source import METHODS

DESCRIPTIONS = {
    "mexgen": "MexGen: expected measurement (fast, default)",
    "pim": "PIM: predicted ideal measurement",
    "mc": "MC-M: Monte Carlo measurements (slowest)",
}


class MethodScreen(ModalScreen[str | None]):
    """Pick with the arrows and Enter, or the method's number."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape,q", "cancel", "Cancel"),
        Binding("1", "pick(0)", show=False),
        Binding("2", "pick(1)", show=False),
        Binding("3", "pick(2)", show=False),
    ]

    def __init__(self, current: str) -> None:
        super().__init__()
        self.current = current

    def compose(self) -> ComposeResult:
        with Vertical(id="method-box"):
            yield Label("Planner method (Enter to switch, Esc to cancel)")
            options = [Option(f"{i + 1}  {DESCRIPTIONS[m]}" + ("  (now)" if m == self.current
                                                                else ""), id=m)
                       for i, m in enumerate(METHODS)]
            yield OptionList(*options, id="method-options")

    def on_mount(self) -> None:
        options = self.query_one(OptionList)
        if self.current in METHODS:
            options.highlighted = METHODS.index(self.current)
        options.focus()

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        event.stop()
        self.dismiss(event.option.id)

    def action_pick(self, index: int) -> None:
        self.dismiss(METHODS[index])

    def action_cancel(self) -> None:
        self.dismiss(None)
