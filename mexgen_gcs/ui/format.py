"""Pure text formatting shared by the panels: numbers with their units, as operators read them.

Headings are compass degrees (0 north, clockwise); positions WGS84 degrees; no frames else.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

#: compass names of the planner's 8 headings
COMPASS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def num(x: float | None, fmt: str, missing: str = "--") -> str:
    """`format(x, fmt)`, or `missing` for None / NaN / inf."""
    return format(x, fmt) if finite(x) else missing


def clock_text(seconds: float) -> str:
    """Elapsed seconds as H:MM:SS (or M:SS under an hour)."""
    if not math.isfinite(seconds) or seconds < 0:
        return "--:--"
    s = int(seconds)
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


def age_text(seconds: float) -> str:
    """An age for the status bar: '0.4s', '12s', '3m', 'never'."""
    if not math.isfinite(seconds):
        return "never"
    if seconds < 10:
        return f"{max(seconds, 0.0):.1f}s"
    if seconds < 120:
        return f"{seconds:.0f}s"
    return f"{seconds / 60:.0f}m"


def compass_name(heading_deg: float) -> str:
    return COMPASS[int(((heading_deg % 360.0) + 22.5) // 45.0) % 8]


def bar(fraction: float, width: int) -> str:
    """A horizontal bar of `width` cells filled to `fraction` (eighth-cell resolution)."""
    width = max(width, 0)
    f = min(max(fraction, 0.0), 1.0) * width
    full = int(f)
    eighths = int((f - full) * 8)
    partial = " ▏▎▍▌▋▊▉"[eighths] if eighths and full < width else ""
    return ("█" * full + partial).ljust(width)


def reward_fractions(rewards: Sequence[float]) -> list[float | None]:
    """Bar lengths in [0, 1] for rewards: the worst finite maps to a small stub, the best to 1;
    None where a heading was pruned (non-finite)."""
    vals = [r for r in rewards if finite(r)]
    if not vals:
        return [None] * len(rewards)
    lo, hi = min(vals), max(vals)
    span = hi - lo
    out: list[float | None] = []
    for r in rewards:
        if not finite(r):
            out.append(None)
        elif span <= 0:
            out.append(1.0)
        else:
            out.append(0.08 + 0.92 * (r - lo) / span)
    return out


def freq_mhz(freq_hz: int) -> str:
    return f"{freq_hz / 1e6:.3f}"


def new_events(previous: Sequence[str], current: Sequence[str]) -> list[str]:
    """The lines of `current` not yet shown, given the window `previous` shown before.

    Both are the tail of one growing event list; the overlap is the longest suffix of
    `previous` that is a prefix of `current`.
    """
    prev = list(previous)
    cur = list(current)
    for k in range(min(len(prev), len(cur)), 0, -1):
        if prev[-k:] == cur[:k]:
            return cur[k:]
    return cur


def event_style(line: str) -> str:
    """Colour for an event line: errors red, safety actions yellow, milestones green."""
    low = line.lower()
    if any(w in low for w in ("error", "failed", "lost", "not_confirmed", "overrun")):
        return "bold red"
    if any(w in low for w in ("safety", "hold", "rtl", "silent", "battery", "abort",
                              "mission_end", "dropped")):
        return "yellow"
    if any(w in low for w in ("tag_localised", "landed_and_disarmed", "offboard_started",
                              "armed", "takeoff", "radio_ok", "vehicle_ready")):
        return "green"
    return ""
