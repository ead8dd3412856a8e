"""The status bar: link, flight mode, armed/in-air, altitude, speed, battery, radio heartbeat
age, mission state and elapsed time, each coloured by how worried the operator should be.

No frames (altitude is above home, speed is ground speed).
"""

from __future__ import annotations

from rich.console import RenderableType
from rich.text import Text
from textual.widget import Widget

from mexgen_gcs.io.snapshot import MissionSnapshot
from mexgen_gcs.mission.state import MissionState
from mexgen_gcs.ui.format import age_text, clock_text, finite, num

OK = "bold black on green"
BAD = "bold bright_white on red"
WARN = "bold black on yellow"
PLAIN = "bold"


def status_text(snap: MissionSnapshot | None, width: int = 1000) -> Text:
    """The status line for a snapshot, broken between items to fit `width` cells."""
    if snap is None:
        return Text(" waiting for the mission… ", style=WARN)
    tel = snap.telemetry
    warn = set(snap.warnings)
    parts: list[tuple[str, str]] = []
    link_lost = "VEHICLE LINK LOST" in warn or not snap.link_ok
    parts.append((" LINK LOST " if link_lost else " LINK OK ", BAD if link_lost else OK))
    parts.append((f" {tel.flight_mode} ", PLAIN))
    armed = "ARMED" if tel.armed else "DISARMED"
    air = "IN AIR" if tel.in_air else "ON GROUND"
    parts.append((f" {armed} {air} ", WARN if tel.armed else PLAIN))
    parts.append((f" alt {num(tel.rel_alt_m, '.1f')} m ", PLAIN))
    parts.append((f" {num(tel.ground_speed_m_s, '.1f')} m/s ", PLAIN))
    battery_low = any(w.startswith("BATTERY") for w in warn)
    bat = f"{tel.battery_percent:.0f}%" if finite(tel.battery_percent) else "--"
    parts.append((f" bat {bat} ", BAD if battery_low else PLAIN))
    silent = "RADIO SILENT" in warn
    parts.append((f" radio {age_text(snap.radio_heartbeat_age_s)} ", BAD if silent else PLAIN))
    waiting = snap.state in (MissionState.HOLDING, MissionState.RETURNING)
    state_style = WARN if waiting else "bold reverse"
    parts.append((f" {snap.state.upper()} ", state_style))
    parts.append((f" T+{clock_text(snap.elapsed_s)} ", PLAIN))
    parts.append((f" {snap.method} ", "bold cyan"))
    text = Text(no_wrap=True, overflow="crop")
    used = 0
    for i, (s, style) in enumerate(parts):
        if i and used + 1 + len(s) > width:  # a line breaks between items, never inside one
            text.append("\n")
            used = 0
        elif i:
            text.append("│", style="dim")
            used += 1
        text.append(s, style=style)
        used += len(s)
    return text


class StatusBar(Widget):
    """One glance at the vehicle and the mission."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.snapshot: MissionSnapshot | None = None

    def show(self, snap: MissionSnapshot) -> None:
        self.snapshot = snap
        lines = status_text(snap, self.content_size.width).plain.count("\n") + 1
        self.refresh(layout=lines != self.content_size.height)  # a re-layout only if needed

    def on_resize(self) -> None:
        self.refresh(layout=True)

    def render(self) -> RenderableType:
        return status_text(self.snapshot, self.content_size.width)
