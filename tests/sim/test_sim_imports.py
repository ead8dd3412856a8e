"""The ``sim`` package's modules import each other without cycles (counting imports made only
for type checking), and the simulator does not import the GCS's mission or UI layers."""

from __future__ import annotations

import ast
from pathlib import Path

SIM = Path(__file__).resolve().parents[2] / "sim"


def _imports(path: Path) -> set[str]:
    """Modules of ``sim`` (and the top-level packages of others) that ``path`` imports."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "sim":
                out.update(f"sim.{a.name}" for a in node.names)
            else:
                out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def _graph() -> dict[str, set[str]]:
    modules = {f"sim.{p.stem}": p for p in SIM.glob("*.py") if p.stem != "__init__"}
    return {name: {m for m in _imports(p) if m in modules} for name, p in modules.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_import_cycles_in_sim() -> None:
    graph = _graph()
    assert "sim.commands" in graph and "sim.vehicle" in graph["sim.runner"]
    assert _cycle(graph) is None, " -> ".join(_cycle(graph) or [])


def test_cycle_finder_finds_one() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_sim_does_not_import_the_gcs_mission_or_ui() -> None:
    for path in SIM.glob("*.py"):
        bad = [m for m in _imports(path)
               if m.startswith(("mexgen_gcs.mission", "mexgen_gcs.ui", "mexgen_gcs.cli"))]
        assert bad == [], (path.name, bad)
