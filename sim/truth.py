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

from pathlib import Path
from typing import Any

from mexgen_gcs.io.jsonl import JsonlWriter
from mexgen_gcs.io.records import TRUTH_ADAPTER
from mexgen_gcs.io.truthfile import TRUTH_FILE

FILENAME = TRUTH_FILE


class TruthWriter:
    """Writes ``DIR/truth.jsonl`` through the product's JSON-lines writer (`io.jsonl`: the
    record types are `io.records`, read back by `io.truthfile`); with ``directory=None`` it
    writes nothing. Refuses a directory that already holds a truth file (FileExistsError):
    two worlds in one file could not be told apart."""

    def __init__(self, directory: Path | None) -> None:
        self.path: Path | None = None
        self._writer: JsonlWriter | None = None
        if directory is not None:
            self.path = directory / FILENAME
            try:
                self._writer = JsonlWriter(self.path, records=TRUTH_ADAPTER)
            except FileExistsError:
                raise FileExistsError(f"{self.path} already exists: give each run its own "
                                      "--truth-dir") from None

    @property
    def invalid(self) -> dict[str, int]:
        """Records written that the truth file's documented types do not allow, by reason."""
        return dict(self._writer.invalid) if self._writer is not None else {}

    @property
    def records(self) -> int:
        return self._writer.records if self._writer is not None else 0

    def write(self, t: float, record_type: str, **fields: Any) -> None:
        if self._writer is not None:
            self._writer.write(record_type, t=round(t, 6), **fields)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
