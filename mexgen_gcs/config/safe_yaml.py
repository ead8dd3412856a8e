"""Bounded YAML parsing for mission files: refuse hostile documents at the parser.

PyYAML's safe loader still trusts the shape of a document: nesting is composed recursively
(`[[[[...` exhausts Python's stack), an alias may refer to its own anchor (`a: &a [*a]` makes a
list that contains itself), aliases of aliases expand exponentially (`b: &b [*a, *a, ...]`, the
"billion laughs"), and a document may be arbitrarily large. `BoundedSafeLoader` is the safe
loader with bounds on all four, checked while the document is composed, so a hostile file costs
at most `MAX_NODES` nodes of work and is refused with a `ConfigError` whose one-line message
names the file, the line and the problem -- before any schema work. It also turns the
constructor's own `ValueError`s (a 5,000-digit integer, a date `2020-99-99`) into messages.

No frames here.
"""

from __future__ import annotations

from typing import Any

import yaml
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError
from yaml.error import Mark
from yaml.events import AliasEvent, NodeEvent
from yaml.nodes import Node

from mexgen_gcs.errors import ConfigError

MAX_BYTES = 256 * 1024
"""A mission file is a few kB; a 256 kB one is refused unread."""
MAX_DEPTH = 32
"""Nesting of mappings and lists; a mission file needs 5."""
MAX_NODES = 10_000
"""Nodes of the document with every alias expanded (the work a reader of it does)."""


class HostileYamlError(ConfigError):
    """The document exceeds a bound of `BoundedSafeLoader`; the message is one line."""


class _Refused(ComposerError):
    """Raised inside the composer; turned into HostileYamlError with the file name."""


def _where(source: str, mark: Mark | None) -> str:
    return f"{source}:{mark.line + 1}:{mark.column + 1}" if mark is not None else source


class BoundedSafeLoader(yaml.SafeLoader):
    """`yaml.SafeLoader` that refuses excessive depth, alias loops, alias expansion past
    `max_nodes` and input longer than `max_bytes` characters."""

    def __init__(self, stream: str, *, max_depth: int = MAX_DEPTH,
                 max_nodes: int = MAX_NODES, max_bytes: int = MAX_BYTES) -> None:
        if len(stream) > max_bytes:
            raise _Refused(None, None, f"the document is {len(stream):,} characters; a mission "
                           f"file is at most {max_bytes:,}", None)
        super().__init__(stream)
        self.max_depth = max_depth
        self.max_nodes = max_nodes
        self._depth = 0
        self._nodes = 0
        self._open: set[str] = set()
        self._expanded: dict[str, int] = {}

    def _count(self, n: int, mark: Mark, alias: str | None) -> None:
        self._nodes += n
        if self._nodes > self.max_nodes:
            what = (f"alias *{alias} expands the document past {self.max_nodes:,} nodes "
                    "(an alias bomb)" if alias is not None else
                    f"the document has more than {self.max_nodes:,} nodes")
            raise _Refused(None, None, f"{what}; a mission file has a few hundred", mark)

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        event = self.peek_event()
        if isinstance(event, AliasEvent):
            name = str(event.anchor)
            if name in self._open:
                raise _Refused(None, None, f"alias *{name} is inside its own anchor &{name} "
                               "(an alias loop)", event.start_mark)
            if name in self._expanded:
                self._count(self._expanded[name], event.start_mark, name)
            return super().compose_node(parent, index)  # an undefined alias: PyYAML's error
        self._depth += 1
        if self._depth > self.max_depth:
            raise _Refused(None, None, f"nested deeper than {self.max_depth} levels; a mission "
                           "file needs 5", event.start_mark)
        anchor = event.anchor if isinstance(event, NodeEvent) else None
        before = self._nodes
        self._count(1, event.start_mark, None)
        if anchor is not None:
            self._open.add(anchor)
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
            if anchor is not None:
                self._open.discard(anchor)
        if anchor is not None:
            self._expanded[anchor] = self._nodes - before
        return node

    def construct_object(self, node: Node, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep)
        except ValueError as exc:  # int('1' * 5000), datetime.date(2020, 99, 99), ...
            raise ConstructorError(None, None, _unreadable(node, exc), node.start_mark) from None


def _unreadable(node: Node, exc: ValueError) -> str:
    value = node.value if isinstance(node.value, str) else ""
    shown = repr(value) if len(value) <= 40 else repr(value[:37]) + "..."
    kind = str(node.tag).rpartition(":")[2]
    if kind == "int":
        return f"the number {shown} has {len(value):,} digits; quote it to make it text"
    if kind == "timestamp":
        return f"{shown} looks like a date but is not one ({exc}); quote it to make it text"
    return f"cannot read {shown or node.tag}: {exc}"


def compose_and_load(text: str, source: str) -> tuple[Node | None, Any]:
    """(root node with marks, constructed data) of one YAML document, parsed once.

    Raises HostileYamlError for a document past a bound, and yaml.YAMLError for YAML that is
    not well formed (the caller words that one)."""
    try:
        loader = BoundedSafeLoader(text)
    except _Refused as exc:
        raise HostileYamlError(f"{source}: refused: {exc.problem}") from None
    try:
        root = loader.get_single_node()
        data = loader.construct_document(root) if root is not None else None
    except _Refused as exc:
        raise HostileYamlError(f"{_where(source, exc.problem_mark)}: refused: "
                               f"{exc.problem}") from None
    finally:
        loader.dispose()
    return root, data
