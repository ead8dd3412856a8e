"""Load a mission file: YAML -> validated `Mission`, or a `ConfigError` that points at the line.

Every problem names the file, the line (from YAML's node marks), the dotted key path
(`planner.method`, `tags[1].id`), what was found and what is expected. All problems of a
file are reported together, sorted by line. A hostile document (too large, too deep, an alias
loop or an alias bomb) is refused by the bounded parser of `config.safe_yaml` with a one-line
message before any schema work.
"""

from __future__ import annotations

import difflib
import os
import re
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from mexgen_gcs.config.area_files import AreaFileError, read_area_file
from mexgen_gcs.config.mission import Mission
from mexgen_gcs.config.safe_yaml import MAX_BYTES, compose_and_load
from mexgen_gcs.config.schema import TAG_ID_PATTERN, KeyPath, RuleViolation
from mexgen_gcs.config.sim_schema import FAULT_MODELS
from mexgen_gcs.errors import ConfigError

_REQUIRED = "version, name, kind, home, area and tags"


@dataclass(frozen=True, slots=True)
class Problem:
    """One thing wrong with a mission file."""

    path: KeyPath
    message: str
    line: int | None = None

    def format(self, source: str) -> str:
        where = f"{source}:{self.line}" if self.line is not None else source
        return f"{where}: {format_key_path(self.path)}: {self.message}"


class MissionFileError(ConfigError):
    """A mission file could not be loaded. `problems` lists each one with its line."""

    def __init__(self, source: str, problems: list[Problem]) -> None:
        self.source = source
        self.problems = sorted(problems, key=lambda p: (p.line or 0, format_key_path(p.path)))
        n = len(self.problems)
        lines = [f"{source}: invalid mission ({n} problem{'s' if n != 1 else ''}):"]
        lines += [f"  {p.format(source)}" for p in self.problems]
        super().__init__("\n".join(lines))


def format_key_path(path: KeyPath) -> str:
    """('tags', 1, 'id') -> 'tags[1].id'; () -> '(top level)'."""
    out = ""
    for elem in path:
        out += f"[{elem}]" if isinstance(elem, int) else (f".{elem}" if out else str(elem))
    return out or "(top level)"


def load_mission(path: str | os.PathLike[str]) -> Mission:
    """Read and validate a mission file. Raises ConfigError with a message for the operator."""
    source = os.fspath(path)
    file = Path(source)
    if file.is_dir():
        raise ConfigError(f"{source}: is a directory; expected a mission file (.yaml)")
    try:
        size = file.stat().st_size
        if size > MAX_BYTES:
            raise ConfigError(f"{source}: refused: the file is {size:,} bytes; a mission file "
                              f"is at most {MAX_BYTES:,}")
        raw = file.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{source}: no such mission file") from None
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read the mission file: {exc.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{source}: not a text file (byte {exc.start} is not UTF-8); expected "
                          "a YAML mission file") from None
    return parse_mission(text, source)


def parse_mission(text: str, source: str = "<mission>") -> Mission:
    """Validate mission YAML text; `source` names it in messages. Raises ConfigError."""
    try:
        root, data = compose_and_load(text, source)
    except yaml.YAMLError as exc:
        raise ConfigError(_yaml_message(source, exc)) from None
    if root is None or data is None:
        raise ConfigError(f"{source}: the file is empty; a mission needs at least {_REQUIRED} "
                          "(see missions/README.md)")
    if not isinstance(data, dict):
        raise ConfigError(f"{source}:{root.start_mark.line + 1}: expected a mapping of keys "
                          f"({_REQUIRED}, ...) at the top level; found {_type_name(data)}")
    lines: dict[KeyPath, int] = {}
    duplicates: list[Problem] = []
    _walk_nodes(root, (), lines, duplicates)
    if duplicates:
        raise MissionFileError(source, duplicates)
    area_problem = _read_area_file(data, source)
    if area_problem is not None:
        raise MissionFileError(source, [Problem(area_problem.path, area_problem.message,
                                                _line_of(area_problem.path, lines))])
    try:
        mission = Mission.model_validate(data)
    except ValidationError as exc:
        problems = [p for err in exc.errors() for p in _problems(err, data)]
        located = [Problem(p.path, p.message, _line_of(p.path, lines)) for p in problems]
        raise MissionFileError(source, located) from None
    return mission.with_source(source, text)


def _read_area_file(data: dict[str, Any], source: str) -> Problem | None:
    """``area.from: FILE`` -> ``area.polygon_deg`` read from FILE (relative to the mission
    file), in place; a Problem at ``area.from`` if it cannot be used. The key stays, so the
    resolved mission says where its polygon came from."""
    area, home = data.get("area"), data.get("home")
    if not isinstance(area, dict) or "from" not in area:
        return None
    name = area["from"]
    if not isinstance(name, str) or not name:
        return Problem(("area", "from"), f"expected a file name (text); found {_show(name)}")
    others = [k for k in ("rectangle_m", "polygon_deg") if k in area]
    if others:
        return Problem(("area", "from"), f"expected exactly one of rectangle_m, polygon_deg or "
                       f"from; found from and {' and '.join(others)}")
    try:
        lat, lon = float(home["lat_deg"]), float(home["lon_deg"])  # type: ignore[index]
    except (KeyError, TypeError, ValueError):
        return None  # the schema reports the home problem; the area waits for it
    path = Path(name).expanduser()
    if not path.is_absolute():
        path = Path(source).parent / path
    try:
        polygon = read_area_file(path, lat, lon)
    except AreaFileError as exc:
        return Problem(("area", "from"), str(exc))
    area["polygon_deg"] = [[a, b] for a, b in polygon]
    return None


# -- YAML node marks ---------------------------------------------------------------------

def _walk_nodes(node: Node, path: KeyPath, lines: dict[KeyPath, int],
                duplicates: list[Problem]) -> None:
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, MappingNode):
        first: dict[str, int] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, ScalarNode):
                continue
            key = str(key_node.value)
            line = key_node.start_mark.line + 1
            if key in first:
                duplicates.append(Problem((*path, key), f"duplicate key (first at line "
                                          f"{first[key]}); expected each key once", line))
                continue
            first[key] = line
            lines[(*path, key)] = line
            _walk_nodes(value_node, (*path, key), lines, duplicates)
    elif isinstance(node, SequenceNode):
        for i, item in enumerate(node.value):
            lines[(*path, i)] = item.start_mark.line + 1
            _walk_nodes(item, (*path, i), lines, duplicates)


def _line_of(path: KeyPath, lines: dict[KeyPath, int]) -> int | None:
    """Line of the key at `path`, or of its nearest existing parent (for missing keys)."""
    for n in range(len(path), -1, -1):
        prefix = tuple(e if isinstance(e, int) else str(e) for e in path[:n])
        if prefix in lines:
            return lines[prefix]
    return None


def _yaml_message(source: str, exc: yaml.YAMLError) -> str:
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark is not None else source
    problem = getattr(exc, "problem", None) or str(exc)
    context = getattr(exc, "context", None)
    detail = f"{problem} ({context})" if context else str(problem)
    hint = ""
    if "'\\t'" in detail:
        hint = "; YAML does not allow tabs for indentation, use spaces"
    elif "mapping values are not allowed" in detail:
        hint = "; check the indentation and that each 'key: value' has a space after the colon"
    return f"{where}: not valid YAML: {detail}{hint}"


# -- pydantic errors -> problems ----------------------------------------------------------

def _problems(err: Any, data: Any) -> list[Problem]:
    kind: str = err["type"]
    path = _data_path(err["loc"], data)
    ctx = err.get("ctx") or {}
    cause = ctx.get("error")
    if isinstance(cause, RuleViolation):
        return [Problem(path + rel, msg) for rel, msg in cause.issues]
    if kind == "value_error":
        return [Problem(path, str(cause) if cause is not None else err["msg"])]
    if kind == "extra_forbidden":
        return [Problem(path, _unknown_key_message(path, data))]
    if kind == "missing":
        return [Problem(path, _missing_message(path, data))]
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        tags = re.findall(r"'([^']*)'", ctx.get("expected_tags", ""))
        if kind == "union_tag_not_found" or not tags:
            tags = _fault_kinds()
        if kind == "union_tag_not_found":
            return [Problem((*path, "kind"), f"missing required key; expected one of "
                            f"{', '.join(tags)}")]
        found = str(ctx.get("tag"))
        return [Problem((*path, "kind"), f"expected one of {', '.join(tags)}; found "
                        f"{found!r}{_did_you_mean(found, tags)}")]
    found = err.get("input")
    if kind in ("literal_error", "enum"):  # a Literal or an Enum field
        choices = re.findall(r"'([^']*)'", ctx.get("expected", ""))
        hint = _did_you_mean(str(found), choices) if isinstance(found, str) else ""
        if isinstance(found, bool):
            hint = " (YAML reads yes/no/on/off as true/false; quote the value)"
        return [Problem(path, f"expected {ctx.get('expected', err['msg'])}; found "
                        f"{_show(found)}{hint}")]
    if kind == "string_pattern_mismatch":
        what = ("a tag id: 1-32 letters, digits, '_', '.' or '-', starting with a letter or "
                "digit" if ctx.get("pattern") == TAG_ID_PATTERN else
                f"text matching {ctx.get('pattern')}")
        return [Problem(path, f"expected {what}; found {_show(found)}")]
    if kind in ("too_short", "too_long"):
        size = len(found) if isinstance(found, list | tuple | str) else "?"
        bound = "at least" if kind == "too_short" else "at most"
        limit = ctx.get("min_length" if kind == "too_short" else "max_length")
        return [Problem(path, f"expected {bound} {limit} items; found {size}")]
    expected = err["msg"].replace("Input should be", "expected", 1)
    return [Problem(path, f"{expected}; found {_show(found)}{_type_hint(kind, found)}")]


def _type_hint(kind: str, found: Any) -> str:
    if kind in ("float_type", "int_type") and isinstance(found, str):
        try:
            float(found)
        except ValueError:
            return ""
        if kind == "int_type":
            return " (YAML reads this as text: write the whole number in digits)"
        return (" (YAML reads this as text: write a plain number, and exponents with a sign "
                "like 1.0e+3)")
    if kind == "int_type" and isinstance(found, float) and found.is_integer():
        return " (write it without a decimal point)"
    if kind == "string_type" and isinstance(found, bool):
        return " (YAML reads yes/no/on/off as true/false; quote the value)"
    if kind == "string_type" and isinstance(found, int | float):
        return f" (quote it to make it text: '{found}')"
    return ""


def _show(value: Any) -> str:
    text = _type_name(value) if isinstance(value, dict | list) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _type_name(value: Any) -> str:
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return f"{type(value).__name__} {value!r}"


def _data_path(loc: tuple[Any, ...], data: Any) -> KeyPath:
    """Pydantic's loc as a path into the YAML data: drops union tags and type names."""
    out: list[str | int] = []
    cursor = data
    for n, elem in enumerate(loc):
        last = n == len(loc) - 1
        in_dict = isinstance(cursor, dict) and elem in cursor
        in_list = isinstance(cursor, list) and isinstance(elem, int) and 0 <= elem < len(cursor)
        if in_dict or in_list:
            out.append(elem)
            cursor = cursor[elem]
        elif last and isinstance(cursor, dict) and isinstance(elem, str):
            out.append(elem)  # a missing key
    return tuple(out)


def _unknown_key_message(path: KeyPath, data: Any) -> str:
    key = str(path[-1]) if path else ""
    allowed = _allowed_keys(path[:-1], data)
    if not allowed:
        return "unknown key"
    return (f"unknown key {key!r}{_did_you_mean(key, allowed)}; expected one of "
            f"{', '.join(allowed)}")


def _missing_message(path: KeyPath, data: Any) -> str:
    model = _model_at(path[:-1], data)
    key = str(path[-1]) if path else ""
    description = ""
    if model is not None and key in model.model_fields:
        description = model.model_fields[key].description or ""
    return f"missing required key {key!r}" + (f" ({description.rstrip('.')})"
                                                if description else "")


def _allowed_keys(path: KeyPath, data: Any) -> list[str]:
    model = _model_at(path, data)
    if model is None:
        return []
    return [f.alias or name for name, f in model.model_fields.items()]


def _model_at(path: KeyPath, data: Any) -> type[BaseModel] | None:
    """The schema model describing the mapping at `path` (following the data for unions)."""
    target: Any = Mission
    cursor = data
    for elem in path:
        cursor = _index(cursor, elem)
        if isinstance(target, tuple) and target[0] == "seq" and isinstance(elem, int):
            target = _resolve(target[1], cursor)
        elif isinstance(target, type) and issubclass(target, BaseModel) and elem in \
                target.model_fields:
            target = _resolve(target.model_fields[str(elem)].annotation, cursor)
        else:
            return None
    return target if isinstance(target, type) and issubclass(target, BaseModel) else None


def _index(cursor: Any, elem: str | int) -> Any:
    if isinstance(cursor, dict):
        return cursor.get(elem)
    if isinstance(cursor, list) and isinstance(elem, int) and 0 <= elem < len(cursor):
        return cursor[elem]
    return None


def _resolve(annotation: Any, value: Any) -> Any:
    """Unwrap Annotated/Optional/unions/tuples down to a model class or ('seq', item)."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _resolve(typing.get_args(annotation)[0], value)
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        models = [m for m in (_resolve(a, value) for a in members)
                  if isinstance(m, type) and issubclass(m, BaseModel)]
        if len(models) == 1:
            return models[0]
        kind = value.get("kind") if isinstance(value, dict) else None
        for model in models:
            field = model.model_fields.get("kind")
            if field is not None and kind in typing.get_args(field.annotation):
                return model
        return None
    if origin is tuple:
        args = typing.get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            return ("seq", args[0])
        return None
    return annotation


def _fault_kinds() -> list[str]:
    return [typing.get_args(m.model_fields["kind"].annotation)[0] for m in FAULT_MODELS]


def _did_you_mean(word: str, choices: list[str]) -> str:
    """A suggestion: the closest spelling, else a key that only adds a unit (speed -> speed_m_s)."""
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if not close:
        close = [c for c in choices if word and c.lower().startswith(word.lower() + "_")]
    return f" (did you mean {close[0]!r}?)" if close else ""
