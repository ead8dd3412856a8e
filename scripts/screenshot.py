"""Save the terminal UI of a flown log as an image: the README's picture.

    mexgen-gcs sitl missions/demo.yaml --headless --speedup 10 --log-dir /tmp/flights
    python scripts/screenshot.py /tmp/flights/<log> --at-s 250 --out /tmp/tui.svg

The UI is the real Textual app, fed the snapshot the `replay` command would show ``--at-s``
mission seconds into the search (with the simulator's truth when the log has it). It writes an
SVG, and a PNG beside it when cairosvg is importable.
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path

from mexgen_gcs.analysis.flightdata import load_flight
from mexgen_gcs.analysis.snapshots import build_snapshots
from mexgen_gcs.analysis.truth import find_truth, load_truth
from mexgen_gcs.ui.app import build_app
from mexgen_gcs.ui.source import ReplaySource


async def shoot(log: Path, at_s: float, out: Path, size: tuple[int, int]) -> Path:
    flight = load_flight(log)
    truth_path = find_truth(flight.log_dir)
    truth = load_truth(truth_path) if truth_path is not None else None
    snaps = build_snapshots(flight, (), truth)
    searching = [s for s in snaps if s.state == "searching"] or snaps
    t0 = searching[0].elapsed_s
    snap = min(searching, key=lambda s: abs(s.elapsed_s - t0 - at_s))
    rest = snaps[snaps.index(snap):]  # paused on the first: the replay has not ended
    app = build_app(ReplaySource(rest, start_paused=True), linger_s=None)
    async with app.run_test(size=size) as pilot:
        for _ in range(50):
            await pilot.pause(0.1)
            if app.snapshot is snap:
                break
        await pilot.pause(1.0)
        app.save_screenshot(out.name, path=str(out.parent))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--at-s", type=float, default=300.0, help="mission seconds into the search")
    ap.add_argument("--out", type=Path, default=Path("docs/img/tui.svg"))
    ap.add_argument("--size", default="120x40", help="terminal columns x rows")
    args = ap.parse_args()
    cols, rows = (int(v) for v in args.size.split("x"))
    svg = asyncio.run(shoot(args.log, args.at_s, args.out, (cols, rows)))
    print(svg)
    try:
        import cairosvg  # type: ignore[import-not-found]
    except ImportError:
        return
    png = svg.with_suffix(".png")
    cairosvg.svg2png(url=str(svg), write_to=str(png), output_width=1400)
    print(png)


if __name__ == "__main__":
    main()
