"""The package's import graph: no cycles, and the layer contracts hold.

grimp builds the graph from the source (imports inside functions included);
the contracts live in pyproject.toml ([tool.importlinter]) and are checked with
import-linter's own command, so CI and a developer's ``lint-imports`` agree.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

grimp = pytest.importorskip("grimp")

ROOT = Path(__file__).resolve().parents[1]


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append(
                        (child, iter(sorted(graph.find_modules_directly_imported_by(child)))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_cycle_finder_finds_a_known_cycle():
    class Toy:
        modules = {"a", "b", "c", "d"}
        edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}

        def find_modules_directly_imported_by(self, m):
            return self.edges.get(m, set())

    assert _cycles(Toy()) == [["a", "b", "c"]]


def test_no_import_cycles_in_src():
    graph = grimp.build_graph("avblocks", include_external_packages=False, cache_dir=None)
    cycles = _cycles(graph)
    lines = []
    for component in cycles:
        lines.append(" <-> ".join(component))
        for a in component:
            for b in sorted(graph.find_modules_directly_imported_by(a)):
                if b in component:
                    details = graph.get_import_details(importer=a, imported=b)
                    where = ", ".join(str(d["line_number"]) for d in details)
                    lines.append(f"    {a} -> {b} (line {where})")
    assert not cycles, "import cycles:\n" + "\n".join(lines)


def test_import_contracts_hold():
    pytest.importorskip("importlinter")
    lint = Path(sys.executable).with_name("lint-imports")
    cmd = [str(lint)] if lint.exists() else [sys.executable, "-m", "importlinter.cli"]
    proc = subprocess.run(cmd + ["--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


# ------------------------------------------------ private names stay at home
#: the top-level areas of the package; the application layer (the CLI, its
#: commands, the run guard they share and the sweep CLI) counts as one
_APPS = {"cli", "commands", "_runio", "sweep", "__main__"}


def _area(module: str) -> str:
    parts = module.split(".")[1:]
    if parts[:2] == ["core", "compiled"]:
        return "core.compiled"              # the compiled engine: a layer of its own
    head = parts[0] if parts else ""
    return "apps" if head in _APPS else head


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_imports(src: Path = ROOT / "src" / "avblocks") -> list[str]:
    """``module:line name`` for every import of a private name (or from a
    private module) of another area of the package, functions included."""
    import ast

    found = []
    for f in sorted(src.rglob("*.py")):
        rel = f.relative_to(src.parent).with_suffix("").parts
        module = ".".join(rel[:-1] if rel[-1] == "__init__" else rel)
        package = module.split(".") if rel[-1] == "__init__" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package[:len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").split(".")[0] == "avblocks":
                target = node.module
            else:
                continue
            if _area(target) == _area(module):
                continue
            for alias in node.names:
                if any(_private(p) for p in target.split(".")[1:]) or _private(alias.name):
                    found.append(f"{module}:{node.lineno} {target}.{alias.name}")
    return found


def test_private_name_finder_sees_relative_and_absolute_imports(tmp_path):
    pkg = tmp_path / "avblocks"
    (pkg / "core").mkdir(parents=True)
    (pkg / "viz").mkdir()
    for p in (pkg, pkg / "core", pkg / "viz"):
        (p / "__init__.py").write_text("")
    (pkg / "core" / "diagram.py").write_text("def _flatten(): pass\n")
    (pkg / "viz" / "draw.py").write_text(
        "from ..core.diagram import _flatten\n"
        "def f():\n    from avblocks.core import diagram\n    from . import _own\n")
    assert private_imports(pkg) == ["avblocks.viz.draw:1 avblocks.core.diagram._flatten"]


def test_no_private_names_cross_areas():
    assert private_imports() == []
