"""Run the UI on a terminal that is never read, and measure the event loop's responsiveness.

Usage: python slow_terminal_probe.py nonblocking|textual RESULT.json SECONDS
Started by test_terminal.py with a pseudo-terminal whose other end nobody reads. Writes
{"max_gap_s", "ticks", "dropped"} once the time is up and output has been dropped (if the
loop still runs), then exits.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from dataclasses import replace

from textual.drivers.linux_driver import LinuxDriver

from mexgen_gcs.ui.app import MexgenApp
from tests.ui.ui_helpers import make_snapshot


class Churn:
    """A live-looking source whose every snapshot redraws much of the screen, at 30 Hz."""

    kind = "live"

    def command(self, cmd: str) -> None:
        pass

    async def snapshots(self):
        base = [make_snapshot(seed=i) for i in range(8)]
        i = 0
        while True:
            snap = base[i % 8]
            yield replace(snap, t=snap.t + i, elapsed_s=snap.elapsed_s + i,
                          warnings=("RADIO SILENT",) if i % 2 else ())
            i += 1
            await asyncio.sleep(1 / 30)


async def main(mode: str, out: str, seconds: float) -> None:
    app = MexgenApp(Churn(), driver_class=LinuxDriver if mode == "textual" else None)

    async def probe() -> None:
        await asyncio.sleep(0.5)
        writer = getattr(app._driver, "_writer_thread", None)
        gaps = []
        start = last = time.monotonic()
        # at least `seconds`, and on until the stalled terminal has made the UI drop output
        while time.monotonic() - start < seconds or (
                getattr(writer, "dropped", 1) == 0 and time.monotonic() - start < 4 * seconds):
            await asyncio.sleep(0.02)
            now = time.monotonic()
            gaps.append(now - last)
            last = now
            app.screen.refresh()  # a full-screen update each tick: plenty of output
        with open(out, "w", encoding="utf-8") as fh:
            json.dump({"max_gap_s": max(gaps), "ticks": len(gaps),
                       "dropped": getattr(writer, "dropped", None)}, fh)
        app.exit()

    task = asyncio.create_task(probe())
    await app.run_async()
    await task


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], float(sys.argv[3])))
