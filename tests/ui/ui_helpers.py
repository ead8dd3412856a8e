"""Fakes and helpers for the UI tests: a fake snapshot stream (a unit test of the view layer
alone), snapshot builders, reading text back out of SVG screenshots, bounded waits.

The snapshots are built with the real MissionSnapshot/TagView/PlanView types; the numbers are
chosen to be recognisable on screen (e.g. RSSI -47.3 dB, altitude 49.6 m). ENU metres.
"""

from __future__ import annotations

import asyncio
import html
import re
from collections.abc import AsyncIterator
from dataclasses import replace
from typing import Literal

import numpy as np

from mexgen_gcs.io.records import Plan
from mexgen_gcs.io.snapshot import MissionSnapshot, TagView
from mexgen_gcs.io.vehicle import Telemetry

AREA = ((-500.0, -100.0), (500.0, -100.0), (500.0, 900.0), (-500.0, 900.0))
HEADINGS = tuple(float(h) for h in range(0, 360, 45))


def make_tag(tag_id: str, freq_hz: int, e: float, n: float, rng: np.random.Generator, *,
             localised: bool = False, rssi: float | None = -47.3,
             truth: tuple[float, float] | None = None) -> TagView:
    sd = 12.0 if localised else 60.0
    cloud = rng.normal([e, n], sd, size=(150, 2))
    return TagView(
        tag_id=tag_id, freq_hz=freq_hz, existence=0.97 if localised else 0.81,
        lat_deg=-34.9212 + n / 111_000.0, lon_deg=138.6011 + e / 91_000.0,
        east_m=e, north_m=n, radius_m=2.45 * sd, cov_pos_m2=(sd ** 2, 0.3 * sd ** 2, sd ** 2),
        localised=localised, localised_at_s=312.0 if localised else None,
        detections_last_min=14 if rssi is not None else 0, detections_total=40,
        last_rssi_db=rssi, cloud_en_m=tuple(map(tuple, cloud.tolist())), truth_en_m=truth)


def make_snapshot(t: float = 1000.0, *, state: str = "searching",
                  warnings: tuple[str, ...] = (), events: tuple[str, ...] | None = None,
                  truth: bool = True, seed: int = 0, method: str = "mexgen",
                  end_reason: str | None = None, armed: bool = True,
                  vehicle_en_m: tuple[float, float] = (-120.0, 380.0)) -> MissionSnapshot:
    rng = np.random.default_rng(seed)
    tags = (
        make_tag("T1", 150_100_000, -300.0, 600.0, rng, localised=True,
                 truth=(-296.0, 604.0) if truth else None),
        make_tag("T2", 150_220_000, 250.0, 700.0, rng, truth=(250.0, 700.0) if truth else None),
        make_tag("T3", 150_340_000, -200.0, 150.0, rng, rssi=None,
                 truth=(-200.0, 150.0) if truth else None),
        make_tag("T4", 150_460_000, 350.0, 250.0, rng, truth=(350.0, 250.0) if truth else None),
    )
    rewards = [0.112, 0.305, 0.412, 0.520, 0.233, None, 0.051, 0.198]  # None: pruned
    plan = Plan(t=t - 1.8, type="plan", method=method, targets=["T2"],
                headings_deg=list(HEADINGS), rewards=rewards, chosen_heading_deg=135.0,
                timing_ms={"predict": 12.0, "measure": 31.0, "update": 8.0,
                           "reward": 5.0, "total": 57.0},
                vehicle_en_m=vehicle_en_m, all_pruned=False)
    tel = Telemetry(connected=True, lat_deg=-34.9178, lon_deg=138.5998, abs_alt_m=49.6,
                    rel_alt_m=49.6, v_north_m_s=-6.0, v_east_m_s=8.0, yaw_deg=135.0,
                    armed=armed, in_air=armed, flight_mode="OFFBOARD" if armed else "HOLD",
                    battery_percent=87.0)
    track = tuple((float(x), float(y)) for x, y in zip(np.linspace(0.0, -120.0, 40),
                                                       np.linspace(0.0, 380.0, 40), strict=True))
    evs = events if events is not None else (
        "    0.0s connecting url=udpin://127.0.0.1:14540",
        "    2.1s armed",
        "   12.5s offboard_started",
        "  312.0s tag_localised tag=T1 after_s=312.0 radius_m=29.4",
    )
    return MissionSnapshot(
        t=t, elapsed_s=t - 600.0, state=state, end_reason=end_reason, telemetry=tel,
        vehicle_en_m=vehicle_en_m, track_en_m=track, tags=tags, plan=plan,
        next_plan_in_s=3.2,
        radio_heartbeat_age_s=0.4, radio_accepted=120, radio_rejects={}, warnings=warnings,
        events=evs, method=method, link_ok=True, area_en_m=AREA)


class FakeSource:
    """A snapshot source a test feeds by hand; records the commands it is sent."""

    def __init__(self, kind: Literal["live", "replay"] = "live") -> None:
        self.kind: Literal["live", "replay"] = kind
        self.queue: asyncio.Queue[MissionSnapshot | None] = asyncio.Queue()
        self.sent: list[str] = []

    def push(self, snap: MissionSnapshot | None) -> None:
        self.queue.put_nowait(snap)

    def command(self, cmd: str) -> None:
        self.sent.append(cmd)

    async def snapshots(self) -> AsyncIterator[MissionSnapshot]:
        while True:
            snap = await self.queue.get()
            if snap is None:  # end of the mission
                return
            yield snap


def later(snap: MissionSnapshot, dt_s: float, **changes: object) -> MissionSnapshot:
    return replace(snap, t=snap.t + dt_s, elapsed_s=snap.elapsed_s + dt_s, **changes)


# -- reading screenshots back ---------------------------------------------------------------
# Rich's SVG export draws each run of one style as a <text> element with its x position (in
# multiples of the character width) and its row in the clip-path id; blank cells are gaps.

_TEXT = re.compile(
    r'<text class="[^"]*" x="([\d.]+)" y="[\d.]+" textLength="([\d.]+)" '
    r'clip-path="url\(#[\w-]+-line-(\d+)\)">([^<]*)</text>')
CHAR_WIDTH = 12.2


def svg_rows(svg: str, width: int, height: int) -> list[str]:
    rows = [[" "] * width for _ in range(height)]
    for x, _length, line, content in _TEXT.findall(svg):
        row = int(line)
        col = round(float(x) / CHAR_WIDTH)
        for i, ch in enumerate(html.unescape(content).replace("\xa0", " ")):
            if 0 <= row < height and 0 <= col + i < width:
                rows[row][col + i] = ch
    return ["".join(r) for r in rows]


def screen_rows(app) -> list[str]:
    w, h = app.size
    return svg_rows(app.export_screenshot(), w, h)


def screen_text(app) -> str:
    return "\n".join(screen_rows(app))


async def until(pilot, predicate, timeout_s: float = 10.0) -> None:
    """Let the app run until `predicate()` holds (bounded)."""
    async with asyncio.timeout(timeout_s):
        while not predicate():
            await pilot.pause(0.02)
