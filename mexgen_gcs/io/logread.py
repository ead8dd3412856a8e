"""Tolerant reading of a JSON-lines log (flight log, truth file): every line is checked against
the record types of `io.records`; a line that is not UTF-8, not JSON, not a record, or not a
valid record of its type is skipped and counted by reason with its line number, and reading
carries on. A last line without its newline that does not parse is a torn line (a crash while
writing), reported apart from damage. Deciding whether what is left is usable -- the header and
its format version above all -- is the caller's job (`io.flightlog`, `io.truthfile`).

No frames here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pydantic_core
from pydantic import TypeAdapter, ValidationError

from mexgen_gcs.errors import LogFormatError
from mexgen_gcs.io.records import GENERIC_ADAPTER, Record

NOT_UTF8 = "not UTF-8"
NOT_JSON = "not JSON"
NOT_A_RECORD = "not a record (an object with a finite t and a type)"


@dataclass
class Damage:
    """The records a reader skipped: reason -> line numbers (1-based), in file order."""

    lines: dict[str, list[int]] = field(default_factory=dict)

    def add(self, reason: str, line: int) -> None:
        self.lines.setdefault(reason, []).append(line)

    @property
    def total(self) -> int:
        return sum(len(v) for v in self.lines.values())

    def __bool__(self) -> bool:
        return self.total > 0

    def counts(self) -> dict[str, int]:
        return {reason: len(lines) for reason, lines in self.lines.items()}

    def describe(self, max_lines: int = 6) -> str:
        """'3 damaged records skipped: 2 not JSON (lines 35, 36), 1 invalid plan (line 80)'."""
        n = self.total
        parts = []
        for reason, lines in self.lines.items():
            shown = ", ".join(str(x) for x in lines[:max_lines])
            more = f", ... {len(lines) - max_lines} more" if len(lines) > max_lines else ""
            parts.append(f"{len(lines)} {reason} (line{'s' if len(lines) > 1 else ''} "
                         f"{shown}{more})")
        return f"{n} damaged record{'s' if n != 1 else ''} skipped: " + "; ".join(parts)


@dataclass(frozen=True)
class RawLog:
    """The readable records of a JSON-lines file, their line numbers, and what was skipped."""

    path: Path
    records: list[Record]
    line_numbers: list[int]
    damage: Damage
    torn_last_line: bool
    first_line: bytes
    """The first non-empty line as it is in the file (b'' if none): the header to check."""


def read_lines(path: Path, what: str) -> list[bytes]:
    """The file's lines (without newlines; the last one is b'' when the file ends with one)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise LogFormatError(f"{path}: is a directory; expected a {what}") from None
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the {what}: {exc.strerror}") from None
    return data.split(b"\n")


def parse_record(line: bytes, adapter: TypeAdapter[Any]) -> Record | str:
    """The record on one line, or the reason it is damaged."""
    try:
        line.decode("utf-8")
    except UnicodeDecodeError:
        return NOT_UTF8
    try:
        return adapter.validate_json(line)  # type: ignore[no-any-return]
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        kinds = {e["type"] for e in errors}
        if "json_invalid" in kinds:
            return NOT_JSON
        if "union_tag_invalid" in kinds:  # a type this version does not list: kept as is
            try:
                return GENERIC_ADAPTER.validate_json(line)
            except ValidationError:
                return NOT_A_RECORD
        loc = errors[0]["loc"] if errors else ()
        if not loc or (loc[-1] in ("t", "type") and len(loc) <= 2):
            return NOT_A_RECORD
        return f"invalid {loc[0]} record"


def read_jsonl(path: Path, adapter: TypeAdapter[Any], what: str) -> RawLog:
    """Every line of `path` parsed and checked with `adapter` (see the module docstring)."""
    lines = read_lines(path, what)
    complete, last = lines[:-1], lines[-1]
    records: list[Record] = []
    numbers: list[int] = []
    damage = Damage()
    first = next((line for line in lines if line.strip()), b"")
    for n, line in enumerate(complete, start=1):
        if not line.strip():
            continue
        rec = parse_record(line, adapter)
        if isinstance(rec, str):
            damage.add(rec, n)
        else:
            records.append(rec)
            numbers.append(n)
    torn = False
    if last.strip():
        rec = parse_record(last, adapter)
        if rec in (NOT_JSON, NOT_UTF8):
            torn = True
        elif isinstance(rec, str):
            damage.add(rec, len(complete) + 1)
        else:
            records.append(rec)
            numbers.append(len(complete) + 1)
    return RawLog(path, records, numbers, damage, torn, first)


def check_format(file: Path, first_line: bytes, header_type: str, format_name: str,
                 newest: int, what: str, *, label: str | None = None,
                 default_version: int | None = None) -> int:
    """The format version of a JSON-lines file from its first line; LogFormatError naming the
    problem if it is not a `format_name` file of a version from 1 to `newest`. `what` names
    the file in messages ("flight log"), `label` what it is not ("mexgen flight log")."""
    label = label or f"mexgen {what}"
    if not first_line.strip():
        raise LogFormatError(f"{file}: empty; not a {label}")
    try:
        head = pydantic_core.from_json(first_line)  # bounded nesting, unlike json.loads
    except ValueError:
        head = None
    implied = format_name if default_version is not None else None  # a header may omit it
    if (not isinstance(head, dict) or head.get("type") != header_type
            or head.get("format", implied) != format_name):
        raise LogFormatError(f"{file}: not a {label} (expected a first record of type "
                             f"'{header_type}' with format '{format_name}')")
    version = head.get("format_version", default_version)
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise LogFormatError(f"{file}: unknown {what} format_version {version!r}")
    if version > newest:
        raise LogFormatError(f"{file}: {what} format_version {version} is newer than this "
                             f"mexgen-gcs reads ({newest}); upgrade mexgen-gcs to read it")
    return version
