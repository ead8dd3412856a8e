"""Ground truth log ``truth.jsonl``: one JSON object per line, each with ``t`` and ``type``.

``t`` is unix seconds of sim time (start_unix + sim elapsed), the clock the simulator
publishes. Positions are local ENU metres about the mission home plus WGS84 where useful.
Record types: ``sim`` (first line: mission, seed, speedup, start time), ``tag`` (each tag at
1 Hz), ``vehicle`` (1 Hz), ``pulse`` (every pulse: true power, detected, what was sent),
``clutter`` (spurious detections sent), ``fault`` (start/end), ``event`` (autopilot events),
``fence`` (accepted geofence uploads), ``end`` (last line on a clean exit).
Written append-only and flushed per record, so a crash loses at most the line being written.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import IO, Any

FILENAME = "truth.jsonl"


def _clean(value: Any) -> Any:
    """JSON has no NaN/inf: write them as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


class TruthWriter:
    """Appends records to ``DIR/truth.jsonl``; with ``directory=None`` it writes nothing."""

    def __init__(self, directory: Path | None) -> None:
        self.path: Path | None = None
        self._file: IO[str] | None = None
        self.records = 0
        if directory is not None:
            directory.mkdir(parents=True, exist_ok=True)
            self.path = directory / FILENAME
            self._file = self.path.open("a", encoding="utf-8")

    def write(self, t: float, record_type: str, **fields: Any) -> None:
        if self._file is None:
            return
        record = {"t": round(t, 6), "type": record_type} | _clean(fields)
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._file.flush()
        self.records += 1

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def read_truth(path: Path) -> list[dict[str, Any]]:
    """All complete records of a truth file (a torn last line is skipped)."""
    out: list[dict[str, Any]] = []
    with path.open(encoding="utf-8") as f:
        for line in f:
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return out
