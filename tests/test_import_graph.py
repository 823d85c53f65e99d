"""The import graph of our packages has no cycle and follows the layers of docs/architecture.md.

Every import counts: module level, inside functions and under ``if TYPE_CHECKING:`` (a type-only
import still ties two modules together: neither can be read or moved without the other).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rig", "processing", "calibration", "drivers", "mock_devices")
FRONT_ENDS = ("rig.commands", "rig.console", "rig.batch", "rig.cli")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(path): path for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))}


def _imported_names(module: str, path: Path) -> Iterator[str]:
    """Every dotted name ``module`` imports (absolute; ``from X import Y`` gives X.Y and X)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            yield base
            yield from (f"{base}.{alias.name}" for alias in node.names)


def import_graph() -> dict[str, set[str]]:
    """module -> the modules of ours it imports (a name that is not a module counts as its package)."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        targets: set[str] = set()
        for name in _imported_names(module, path):
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name and name != module:
                targets.add(name)
        graph[module] = targets
    return graph


def _components(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def connect(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            if target not in index:
                connect(target)
                low[node] = min(low[node], low[target])
            elif target in stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    return found


def _cycle_in(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """A shortest cycle through the component's first module (first module repeated at the end)."""
    start, members = component[0], set(component)
    parents: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for target in sorted(graph[node] & members):
                if target == start:
                    cycle = [node]
                    while cycle[-1] != start:
                        cycle.append(parents[cycle[-1]])
                    return [*reversed(cycle), start]
                if target not in parents:
                    parents[target] = node
                    following.append(target)
        frontier = following
    raise AssertionError(f"no cycle in component {component}")


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per tangle of modules that import each other (each: first module repeated at the end)."""
    return [_cycle_in(graph, component) for component in _components(graph)]


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _violations(graph: dict[str, set[str]], sources: tuple[str, ...], allowed: tuple[str, ...]) -> list[str]:
    return sorted(
        f"{module} -> {target}"
        for module, targets in graph.items()
        if _within(module, sources)
        for target in targets
        if not _within(target, allowed)
    )


def test_the_graph_sees_every_kind_of_import() -> None:
    graph = import_graph()
    assert "rig.pipeline.plan" in graph["rig.pipeline.stages"]  # module level
    assert "processing.patterns" in graph["rig.pipeline.plan"]  # inside a function
    assert find_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": set()}) == [
        ["a", "b", "c", "a"]
    ]


def test_no_import_cycle() -> None:
    cycles = find_cycles(import_graph())
    assert cycles == [], "import cycles:\n" + "\n".join(" -> ".join(cycle) for cycle in cycles)


def test_layers_of_the_architecture() -> None:
    graph = import_graph()
    assert _violations(graph, ("processing",), ("processing",)) == []
    assert _violations(graph, ("calibration",), ("calibration", "processing")) == []
    assert _violations(graph, ("drivers",), ("drivers", "processing")) == []
    assert _violations(graph, ("mock_devices",), ("mock_devices", "drivers", "processing")) == []
    services = tuple(m for m in graph if _within(m, ("rig",)) and not _within(m, FRONT_ENDS) and m != "rig")
    front_end_imports = sorted(f"{m} -> {t}" for m in services for t in graph[m] if _within(t, FRONT_ENDS))
    assert front_end_imports == [], "a service imports a front-end"
    # the rig's description sits below the layers that use it; the devices below the acquisition using them
    assert (
        sorted(t for t in graph["rig.config"] if _within(t, ("rig.hardware", "rig.acquisition", "rig.pipeline"))) == []
    )
    assert [v for v in _violations(graph, ("rig.hardware",), ("rig.hardware",)) if "-> rig.acquisition" in v] == []
    mock_users = sorted(m for m, targets in graph.items() if any(_within(t, ("mock_devices",)) for t in targets))
    assert [m for m in mock_users if not _within(m, ("rig.hardware", "mock_devices"))] == []
