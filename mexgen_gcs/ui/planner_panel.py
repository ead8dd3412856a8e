"""The planner panel: method, target tags, the expected reward of each of the 8 headings as
bars, the chosen heading, planning time by stage and the time to the next re-plan. With
altitude actions (``flight.min_alt_m``) each heading's row shows its best altitude's reward
and that altitude, and the heading line the altitude flown to.

Headings are compass degrees (0 north, clockwise).
"""

from __future__ import annotations

import math

from rich.console import RenderableType
from rich.text import Text
from textual.widget import Widget

from mexgen_gcs.io.records import Plan
from mexgen_gcs.ui.format import bar, compass_name, finite, reward_fractions

STAGE_NAMES = {"predict": "pred", "measure": "meas", "update": "upd", "reward": "rew"}


def planner_text(plan: Plan | None, method: str, width: int, next_plan_in_s: float) -> Text:
    """The panel's content for a plan (or the method alone before the first plan)."""
    text = Text(no_wrap=True, overflow="ellipsis")
    if plan is None:
        text.append(f"{method}", style="bold cyan")
        text.append("  no plan yet\n", style="dim")
        return text
    text.append(plan.method, style="bold cyan")
    targets = ",".join(plan.targets) if plan.targets else "-"
    text.append("  target ", style="dim")
    text.append(targets, style="bold")
    if plan.method != method:
        text.append(f"  → {method}", style="bold yellow")
    text.append("\n")
    chosen = plan.chosen_heading_deg
    text.append("heading ", style="dim")
    text.append(f"{chosen:03.0f}° {compass_name(chosen)}", style="bold bright_white")
    if plan.chosen_alt_m is not None:
        text.append("  alt ", style="dim")
        text.append(f"{plan.chosen_alt_m:.0f} m", style="bold bright_white")
    text.append("\n")
    headings, rewards, alts = _best_per_heading(plan)
    fractions = reward_fractions(rewards)
    label_w = 9  # "NE  045° "
    value_w = 9
    bar_w = max(width - label_w - value_w - 2, 4)
    if alts is not None:
        bar_w = max(bar_w - 5, 4)
    row_alts: list[float | None] = list(alts) if alts is not None else [None] * len(headings)
    for h, r, f, a in zip(headings, rewards, fractions, row_alts, strict=False):
        is_chosen = abs(((h - chosen + 180.0) % 360.0) - 180.0) < 1e-6
        style = "bold green" if is_chosen else "green"
        text.append(f"{compass_name(h):<3} {h:03.0f}° ", style="bold" if is_chosen else "")
        if f is None:
            text.append("pruned".ljust(bar_w), style="dim")
            text.append(" " * value_w)
        else:
            text.append(bar(f, bar_w), style=style)
            text.append(f" {r:>8.3g}", style="bold" if is_chosen else "")
            if a is not None:
                text.append(f" @{a:<3.0f}", style="dim")
        text.append(" ◀\n" if is_chosen else "\n", style="bold")
    stages = [f"{STAGE_NAMES.get(k, k)} {v:.0f}" for k, v in plan.timing_ms.items()
              if k != "total" and finite(v)]
    total = plan.timing_ms.get("total")
    text.append("ms ", style="dim")
    text.append(" ".join(stages))
    if finite(total):
        text.append(f" = {total:.0f}", style="bold")
    text.append("\n")
    text.append("next re-plan in ", style="dim")
    text.append(f"{next_plan_in_s:.1f} s", style="bold")
    return text


def _best_per_heading(plan: Plan) -> tuple[list[float], list[float], list[float] | None]:
    """(headings, rewards, altitudes): one row per heading; with altitude actions the best
    altitude's reward (NaN where every altitude is pruned) and that altitude."""
    rewards = [math.nan if r is None else r for r in plan.rewards]  # None: pruned
    if plan.alts_m is None:
        return list(plan.headings_deg), rewards, None
    best: dict[float, tuple[float, float]] = {}
    for h, r, a in zip(plan.headings_deg, rewards, plan.alts_m, strict=False):
        key = round(h % 360.0, 6)
        if key not in best or (not math.isnan(r) and (math.isnan(best[key][0])
                                                      or r > best[key][0])):
            best[key] = (r, a)
    heads = list(best)
    return heads, [best[h][0] for h in heads], [best[h][1] for h in heads]


class PlannerPanel(Widget):
    """What the planner decided last and why."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.plan: Plan | None = None
        self.method = "-"
        self.next_plan_in_s = 0.0
        self.border_title = "Planner"

    def show(self, plan: Plan | None, method: str, next_plan_in_s: float) -> None:
        self.plan = plan
        self.method = method
        self.next_plan_in_s = next_plan_in_s
        self.refresh()

    def render(self) -> RenderableType:
        return planner_text(self.plan, self.method, self.content_size.width,
                            self.next_plan_in_s)
