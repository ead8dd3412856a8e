"""The simulator's ground truth (``truth.jsonl``) for scoring a flight: where each tag really
was, and when.

Frame: local ENU metres about the mission home, as the simulator writes them (``x_m`` east,
``y_m`` north). Times are unix seconds of sim time, the same clock as the flight log of a SITL
flight. A torn last line is skipped, like the flight log's.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.errors import LogFormatError

FloatArray = NDArray[np.float64]
TRUTH_FILE = "truth.jsonl"


@dataclass(frozen=True, slots=True)
class TagTruth:
    """One tag's true track (K,) and its motion model name."""

    tag_id: str
    motion: str
    t: FloatArray
    east_m: FloatArray
    north_m: FloatArray

    def position_at(self, t: FloatArray | float) -> FloatArray:
        """(..., 2) true position linearly interpolated at t (clamped to the track's ends)."""
        tt = np.asarray(t, dtype=np.float64)
        return np.stack([np.interp(tt, self.t, self.east_m), np.interp(tt, self.t, self.north_m)],
                        axis=-1)

    @property
    def static(self) -> bool:
        return self.motion == "static" or bool(
            np.ptp(self.east_m) < 1e-6 and np.ptp(self.north_m) < 1e-6)


@dataclass(frozen=True, slots=True)
class Truth:
    """Ground truth of one simulated flight."""

    path: Path
    tags: dict[str, TagTruth]
    header: dict[str, Any]

    def error_m(self, tag_id: str, t: float, east_m: float, north_m: float) -> float | None:
        """Distance from an estimate to the tag's true position at t; None if unknown."""
        tag = self.tags.get(tag_id)
        if tag is None or not (math.isfinite(east_m) and math.isfinite(north_m)):
            return None
        e, n = tag.position_at(t)
        return float(math.hypot(east_m - e, north_m - n))


def find_truth(log_dir: Path) -> Path | None:
    """`truth.jsonl` beside a flight log, if there is one."""
    p = log_dir / TRUTH_FILE
    return p if p.is_file() else None


def load_truth(path: str | os.PathLike[str]) -> Truth:
    """Read a truth file. LogFormatError if it is not one."""
    p = Path(path)
    if p.is_dir():
        p = p / TRUTH_FILE
    try:
        lines = p.read_text(encoding="utf-8", errors="replace").split("\n")
    except OSError as exc:
        raise LogFormatError(f"{p}: cannot read the truth file: {exc.strerror}") from None
    header: dict[str, Any] = {}
    rows: dict[str, list[tuple[float, float, float]]] = {}
    motion: dict[str, str] = {}
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:
            if n >= len(lines) - 1:  # the torn last line of a crashed simulator
                continue
            raise LogFormatError(f"{p}:{n}: not a JSON line; the truth file is damaged") from None
        if not isinstance(rec, dict):
            continue
        kind = rec.get("type")
        if kind == "sim" and not header:
            header = rec
            for tag in rec.get("tags") or []:
                motion[str(tag.get("id"))] = str(tag.get("motion", "static"))
        elif kind == "tag":
            try:
                rows.setdefault(str(rec["tag"]), []).append(
                    (float(rec["t"]), float(rec["x_m"]), float(rec["y_m"])))
            except (KeyError, TypeError, ValueError):
                continue
            if "motion" in rec:
                motion.setdefault(str(rec["tag"]), str(rec["motion"]))
    if not header:
        raise LogFormatError(f"{p}: not a simulator truth file (no 'sim' header record)")
    for tag in header.get("tags") or []:  # a tag with no track yet: its start position
        tid = str(tag.get("id"))
        if tid not in rows and "x_m" in tag and "y_m" in tag:
            rows[tid] = [(float(header.get("start_unix", header["t"])), float(tag["x_m"]),
                          float(tag["y_m"]))]
    tags = {}
    for tid, r in rows.items():
        arr = np.array(sorted(r), dtype=np.float64)
        tags[tid] = TagTruth(tid, motion.get(tid, "static"), arr[:, 0], arr[:, 1], arr[:, 2])
    return Truth(p, tags, header)
