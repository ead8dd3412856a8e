"""The one reader of the simulator's ground truth, ``truth.jsonl`` (record types in
`io.records`, the contract in docs/truth-file.md).

Like the flight log: damaged records are skipped and counted by reason and line, a torn last
line is skipped, and the file is refused (LogFormatError) only when its first record is not a
``sim`` header of a known format version, or nothing but damage follows the header. A growing
file (the simulator still running) is read incrementally with `TruthTail`.

Frame: local ENU metres about the mission home (``x_m`` east, ``y_m`` north); times are unix
seconds of sim time, the clock of a SITL flight's log.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mexgen_gcs.errors import LogFormatError
from mexgen_gcs.io.logread import Damage, check_format, parse_record, read_jsonl
from mexgen_gcs.io.records import (
    TRUTH_ADAPTER,
    TRUTH_FORMAT,
    TRUTH_VERSION,
    Record,
    SimHeader,
    TagTruth,
)

TRUTH_FILE = "truth.jsonl"


@dataclass(frozen=True)
class TruthFile:
    """A read truth file: the header, every valid record (header first), what was skipped."""

    path: Path
    records: list[Record]
    torn_last_line: bool = False
    damage: Damage = field(default_factory=Damage)

    @property
    def header(self) -> SimHeader:
        head = self.records[0]
        assert isinstance(head, SimHeader)
        return head

    def of_type(self, type: str) -> Iterator[Record]:
        return (r for r in self.records if r.type == type)

    def tags(self) -> Iterator[TagTruth]:
        return (r for r in self.records if isinstance(r, TagTruth))


def read_truth_file(path: str | os.PathLike[str]) -> TruthFile:
    """Read ``truth.jsonl`` (or the directory holding it). LogFormatError if it is not a truth
    file of a version this code reads, or nothing usable is in it."""
    file = Path(path)
    if file.is_dir():
        file = file / TRUTH_FILE
    raw = read_jsonl(file, TRUTH_ADAPTER, "simulator truth file")
    check_format(file, raw.first_line, "sim", TRUTH_FORMAT, TRUTH_VERSION, "truth file",
                 label="simulator truth file", default_version=1)
    if not raw.records or not isinstance(raw.records[0], SimHeader):
        reason = next(iter(raw.damage.lines), "invalid")
        raise LogFormatError(f"{file}: the 'sim' header record (the first line) is damaged "
                             f"({reason}); the truth file cannot be read without it")
    if raw.damage and len(raw.records) == 1:
        raise LogFormatError(f"{file}: nothing usable after the 'sim' header: "
                             f"{raw.damage.describe()}")
    return TruthFile(file, raw.records, raw.torn_last_line, raw.damage)


class TruthTail:
    """Reads the records a running simulator appends to its truth file, a complete line at a
    time; damaged lines are counted in `damage`, as `read_truth_file` would."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.damage = Damage()
        self._offset = 0
        self._line = 0

    def read_new(self) -> list[Record]:
        """Records completed since the last call ([] if the file does not exist yet)."""
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self._offset)
                data = fh.read()
        except OSError:
            return []
        end = data.rfind(b"\n") + 1
        out: list[Record] = []
        for line in data[:end].split(b"\n")[:-1]:
            self._line += 1
            if not line.strip():
                continue
            rec = parse_record(line, TRUTH_ADAPTER)
            if isinstance(rec, str):
                self.damage.add(rec, self._line)
            else:
                out.append(rec)
        self._offset += end
        return out


class TagPositions:
    """The latest true position of each tag (ENU metres) in a running simulator's truth file,
    for showing beside the estimates."""

    def __init__(self, path: Path) -> None:
        self.tail = TruthTail(path)
        self._latest: dict[str, tuple[float, float]] = {}

    def positions(self) -> dict[str, tuple[float, float]]:
        for rec in self.tail.read_new():
            if isinstance(rec, TagTruth):
                self._latest[rec.tag] = (rec.x_m, rec.y_m)
        return dict(self._latest)
