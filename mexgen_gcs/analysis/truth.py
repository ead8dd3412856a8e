"""The simulator's ground truth (``truth.jsonl``) for scoring a flight: where each tag really
was, and when.

Frame: local ENU metres about the mission home, as the simulator writes them (``x_m`` east,
``y_m`` north). Times are unix seconds of sim time, the same clock as the flight log of a SITL
flight. Read by the one truth reader, `io.truthfile` (damaged records skipped and counted, a
torn last line skipped, like the flight log's).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.io.logread import Damage
from mexgen_gcs.io.records import SimHeader
from mexgen_gcs.io.truthfile import TRUTH_FILE, read_truth_file

FloatArray = NDArray[np.float64]


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


@dataclass(frozen=True)
class Truth:
    """Ground truth of one simulated flight."""

    path: Path
    tags: dict[str, TagTruth]
    header: SimHeader
    damage: Damage = field(default_factory=Damage)
    """Damaged records of the truth file that were skipped."""
    torn_last_line: bool = False

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
    """Read a truth file with `io.truthfile.read_truth_file` (damaged records skipped and
    counted) into per-tag tracks. LogFormatError if it is not a truth file."""
    file = read_truth_file(path)
    head = file.header
    rows: dict[str, list[tuple[float, float, float]]] = {}
    motion = {tag.id: tag.motion for tag in head.tags}
    for rec in file.tags():
        rows.setdefault(rec.tag, []).append((rec.t, rec.x_m, rec.y_m))
        motion.setdefault(rec.tag, rec.motion)
    for tag in head.tags:  # a tag with no track yet: its start position
        rows.setdefault(tag.id, [(head.start_unix, tag.x_m, tag.y_m)])
    tags = {}
    for tid, r in rows.items():
        arr = np.array(sorted(r), dtype=np.float64)
        tags[tid] = TagTruth(tid, motion.get(tid, "static"), arr[:, 0], arr[:, 1], arr[:, 2])
    return Truth(file.path, tags, head, file.damage, file.torn_last_line)
