"""The package's layers: the method (the paper's mathematics) imports no workflow.

``suspid.method`` is what a workflow composes; a method module that imported
``suspid.workflows`` (even inside a function) would make the layers a cycle.
Every import statement of ``core/method`` is read, function-level ones included.
"""

from __future__ import annotations

import ast
from pathlib import Path

METHOD = Path(__file__).resolve().parents[1] / "core" / "method"


def _imports(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append(node.module)
    return out


def test_method_imports_no_workflow():
    files = sorted(METHOD.glob("*.py"))
    assert len(files) > 5
    bad = {f.name: m for f in files for m in _imports(f) if m.startswith(("suspid.workflows", "suspid.cli",
                                                                            "suspid.api"))}
    assert not bad, f"method modules import workflows: {bad}"
