"""Flight log: one directory per flight, `flight.jsonl` with one JSON object per line.

Contract (docs/flight-log.md; every record type is defined once, in `io.records`): every
record has `t` (unix s) and `type`; the file is written append-only and flushed per record, so
a crash loses at most the line being written. The reader skips a torn last line and damaged
records (counted by reason and line, see `io.logread`). The first record is
`type: "mission"` with `format` ("mexgen-flightlog"), `format_version`, the resolved mission,
the mission file path and text, software versions, seed and method. Positions inside records
are in the frame `io.records` names (ENU metres about home for estimates, WGS84 for
telemetry); the log does not convert frames.

Values are made JSON-safe on the way in: numpy scalars/arrays become Python numbers/lists,
NaN and infinities become null, tuples become lists, dataclasses and pydantic models dicts.
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mexgen_gcs.errors import LogFormatError
from mexgen_gcs.io.jsonl import JsonlWriter
from mexgen_gcs.io.logread import Damage, check_format, read_jsonl
from mexgen_gcs.io.records import (
    FLIGHT_ADAPTER,
    FLIGHT_LOG_FORMAT,
    FLIGHT_LOG_VERSION,
    MissionHeader,
    Record,
)

if TYPE_CHECKING:
    from mexgen_gcs.config.mission import Mission

FORMAT = FLIGHT_LOG_FORMAT
FORMAT_VERSION = FLIGHT_LOG_VERSION
LOG_FILE = "flight.jsonl"


def software_versions() -> dict[str, str | None]:
    """Versions of mexgen_gcs and the libraries that decide what flies."""
    from mexgen_gcs import __version__

    out: dict[str, str | None] = {"mexgen_gcs": __version__, "python": platform.python_version()}
    for dist in ("numpy", "mavsdk", "pymavlink"):
        try:
            out[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            out[dist] = None
    return out


class FlightLogWriter(JsonlWriter):
    """`<log_dir>/flight.jsonl`, starting with the mission record."""

    def __init__(
        self,
        log_dir: str | os.PathLike[str],
        mission: Mission,
        *,
        seed: int | None = None,
        method: str | None = None,
        fsync: bool = False,
        clock: Callable[[], float] = time.time,
        extra: Mapping[str, Any] | None = None,
    ) -> None:
        self.log_dir = Path(log_dir)
        super().__init__(self.log_dir / LOG_FILE, fsync=fsync, clock=clock,
                         records=FLIGHT_ADAPTER)
        from mexgen_gcs.config.describe import dump_resolved

        self.write(
            "mission",
            format=FORMAT,
            format_version=FORMAT_VERSION,
            mission=dump_resolved(mission),
            mission_path=mission.source_path,
            mission_text=mission.source_text,
            versions=software_versions(),
            seed=seed,
            method=method if method is not None else mission.planner.method,
            **dict(extra or {}),
        )


def new_log_dir(base_dir: str | os.PathLike[str], name: str,
                clock: Callable[[], float] = time.time) -> Path:
    """A fresh directory `<base_dir>/<YYYYmmdd-HHMMSS>-<name>[-N]`, created."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(clock()))
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "flight"
    base = Path(base_dir)
    base.mkdir(parents=True, exist_ok=True)
    for n in range(1000):
        path = base / (f"{stamp}-{safe}" + (f"-{n}" if n else ""))
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"no free log directory name under {base}")


@dataclass(frozen=True)
class FlightLog:
    """A read flight log: its valid records (typed, see `io.records`), what was skipped."""

    path: Path
    records: list[Record]
    torn_last_line: bool = False
    """A partial last line (a crash while writing) was skipped."""
    damage: Damage = field(default_factory=Damage)
    """Damaged records skipped, by reason and line."""

    @property
    def skipped_lines(self) -> int:
        return self.damage.total + int(self.torn_last_line)

    @property
    def header(self) -> MissionHeader:
        """The first record (type mission)."""
        head = self.records[0]
        assert isinstance(head, MissionHeader)
        return head

    def of_type(self, type: str) -> Iterator[Record]:
        return (r for r in self.records if r.type == type)

    def __iter__(self) -> Iterator[Record]:
        return iter(self.records)

    def __len__(self) -> int:
        return len(self.records)


def read_flight_log(path: str | os.PathLike[str]) -> FlightLog:
    """Read `flight.jsonl` (or the directory holding it).

    Damaged records (not JSON, not valid for their type) and a torn last line are skipped and
    reported in `damage` / `torn_last_line`. Raises LogFormatError when the file is not a
    flight log, its format version is unknown or newer, its mission record is damaged, or
    nothing but damage follows the mission record."""
    file = Path(path)
    if file.is_dir():
        file = file / LOG_FILE
    raw = read_jsonl(file, FLIGHT_ADAPTER, "flight log")
    check_format(file, raw.first_line, "mission", FORMAT, FORMAT_VERSION, "flight log")
    if not raw.records or not isinstance(raw.records[0], MissionHeader):
        reason = next((r for r, lines in raw.damage.lines.items() if lines[0] == 1), "invalid")
        raise LogFormatError(f"{file}: the mission record (the first line) is damaged "
                             f"({reason}); the log cannot be read without it")
    if raw.damage and len(raw.records) == 1:
        raise LogFormatError(f"{file}: nothing usable after the mission record: "
                             f"{raw.damage.describe()}")
    return FlightLog(file, raw.records, raw.torn_last_line, raw.damage)
