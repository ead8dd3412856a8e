"""The one JSON-lines writer, used for the flight log (`io.flightlog`) and the simulator's
truth file (`sim.truth`): one JSON object per line, each with ``t`` and ``type``; values made
JSON-safe on the way (numpy to Python, NaN and infinities to null). No frames here.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import enum
import json
import math
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np
from pydantic import TypeAdapter

from mexgen_gcs.io.logread import parse_record


def to_jsonable(value: Any) -> Any:
    """A JSON-safe copy of value: numpy -> Python, NaN/inf -> None, tuples -> lists."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, int):
        return value
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in value]
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value)
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    dump = getattr(value, "model_dump", None)
    if callable(dump):
        return to_jsonable(dump(mode="json"))
    raise TypeError(f"cannot write a {type(value).__name__} to a flight log")


class JsonlWriter:
    """Append-only JSON-lines file: `write(type, **fields)` adds `t` and `type`, writes each
    record straight to the file (no user-space buffer), and fsyncs it too if `fsync=True`.
    Creates the parent directory; refuses to overwrite an existing file.

    A write that fails with OSError (disk full, I/O error) is undone: the file is cut back to
    its last complete record, `lost_records` counts it and the OSError is raised, so the file
    never holds a torn line in its middle and the caller decides whether to go on.

    With `records` (an `io.records` adapter: the flight log's or the truth file's) every line
    is checked as its reader will check it, before it is written: a record its documented type
    does not allow is still written (nothing is lost), and counted in `invalid` by the reason
    a reader will give (``invalid plan record``), for the caller to report.
    """

    def __init__(self, path: str | os.PathLike[str], *, fsync: bool = False,
                 clock: Callable[[], float] = time.time,
                 records: TypeAdapter[Any] | None = None) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] | None = open(self.path, "xb", buffering=0)  # noqa: SIM115
        self._fsync = fsync
        self._clock = clock
        self._size = 0
        self.records = 0
        self.lost_records = 0
        self._check = records
        self.invalid: collections.Counter[str] = collections.Counter()

    def write(self, type: str, **fields: Any) -> dict[str, Any]:
        """Append one record; `t` defaults to the clock. Returns the record as written."""
        if self._file is None:
            raise ValueError(f"{self.path} is closed")
        t = fields.pop("t", None)
        record = {"t": self._clock() if t is None else t, "type": type, **fields}
        safe = to_jsonable(record)
        line = json.dumps(safe, separators=(",", ":"), allow_nan=False).encode("utf-8")
        if self._check is not None:
            checked = parse_record(line, self._check)
            if isinstance(checked, str):
                self.invalid[checked] += 1
        data = line + b"\n"
        try:
            view = memoryview(data)
            while view:
                n = self._file.write(view)
                if not n:
                    raise OSError(f"{self.path}: short write")
                view = view[n:]
            if self._fsync:
                os.fsync(self._file.fileno())
        except OSError:
            self.lost_records += 1
            self._undo()
            raise
        self._size += len(data)
        self.records += 1
        return safe

    def sync(self) -> None:
        """Force what is written to the disk (fsync)."""
        if self._file is not None:
            os.fsync(self._file.fileno())

    def _undo(self) -> None:
        """Cut a partly written record off (best effort: truncating frees space)."""
        if self._file is None:
            return
        with contextlib.suppress(OSError):
            self._file.truncate(self._size)
            self._file.seek(self._size)

    @property
    def closed(self) -> bool:
        return self._file is None

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> JsonlWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
