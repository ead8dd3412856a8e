"""The import graph of mexgen_gcs and sim has no cycles.

The graph is built from the source (AST), not by importing: every `import` and `from ... import`
of a module of the two packages, including those inside functions (a lazy import still makes
the two modules depend on each other at run time) and those under `if TYPE_CHECKING:` (two
modules that need each other's types are one design, whatever the interpreter does).
`from pkg import name` is an edge to `pkg.name` when that is a module, else to `pkg` (its
__init__). A cycle is a strongly connected component of more than one module, or a module
importing itself.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("mexgen_gcs", "sim")

KNOWN_CYCLES: tuple[frozenset[str], ...] = (
    # Being removed on other branches; the lead empties this list as they are merged. A cycle
    # listed here that no longer exists fails the test too, so the list cannot go stale.
)


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


def _imports(tree: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement, wherever it is."""
    return (n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom))


def import_graph() -> dict[str, set[str]]:
    """module -> the modules of PACKAGES it imports."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        edges: set[str] = set()
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = name.split(".")
                    anchor = anchor if is_package else anchor[:-1]
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join([*anchor, base] if base else anchor)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                           for a in node.names]
            for target in targets:
                while target and target not in modules:  # import a.b.c where c is a name
                    target = target.rpartition(".")[0]
                if target and target.split(".")[0] in PACKAGES:
                    edges.add(target)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """Strongly connected components with a cycle (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[frozenset[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                members = set()
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    members.add(m)
                    if m == node:
                        break
                if len(members) > 1 or node in graph.get(node, ()):
                    out.append(frozenset(members))
    return out


def test_the_graph_sees_real_imports() -> None:
    graph = import_graph()
    assert "mexgen_gcs.config.loader" in graph["mexgen_gcs.config"]
    assert "mexgen_gcs.core.geo" in graph["mexgen_gcs.config.mission"]
    assert "mexgen_gcs.io.records" in graph["mexgen_gcs.io.logread"]
    assert "mexgen_gcs.config.mission" in graph["mexgen_gcs.config.checks"]  # TYPE_CHECKING
    assert "mexgen_gcs.analysis.flightdata" in graph["mexgen_gcs.analysis.cli"]  # in a function
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]
    assert cycles({"a": {"a"}, "b": set()}) == [frozenset("a")]


def test_no_import_cycles() -> None:
    found = cycles(import_graph())
    new = [sorted(c) for c in found if c not in KNOWN_CYCLES]
    assert not new, f"import cycles: {new}"
    gone = [sorted(c) for c in KNOWN_CYCLES if c not in found]
    assert not gone, f"these cycles are gone: remove them from KNOWN_CYCLES: {gone}"


# -- layers (docs/architecture.md) -------------------------------------------------------------

#: layer -> the layers it may import (besides itself). A layer is a subpackage of mexgen_gcs;
#: "errors" is mexgen_gcs/errors.py, "package" mexgen_gcs/__init__.py (the version).
LAYERS: dict[str, set[str]] = {
    "package": set(),
    "errors": set(),
    "core": {"errors"},
    "config": {"core", "errors"},
    "io": {"config", "core", "errors", "package"},
    "receiver": {"io", "config", "core", "errors", "package"},
    "mission": {"receiver", "io", "config", "core", "errors", "package"},
    "ui": {"mission", "receiver", "io", "config", "core", "errors", "package"},
    # analysis and experiments use what a flight decides with (core, config, io), never the
    # asyncio flight itself
    "analysis": {"io", "config", "core", "errors", "package"},
    "experiments": {"config", "core", "errors", "package"},
    "bench": {"experiments", "receiver", "core", "config", "errors", "package"},
    "cli": {"config", "core", "errors", "package"},  # the other handlers: looked up by name
    "__main__": {"cli"},
}
#: what sim (a separate program) may use of mexgen_gcs
SIM_MAY_IMPORT = ("mexgen_gcs.core", "mexgen_gcs.config", "mexgen_gcs.errors",
                  "mexgen_gcs.io.wire", "mexgen_gcs.io.jsonl", "mexgen_gcs.io.records",
                  "mexgen_gcs.io.truthfile", "mexgen_gcs.io.pulseinfo", "mexgen_gcs.receiver.synth",
                  "mexgen_gcs.receiver.rtltcp")
#: (importer, imported) that break the layers, being removed elsewhere; emptied by the lead
KNOWN_LAYER_BREAKS: frozenset[tuple[str, str]] = frozenset()


def _layer(module: str) -> str:
    parts = module.split(".")
    return "package" if len(parts) == 1 else parts[1]


def test_layers_import_only_what_docs_architecture_allows() -> None:
    breaks = set()
    for module, targets in import_graph().items():
        for target in targets:
            if module.startswith("sim"):
                if target.startswith("mexgen_gcs") and not target.startswith(SIM_MAY_IMPORT):
                    breaks.add((module, target))
                continue
            if target.startswith("sim"):
                breaks.add((module, target))  # mexgen_gcs never imports the simulator
                continue
            a, b = _layer(module), _layer(target)
            if a != b and b not in LAYERS[a]:
                breaks.add((module, target))
    assert set(LAYERS) >= {_layer(m) for m in import_graph() if m.startswith("mexgen_gcs")}
    assert breaks - KNOWN_LAYER_BREAKS == set(), sorted(breaks - KNOWN_LAYER_BREAKS)
    gone = KNOWN_LAYER_BREAKS - breaks
    assert not gone, f"these layer breaks are gone: remove them from KNOWN_LAYER_BREAKS: {gone}"
