"""The package's import structure: no module-level import cycle, a light root and command line.

A plugin's ``from suspid import hookimpl`` must not load the workflows, and
``suspid --help`` must not pay for numpy, scipy, GPy or matplotlib: both
follow from a root that imports only the hook markers and an API loaded on
first use.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"suspid": ROOT / "core", "suspid.plugins": ROOT / "plugins"}


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of suspid and its built-in plugins."""
    out = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def _targets(module: str, node: ast.ImportFrom | ast.Import, is_package: bool, known: set[str]) -> set[str]:
    """The suspid modules one import statement names (``from a import b`` names ``a.b`` when it is a module)."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names if a.name in known}
    base = module if is_package else module.rpartition(".")[0]
    for _ in range(max(node.level - 1, 0)):
        base = base.rpartition(".")[0]
    target = (f"{base}.{node.module}" if node.module else base) if node.level else node.module
    return {f"{target}.{a.name}" if f"{target}.{a.name}" in known else target for a in node.names} & known


def import_graph() -> dict[str, set[str]]:
    """Module -> the suspid modules it imports when it is executed (top-level statements, not function bodies)."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        edges: set[str] = set()
        for statement in tree.body:
            nodes = ast.walk(statement) if isinstance(statement, (ast.If, ast.Try)) else [statement]
            for node in nodes:
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    edges |= _targets(name, node, path.name == "__init__.py", set(modules))
        graph[name] = edges - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_cycle_finder_finds_a_known_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    graph = import_graph()
    assert "suspid.api" in graph and "suspid.plugins.simulators.exudyn_train.model" in graph
    assert cycles(graph) == []


def _loaded_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


@pytest.mark.parametrize("statement", ["from suspid import hookimpl", "import suspid.cli"])
def test_root_and_cli_do_not_load_the_workflows(statement):
    loaded = _loaded_after(statement)
    assert "suspid.hookspecs" in loaded
    assert not {"numpy", "scipy", "GPy", "matplotlib", "suspid.config", "suspid.workflows.identify"} & loaded


def test_api_names_load_on_first_use():
    loaded = _loaded_after("import suspid; suspid.identify")
    assert {"suspid.api", "numpy"} <= loaded
    import suspid
    assert callable(suspid.validate) and "identify" in dir(suspid)
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        suspid.nonexistent  # noqa: B018
